"""The behaviour of ros2_control's ``mock_components/GenericSystem``, for profiles that have no
wire protocol (the ros2_control ``<gpio>`` examples).

Commands are mirrored to the state interfaces of the same name (plus
``position_state_following_offset`` on position, or on ``custom_interface_with_following_offset``);
states start at their ``initial_value``; ``mock_gpio_commands`` and ``mock_sensor_commands``
add command interfaces to inject GPIO and sensor readings; ``disable_commands`` stops the
mirroring; ``calculate_dynamics`` derives velocity from position commands and integrates
velocity commands.
"""

from __future__ import annotations

import time
from typing import Any

from deltoctl.core.driver import Block, Driver, MoveResult, Progress
from deltoctl.errors import InvalidInput
from deltoctl.profile.model import Hardware


def _flag(hw: Hardware, name: str) -> bool:
    return hw.params.get(name, "false").lower() == "true"


class GenericDriver(Driver):
    def __init__(self, block: Block) -> None:
        super().__init__(block)
        self.commands: dict[str, Hardware] = {}  # command interface → its block
        self._last_write: dict[str, float] = {}

    def configure(self) -> None:
        hw = self.hw
        gpio_cmds, sensor_cmds = _flag(hw, "mock_gpio_commands"), _flag(hw,
                                                                       "mock_sensor_commands")
        for comp in hw.components():
            for itf in comp.state_interfaces:
                initial = itf.initial_value
                try:
                    value = float(initial) if initial is not None else 0.0
                except ValueError:
                    value = 1.0 if initial.lower() == "true" else 0.0
                self.values[f"{comp.name}/{itf.name}"] = value
                if (comp.kind == "gpio" and gpio_cmds) or (comp.kind == "sensor"
                                                           and sensor_cmds):
                    self.commands[f"{comp.name}/{itf.name}"] = hw
            for itf in comp.command_interfaces:
                self.commands[f"{comp.name}/{itf.name}"] = hw
        self.connected = True

    def identify(self) -> dict:
        return {"plugin": self.hw.plugin, "type": self.hw.type, "params": dict(self.hw.params)}

    def read(self) -> dict[str, float]:
        self.stats["packets"] += 1
        return self.values

    def set_command(self, name: str, value: float) -> None:
        hw = self.commands.get(name)
        if hw is None:
            raise InvalidInput(f"{name} is not a command interface of {self.hw.name} "
                               f"(commands: {', '.join(sorted(self.commands))})")
        if _flag(hw, "disable_commands"):
            return
        comp_name, _, itf = name.rpartition("/")
        now = time.monotonic()
        offset = float(hw.params.get("position_state_following_offset", "0") or 0)
        custom = hw.params.get("custom_interface_with_following_offset", "")
        target = itf
        if itf == "position" and offset and custom:
            target = custom
        elif itf != "position":
            offset = 0.0
        if _flag(hw, "calculate_dynamics") and itf in ("position", "velocity"):
            dt = now - self._last_write.get(name, now)
            previous = self.values.get(f"{comp_name}/position", 0.0)
            if itf == "position":
                self.values[f"{comp_name}/velocity"] = (value - previous) / dt if dt > 0 else 0.0
            else:
                self.values[f"{comp_name}/position"] = previous + value * dt
        self._last_write[name] = now
        if f"{comp_name}/{target}" in self.values:
            self.values[f"{comp_name}/{target}"] = value + offset

    def move(self, targets: dict[str, float], velocity: float | None = None,
             progress: Progress | None = None) -> MoveResult:
        """Position commands, mirrored to the states at once: one cycle, reported to the
        ``on_cycle`` hook with the state before the commands and after them."""
        hook = self.on_cycle
        if hook is not None:
            nan = float("nan")
            setpoints = {j: (t, nan, nan) for j, t in targets.items()}
            hook(time.time_ns(), dict(self.values), setpoints)
        for joint, value in targets.items():
            self.set_command(f"{joint}/position", value)
        if hook is not None:
            hook(time.time_ns(), self.values, setpoints)
        return MoveResult(True, 0.0, {j: 0.0 for j in targets}, [])

    def detect(self) -> dict:
        parts = [{"name": c.name, "kind": c.kind,
                  "states": [i.name for i in c.state_interfaces]}
                 for c in self.hw.components()]
        return {"parts": parts, "checks": [], "summary": f"{len(parts)} simulated parts"}

    def config_read(self) -> dict[str, dict[str, dict[str, Any]]]:
        """Every state interface's value, by part; writable where a command interface of the
        same name (or a mock_*_commands param) feeds it."""
        parts: dict[str, dict[str, dict[str, Any]]] = {}
        for comp in self.hw.components():
            for itf in comp.state_interfaces:
                key = f"{comp.name}/{itf.name}"
                parts.setdefault(comp.name, {})[itf.name] = {
                    "value": self.values.get(key, 0.0),
                    "access": "RW" if key in self.commands else "R"}
        return parts

    def config_write(self, changes: dict[str, dict[str, Any]],
                     allow: frozenset[str] = frozenset()) -> dict[str, dict[str, Any]]:
        """Each value as a command, mirrored to its state as the mock does; read back. A
        joint's position, velocity or effort is a command like any other: outside the safety
        envelope it is refused before anything is written (a snapshot is untrusted)."""
        import math

        from deltoctl.core.envelope import check_command

        joints = {j.name: j for j in self.hw.joints}
        for part, items in changes.items():
            for name, value in items.items():
                if f"{part}/{name}" not in self.commands:
                    raise InvalidInput(f"{part}/{name} is not a command interface of "
                                       f"{self.hw.name}")
                if (not isinstance(value, (int, float)) or isinstance(value, bool)
                        or not math.isfinite(value)):
                    raise InvalidInput(f"{part}/{name} takes a number, not {value!r}")
                if part in joints:
                    check_command(self.profile, joints[part], name, float(value),
                                  self.values.get(f"{part}/position"))
        for part, items in changes.items():
            for name, value in items.items():
                self.set_command(f"{part}/{name}", float(value))
        return {part: {name: self.values.get(f"{part}/{name}") for name in items}
                for part, items in changes.items()}

    def stop(self) -> None:
        """Nothing moves on its own in the mock: holding the last command is the safe state."""

    def cleanup(self) -> None:
        self.connected = False
