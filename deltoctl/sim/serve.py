"""Serve the simulated devices of a profile — every block whose family has an emulator — with
the faults asked for. One code path for ``--sim``, ``deltoctl sim serve`` and the pytest
fixture: each family's emulator (named in its descriptor) serves its blocks behind a real
transport and returns each bus's target URL, which the System opens like hardware."""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, fields
from typing import Any

from deltoctl import registry
from deltoctl.errors import InvalidInput
from deltoctl.profile.model import Component, Hardware, Profile


@dataclass
class ServeOptions:
    host: str = "127.0.0.1"
    port: int = 0  # a TCP device's port (0: any free one)
    # a gripper
    firmware: str = "3.0"  # MAJOR.MINOR
    model_id: int | None = None  # another model than the profile's
    short_version: bool = False
    input_1: bool = False
    delay: float = 0.0  # s before every reply
    stall: tuple[str, ...] = ()  # joints that cannot move
    # the buses
    missing: tuple[str, ...] = ()  # joints that never answer
    pace: bool = False  # serial buses take the wire time of every byte
    wrong_baud: tuple[str, ...] = ()  # servos at another baud rate than their bus
    who_am_i: int = 0x6A
    orientation: tuple[float, ...] = (0.0, 0.0)  # the IMU's roll, pitch (and yaw), degrees


JOINT_OPTIONS = ("stall", "missing", "wrong_baud")  # options that name joints
ALWAYS = ("host", "port")


class ServeContext:
    """What an emulator gets: the options, the stack that closes what it starts, and the
    simulated I2C buses that devices of several families share."""

    def __init__(self, stack: contextlib.ExitStack, profile: Profile,
                 options: ServeOptions) -> None:
        self.stack, self.profile, self.options = stack, profile, options
        self.blocks: dict[str, dict[str, Any]] = {}  # what each block's emulator reports
        self._i2c: dict[str, tuple[Any, str]] = {}

    def named(self, option: str, hw: Hardware) -> list[Component]:
        """The joints of this block that a joint option (``missing`` …) names."""
        names = getattr(self.options, option)
        return [j for j in hw.joints if j.name in names]

    def i2c_bus(self, bus: str) -> tuple[Any, str]:
        """``(simulated bus, target URL)`` for a bus name, served once on loopback; each
        family adds its devices to the bus's ``devices``."""
        if bus not in self._i2c:
            from deltoctl.sim.i2c_bus import I2CSocketServer, SimSMBus

            sim = SimSMBus({})
            server = self.stack.enter_context(I2CSocketServer(sim, host=self.options.host))
            self._i2c[bus] = (sim, server.url)
        return self._i2c[bus]


def serve_profile(stack: contextlib.ExitStack, prof: Profile, options: ServeOptions,
                  hardware: list[str] | tuple[str, ...] = ()) -> dict[str, Any]:
    """Start the simulated devices of the profile's blocks (or of those ``hardware`` names),
    closed with ``stack``. Returns ``{"profile", "buses": {bus: target URL}, "blocks":
    {block: what its emulator reports}}``, and ``endpoint`` when there is one bus."""
    from deltoctl.core.system import select_blocks

    blocks = select_blocks(prof, hardware)
    by_family: dict[str, list[Hardware]] = {}
    families: dict[str, registry.Family | None] = {}
    for hw in blocks:
        family = registry.of_block(prof.family_of(hw), hw.plugin)
        name = family.name if family else prof.family_of(hw) or hw.plugin
        by_family.setdefault(name, []).append(hw)
        families[name] = family
    _check_options(prof, blocks, options, [f for f in families.values() if f])
    ctx = ServeContext(stack, prof, options)
    buses: dict[str, str] = {}
    for name, family in families.items():
        serve = family.emulator_function() if family else None
        if serve is not None:
            buses.update(serve(ctx, by_family[name]))
    if not buses and not any(f and not f.schemes for f in families.values()):
        raise InvalidInput(f"no simulator for the blocks of {prof.name!r} "
                           f"(families: {', '.join(n or 'none' for n in by_family)})")
    result: dict[str, Any] = {"profile": prof.name, "buses": buses, "blocks": ctx.blocks}
    if len(buses) == 1:
        result["endpoint"] = next(iter(buses.values()))
    return result


def _check_options(prof: Profile, blocks: list[Hardware], options: ServeOptions,
                   families: list[registry.Family]) -> None:
    """Every option set is one the profile's families take; every joint named is there."""
    defaults = ServeOptions()
    taken = {o for f in families for o in f.serve_options} | set(ALWAYS)
    flag = {f.name: "--" + f.name.replace("_", "-") for f in fields(options)}
    misplaced = [flag[f.name] for f in fields(options)
                 if f.name not in taken and getattr(options, f.name) != getattr(defaults, f.name)]
    if misplaced:
        allowed = sorted(flag[o] for o in taken - set(ALWAYS))
        raise InvalidInput(f"{', '.join(misplaced)}: not for {prof.name} "
                           f"(its simulator takes: {', '.join(allowed) or 'no options'})")
    joints = {j.name for hw in blocks for j in hw.joints}
    for option in JOINT_OPTIONS:
        for name in getattr(options, option):
            if name not in joints:
                raise InvalidInput(f"{flag[option]}: {prof.name} has no joint {name!r}")
