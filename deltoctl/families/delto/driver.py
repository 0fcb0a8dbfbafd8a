"""The Delto driver: the host side of the protocol session over a TCP link, mapped to
ros2_control interface names.

Packet sizes come from the model the gripper *reports* (a configured model that differs is an
error unless allowed). A lost link sets ``system/connection_status`` to 0 and starts a
background reconnect, timed by the exchange policy's reopener (1 s apart, 10 tries a round,
rounds repeating); reads meanwhile return the last values and writes are skipped, so a loop
keeps its rate and a recording goes on. A reopened link gets duty 0 before anything else.
"""

from __future__ import annotations

import re
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from math import isfinite
from operator import itemgetter, mul
from typing import Any

from deltoctl.core.driver import Block, Driver, MoveResult, Progress
from deltoctl.core.exchange import ExchangePolicy, Reopener
from deltoctl.errors import (
    DeltoctlError,
    DeviceError,
    InvalidInput,
    LinkLost,
    NoAnswer,
    ProtocolError,
    Unreachable,
)
from deltoctl.families.delto import codec
from deltoctl.families.delto.models import (
    DUTY_WIRE_LIMIT,
    FT_6AXIS,
    FT_TYPES,
    MODELS,
    SENSOR_NAMES,
    SENSOR_NONE,
    TACTILE_GRIDS,
    CurrentLimiter,
    DeltoModel,
    effort_to_duty_percent,
    model_label,
    sensor_label,
)
from deltoctl.families.delto.motion import effort_cap, move_to
from deltoctl.families.delto.session import NEED_DATA, Reply, Role, Session
from deltoctl.transport.tcp import TcpLink, parse_tcp_url

VERSION_TIMEOUT = 3.0
STOP_TIMEOUT = 0.3  # s: the one quick reconnection a stop tries on a lost link
# one try of a GET_DATA (a link that misses a reply is reopened); a lost link tried again
# every second, 10 tries a round, rounds repeating until it is back
POLICY = ExchangePolicy(tries=1, timeout=0.5, reopen_period=1.0, reopen_tries=10)
DIP_SWITCHES = "DIP switches 2 and 4"  # developer mode's


@dataclass
class Identity:
    configured_model: int
    reported_model: int
    firmware: tuple[int, int]
    sensor_type: int | None
    finger_mask: int | None
    short_version: bool
    direction: tuple[int, ...]
    direction_map: str

    def as_dict(self) -> dict:
        return {
            "configured_model": model_label(self.configured_model),
            "reported_model": model_label(self.reported_model),
            "model_match": self.configured_model == self.reported_model,
            "firmware": f"{self.firmware[0]}.{self.firmware[1]}",
            "sensor_type": SENSOR_NAMES.get(self.sensor_type, "unknown")
            if self.sensor_type is not None else None,
            "finger_mask": self.finger_mask,
            "short_version_reply": self.short_version,
            "direction_map": self.direction_map,
            "direction": list(self.direction),
        }


class DeltoDriver(Driver):
    def __init__(self, block: Block) -> None:
        super().__init__(block)
        hw = block.hw
        self.host, self.port = parse_tcp_url(block.url, codec.DEFAULT_PORT)
        try:
            self.configured_model = int(hw.params.get("delto_model", "0"), 0)
        except ValueError:
            raise InvalidInput(f"delto_model {hw.params.get('delto_model')!r} of {hw.name!r} "
                               "is not a number") from None
        self.fingertip_sensor = hw.params.get("fingertip_sensor") == "true"
        self.io = hw.params.get("IO") == "true"
        self.allow_model_mismatch = block.allow_model_mismatch
        self.link: TcpLink | None = None
        self.session: Session | None = None  # the link's conversation
        self.identity: Identity | None = None
        self.model = MODELS.get(self.configured_model)
        self.codes: tuple[int, ...] = ()
        self.limiters = [CurrentLimiter() for _ in hw.joints]
        self._duty_plan: tuple = (None, [])
        self._last_duty: tuple[list[int], bytes] = ([], b"")  # duties, their SET_DUTY
        self._request = b""  # GET_DATA with this connection's data codes
        self._reply_plan: tuple = ()
        self._pending: TcpLink | None = None  # a GET_DATA sent by start_read, reply not yet read
        self._lock = threading.RLock()
        self.policy = POLICY
        self.reopener = Reopener(POLICY)
        self._reconnecting = False
        self._connecting = threading.Lock()  # one connection attempt at a time
        self._closed = False
        self._driving = False  # a duty was sent since the last stop: only then is there one
        self._closing = threading.Event()  # wakes the reconnect thread to end it
        self._last_read = 0.0
        joints = [j.name for j in hw.joints]
        self._effort_keys = frozenset(f"{j}/effort" for j in joints)
        gpio = hw.gpios[0].name if hw.gpios else "gpio"
        # fingertip sensors, finger by finger in the profile's order: F/T, or tactile grids
        self.ft_sensors = [s for s in hw.sensors if s.state("force.x")]
        self.tactile_sensors = [s for s in hw.sensors
                                if any(i.name.startswith("cell_") for i in s.state_interfaces)]
        for s in self.tactile_sensors:
            _check_tactile_params(s)
        if (self.ft_sensors or self.tactile_sensors) and not self.fingertip_sensor:
            self.warnings.append(f"{hw.name}: the profile declares fingertip sensors but "
                                 "fingertip_sensor is not true: the gripper sends no values "
                                 "for them")
        self._keys = {  # interface names, built once: the cycle only zips values in
            **{k: [f"{j}/{k}" for j in joints]
               for k in ("position", "velocity", "effort", "temperature")},
            "ft": [[f"{s.name}/{axis}" for axis in ("force.x", "force.y", "force.z",
                                                    "torque.x", "torque.y", "torque.z")]
                   for s in self.ft_sensors],
            "gpio": [f"{gpio}/{n}" for n in ("output_1", "output_2", "output_3", "input_1")],
        }
        self.timing: dict[str, float] | None = None  # seconds per stage, when benchmarking

    # -- lifecycle -----------------------------------------------------------------------------
    def configure(self) -> None:
        self._connect()

    def identify(self) -> dict:
        assert self.identity is not None
        return self.identity.as_dict()

    def _connect(self, timeout: float = VERSION_TIMEOUT, reopening: bool = False) -> None:
        """A link, its GET_VERSION exchange and what it says; ``reopening`` a lost link: duty 0
        goes out and the reconnect is counted before the link is anyone else's."""
        try:
            link = TcpLink(self.host, self.port, connect_timeout=timeout)
        except Unreachable as exc:
            exc.hint = f"{exc.hint} (Delto: developer mode, {DIP_SWITCHES})"
            raise
        session = Session(Role.HOST)
        try:
            link.send(session.send(codec.encode_version_request()))
            reply = receive(link, session, timeout)
        except (LinkLost, NoAnswer, ProtocolError) as exc:  # something listens there, but
            link.close()  # it is not a gripper answering
            raise Unreachable(f"no version reply: {exc}", hint="check that the gripper is in "
                              f"developer mode ({DIP_SWITCHES}): in operator "
                              "mode it speaks Modbus TCP on the same port") from None
        try:
            info = codec.decode_version_reply(reply.frame)
        except DeviceError:
            link.close()
            raise
        actual = MODELS.get(info.model_id)
        if actual is None:
            link.close()
            raise DeviceError(f"the gripper at {self.host}:{self.port} reports an unknown "
                              f"model {info.model_id:#06x}")
        if info.model_id != self.configured_model:
            message = (f"model mismatch: the profile says {model_label(self.configured_model)}"
                       f", the gripper at {self.host}:{self.port} is {model_label(info.model_id)}")
            if not self.allow_model_mismatch:
                link.close()
                raise DeviceError(message, hint="use the profile for the connected model, "
                                  "or pass --allow-model-mismatch to go on with the reported one")
            if message not in self.warnings:
                self.warnings.append(message + " (allowed; using the reported model)")
        sensor = info.sensor_type
        short = sensor is None
        mask = info.finger_mask
        if short:  # old firmware: 6-axis F/T on every finger when the profile has fingertip
            # sensors, else none (the vendor's fallback, mask included)
            sensor = FT_6AXIS if self.fingertip_sensor else SENSOR_NONE
            mask = (1 << actual.fingers) - 1 if self.fingertip_sensor else 0
        direction = actual.direction(info.firmware)
        revised = all(d == 1 for d in direction) or actual.revised_from is None
        if reopening:  # motion never resumes by itself after a loss
            try:
                link.send(session.send(codec.encode_duty([0] * actual.motors)))
            except DeviceError:
                link.close()
                raise
        with self._lock:
            if reopening:
                self._count_reopened()
            self.link, self.session = link, session
            self.model = actual
            self.codes = codec.data_codes(actual, self.fingertip_sensor, self.io and actual.gpio)
            self._request = codec.encode_data_request(self.codes)
            self._plan_reply(actual, sensor)
            self.identity = Identity(
                self.configured_model, info.model_id, info.firmware, sensor, mask, short,
                direction, "revised" if revised else "legacy")
            self.connected = True
        self._warn_sensor_mismatch(sensor, short)

    def _warn_sensor_mismatch(self, sensor: int, short: bool) -> None:
        """A warning (exit 3) when the gripper's fingertip sensors are not the profile's: the
        declared fingertip interfaces its replies leave without values, named."""
        if not self.fingertip_sensor:
            return  # said in __init__: no fingertip values are asked for
        filled = set(self._reply_plan[2])
        missing = []  # each sensor's interfaces without values: sensor/* when none has one
        for s in [*self.ft_sensors, *self.tactile_sensors]:
            names = [i.name for i in s.state_interfaces if f"{s.name}/{i.name}" not in filled]
            if names:
                missing.append(f"{s.name}/" + ("*" if len(names) == len(s.state_interfaces)
                                               else ",".join(names)))
        if not missing:
            return
        declared = ", ".join(sorted({_grid_label(s) for s in self.tactile_sensors}))
        profile = " and ".join(filter(None, [
            "F/T sensors" if self.ft_sensors else "",
            f"tactile grids ({declared})" if self.tactile_sensors else ""]))
        reported = sensor_label(sensor) + (" (implied by its short version reply)"
                                           if short else "")
        message = (f"{self.hw.name}: fingertip sensor mismatch: the profile declares "
                   f"{profile}, the gripper at {self.host}:{self.port} reports {reported}: "
                   f"no values for {'; '.join(missing)}")
        if message not in self.warnings:
            self.warnings.append(message)

    def detect(self) -> dict:
        """Sensors, finger mask and GPIO as the gripper reports them, against the profile."""
        values = dict(self.read())
        ident, model = self.identity, self.model
        assert ident is not None and model is not None
        fingers = [f + 1 for f in range(model.fingers) if (ident.finger_mask or 0) >> f & 1]
        reported_ft = ident.sensor_type in FT_TYPES
        grid = TACTILE_GRIDS.get(ident.sensor_type or 0)
        declared = {_grid_label(s) for s in self.tactile_sensors}
        checks = [
            {"what": "fingertip F/T sensors", "profile": len(self.ft_sensors),
             "device": model.fingers if reported_ft else 0},
            {"what": "fingertip tactile grids", "profile": len(self.tactile_sensors),
             "device": model.fingers if grid else 0},
            {"what": "GPIO", "profile": bool(self.hw.gpios),
             "device": self._keys["gpio"][3] in values},
        ]
        if self.tactile_sensors or grid:
            checks.insert(2, {"what": "tactile grid (rows×cols)",
                              "profile": ", ".join(sorted(declared)) or "none",
                              "device": grid.label if grid else "none"})
        for c in checks:
            c["match"] = c["profile"] == c["device"]
        sensor = SENSOR_NAMES.get(ident.sensor_type or 0, "unknown")
        tactile = None
        if grid is not None:
            tactile = {"type": sensor, "rows": grid.rows, "cols": grid.cols,
                       "cells": grid.cells, "cell_bits": 8 if grid.code == "B" else 16,
                       "encoding": grid.encoding}
        what = sensor.upper() + (f" ({grid.label} cells per finger)" if grid else "")
        if grid and not self.tactile_sensors:
            what += (f"; the profile declares no tactile grids (a sensor per finger with "
                     f"cell_<row>_<col> interfaces, {grid.label})")
        return {
            "sensor_type": sensor,
            "fingers_with_sensor": fingers,
            "tactile": tactile,
            "gpio": {k.split("/")[1]: values[k] for k in self._keys["gpio"] if k in values},
            "checks": checks,
            "summary": f"{self.hw.name}: sensor type {what}, fingers with a sensor: "
                       f"{', '.join(map(str, fingers)) or 'none'}",
        }

    # -- configuration ---------------------------------------------------------------------------
    def config_read(self) -> dict[str, dict[str, dict[str, Any]]]:
        """What the gripper says it is (GET_VERSION: model, firmware, sensor type, finger
        mask), all read-only over this protocol; and per F/T sensor what it reads at rest
        now: the offset is set by SET_FT_SENSOR_OFFSET but has no read, so the residual
        after it is the trace it leaves (a reading, never compared)."""
        ident = self.identity
        if ident is None:
            raise DeviceError(f"{self.hw.name}: no version reply yet (the link is down)")
        fingers = [str(f + 1) for f in range(8) if (ident.finger_mask or 0) >> f & 1]
        device: dict[str, dict[str, Any]] = {
            "model": {"value": model_label(ident.reported_model), "access": "R"},
            "configured model": {"value": model_label(ident.configured_model),
                                 "access": "profile"},
            "firmware": {"value": f"{ident.firmware[0]}.{ident.firmware[1]}", "access": "R"},
            "sensor type": {"value": SENSOR_NAMES.get(ident.sensor_type or 0, "unknown"),
                            "access": "R"},
            "finger mask": {"value": ident.finger_mask, "access": "R", "min": 0, "max": 255,
                            "meaning": "fingers " + (", ".join(fingers) or "none")},
            "short version reply": {"value": ident.short_version, "access": "R"},
            "direction map": {"value": ident.direction_map, "access": "R"},
        }
        return {"gripper": device, **self._ft_residuals()}

    def _ft_residuals(self, samples: int = 10) -> dict[str, dict[str, dict[str, Any]]]:
        """Each F/T sensor's mean reading over a few cycles (N, N·m)."""
        keys = [k for sensor in self._keys["ft"] for k in sensor]
        if not keys or self.identity is None or self.identity.sensor_type not in FT_TYPES:
            return {}
        sums = dict.fromkeys(keys, 0.0)
        for _ in range(samples):
            values = self.read()
            for k in keys:
                sums[k] += values.get(k, 0.0)
        parts: dict[str, dict[str, dict[str, Any]]] = {}
        for key, total in sums.items():
            sensor, _, axis = key.partition("/")
            parts.setdefault(sensor, {})[f"residual {axis}"] = {
                "value": round(total / samples, 5), "access": "R", "state": True,
                "unit": "N" if axis.startswith("force") else "N·m"}
        return parts

    def config_write(self, changes: dict[str, dict[str, Any]],
                     allow: frozenset[str] = frozenset()) -> dict[str, dict[str, Any]]:
        """Nothing of it: the developer-mode protocol writes duties, GPIO and the F/T tare
        only."""
        names = ", ".join(f"{part} {item}" for part, items in changes.items() for item in items)
        raise InvalidInput(f"{self.hw.name}: {names or 'nothing'}: read-only over the "
                           "gripper's protocol")

    def set_command(self, name: str, value: float) -> None:
        """GPIO outputs by interface name; the three always travel together."""
        outputs = tuple(self._keys["gpio"][:3])
        if name not in outputs:
            raise InvalidInput(f"{name} is not a command interface of {self.hw.name} "
                               f"(commands: {', '.join(outputs)})")
        values = self.read()
        if self._keys["gpio"][3] not in values:
            raise DeviceError("the gripper sends no GPIO block (no GPIO on this model, or IO "
                              "is false in the profile)")
        state = [values[o] == 1.0 for o in outputs]
        state[outputs.index(name)] = value != 0
        self.set_gpio((state[0], state[1], state[2]))

    def cleanup(self) -> None:
        self._closed = True
        self._closing.set()
        with self._lock:
            if self.link:
                self.link.close()
                self.link, self.session = None, None

    # -- cyclic I/O ------------------------------------------------------------------------------
    def _plan_reply(self, model: DeltoModel, sensor_type: int) -> None:
        """Which raw value of a reply goes to which interface, with its scale: worked out once
        per connection, so a cycle is one unpack and one C-speed pass (``_store``)."""
        fields = codec.reply_fields(model, self.codes, sensor_type)
        ft_keys = [k for sensor in self._keys["ft"] for k in sensor]
        plan = [(key, field)
                for keys, name in ((self._keys["position"], "position"),
                                   (self._keys["effort"], "current"),
                                   (self._keys["temperature"], "temperature"),
                                   (self._keys["velocity"], "velocity"), (ft_keys, "ft"))
                for key, field in zip(keys, fields.get(name, ()))]
        grid = TACTILE_GRIDS.get(sensor_type)
        if grid is not None and "tactile" in fields:  # cells by name: a declared grid of
            cells = fields["tactile"]  # another size gets the cells both have
            for f, sensor in enumerate(self.tactile_sensors[: model.fingers]):
                for k in range(grid.cells):
                    name = f"cell_{k // grid.cols}_{k % grid.cols}"
                    if sensor.state(name):
                        plan.append((f"{sensor.name}/{name}", cells[f * grid.cells + k]))
        gpio = [i for i, _ in fields.get("gpio", ())]
        self._reply_plan = (model, sensor_type, [key for key, _ in plan],
                            itemgetter(*(i for _, (i, _) in plan)),
                            [scale for _, (_, scale) in plan],
                            _picker(gpio) if gpio else None,
                            codec.data_reply_unpacker(model, self.codes, sensor_type))

    def start_read(self) -> None:
        """Send GET_DATA; ``read`` takes the reply (another gripper's request goes out
        meanwhile)."""
        link, session = self.link, self.session
        if link is None or session is None or self._pending is not None:
            return
        try:
            link.send(session.send(self._request))
        except DeviceError as exc:
            self.stats["errors"] += 1
            self._lost(exc)
            return
        self._pending = link

    def read(self) -> dict[str, float]:
        """One GET_DATA exchange; on a lost link, the last values (``connected`` false)."""
        with self._lock:
            link, session, identity = self.link, self.session, self.identity
        pending, self._pending = self._pending, None
        if link is None or session is None or identity is None:
            self._start_reconnect()
            return self.values
        self.stats["packets"] += 1
        unpack = self._reply_plan[6]
        timing = self.timing
        try:
            t0 = time.perf_counter()
            if pending is not link:
                link.send(session.send(self._request))
            reply = receive(link, session, self.policy.timeout)
            t1 = time.perf_counter()
            raw = unpack(reply.frame)
        except DeviceError as exc:
            self.stats["errors"] += 1
            self._lost(exc)
            return self.values
        self._store(raw)
        if timing is not None:
            timing["socket"] += t1 - t0
            timing["codec"] += time.perf_counter() - t1
        return self.values

    def _store(self, raw: tuple[int, ...]) -> None:
        v = self.values
        model, _, keys, pick, scales, gpio, _ = self._reply_plan
        if model.legacy:  # the DG-3F-B sends no velocity: differentiate the position
            now = time.monotonic()
            dt = now - self._last_read if self._last_read else 0.0
            self._last_read = now
            before = [v.get(k) for k in self._keys["position"]]
        v.update(zip(keys, map(mul, pick(raw), scales)))
        if gpio is not None:  # each input and output: 1.0 or 0.0
            v.update(zip(self._keys["gpio"], map(float, map(bool, gpio(raw)))))
        if model.legacy:
            for key, pos_key, previous in zip(self._keys["velocity"], self._keys["position"],
                                              before):
                v[key] = (v[pos_key] - previous) / dt if previous is not None and dt > 0 else 0.0

    def write(self, commands: dict[str, float]) -> None:
        """Effort commands (``joint/effort``) in one SET_DUTY; GPIO outputs by name."""
        if commands.keys() <= self._effort_keys:  # the cycle's case: efforts only
            self._write_duties(commands.get, 1)
            return
        efforts = {}
        for name, value in commands.items():
            if name in self._effort_keys:
                efforts[name] = value
            else:
                self.set_command(name, value)
        if efforts:
            self._write_duties(efforts.get, 1)

    def write_efforts(self, efforts: dict[str, float]) -> None:
        """Effort commands (N·m) by joint name → current limiter → duty → direction →
        SET_DUTY."""
        self._write_duties(efforts.get, 0)

    def _write_duties(self, get: Callable[[str], float | None], by: int) -> None:
        """``get`` gives each joint's effort by its name (``by`` 0) or its interface (1)."""
        identity, model = self.identity, self.model
        if identity is None or model is None:
            return
        plan = self._duty_plan
        if plan[0] is not identity:  # per joint, worked out once per connection
            joints = self.hw.joints[: model.motors]
            steps = [(j.name, f"{j.name}/effort", self.limiters[i], identity.direction[i])
                     for i, j in enumerate(joints)]
            plan = self._duty_plan = (identity, steps, ([s[0] for s in steps],
                                                        [s[1] for s in steps]),
                                      codec.encode_duty([0] * model.motors))
        targets = list(map(get, plan[2][by]))
        if not any(targets):  # no joint commanded, or 0 for each: duty 0 on every motor
            self._send(plan[3])
            return
        values = self.values
        duties = []
        for target, (_, effort_key, limiter, direction) in zip(targets, plan[1]):
            if not target or not isfinite(target):  # NaN would clamp to full duty: stop
                duties.append(0)
                continue
            limited = limiter(target, values.get(effort_key, 0.0))
            if (limited > 0) != (target > 0):
                duties.append(0)  # the limiter shrinks a command, never reverses it
                continue
            duty = int(effort_to_duty_percent(limited) * 10)
            duties.append(max(-DUTY_WIRE_LIMIT, min(DUTY_WIRE_LIMIT, duty)) * direction)
        duties += [0] * (model.motors - len(duties))
        self._driving = True
        if duties != self._last_duty[0]:  # a command held from cycle to cycle: encoded once
            self._last_duty = (duties, codec.encode_duty(duties))
        self._send(self._last_duty[1])

    def move(self, targets: dict[str, float], velocity: float | None = None,
             progress: Progress | None = None) -> MoveResult:
        """A current-bounded position loop on the effort interface (motion.py)."""
        return move_to(self, targets, velocity=velocity, progress=progress)

    def effort_cap(self) -> float:
        """The profile's current cap as an effort: what a move commands at most."""
        return effort_cap(self.profile)

    def follow(self, setpoints: dict[str, tuple[float, float, float]]) -> None:
        """Recorded efforts (``replay``), clamped to the current cap as a move's are; a joint
        without one (NaN) gets duty 0."""
        cap = self.effort_cap()
        self.write_efforts({j: max(-cap, min(cap, sp[2])) for j, sp in setpoints.items()
                            if isfinite(sp[2])})

    def stop(self) -> None:
        """The safe state: duty 0 on every motor, once this session sent a duty (a gripper
        it never drove keeps what holds it, a grasp). With the link down (a gripper keeps its
        last duty), one immediate reconnection is tried first: a stop must reach it."""
        if self.model is None or not self._driving:
            return
        if self.link is None and not self._closed and self._connecting.acquire(timeout=1.0):
            try:
                if self.link is None:
                    self._connect(STOP_TIMEOUT)
            except DeltoctlError:
                self.warnings.append(f"{self.hw.name}: unreachable to stop; check that it "
                                     "stopped")
            finally:
                self._connecting.release()
        self._send(codec.encode_duty([0] * self.model.motors))
        self._driving = self.link is None  # not sent: the next stop (closing) tries again

    def make_safe(self) -> None:
        """Duty 0 on every motor, though this session sent none (a gripper keeps the last
        duty of a process that was killed)."""
        self._driving = True
        self.stop()

    def set_gpio(self, outputs: tuple[bool, bool, bool]) -> None:
        if self.model is None or not self.model.gpio:
            raise DeviceError(f"{self.model.name if self.model else 'this gripper'} has no GPIO")
        self._send(codec.encode_gpio(outputs))

    def tare_ft(self) -> None:
        ident = self.identity
        if ident is None or ident.sensor_type not in FT_TYPES or not self.fingertip_sensor:
            raise DeviceError(self.no_ft_reason(), hint="deltoctl detect shows what it has")
        self._send(codec.encode_ft_offset())

    def no_ft_reason(self) -> str | None:
        """Why this gripper has no F/T values to tare (None: it has them)."""
        ident = self.identity
        where = f"{self.hw.name} ({self.host}:{self.port})"
        if ident is None:
            return f"{where}: no version reply yet (the link is down)"
        if not self.fingertip_sensor:
            return (f"{where}: fingertip_sensor is false in the profile, so the gripper "
                    "sends no fingertip values")
        if ident.sensor_type in FT_TYPES:
            return None
        if ident.sensor_type in TACTILE_GRIDS:
            return (f"{where} reports tactile fingertips ({sensor_label(ident.sensor_type)}),"
                    " not F/T sensors")
        return (f"{where} reports no fingertip sensors (sensor type "
                f"{sensor_label(ident.sensor_type)})")

    def _send(self, data: bytes) -> None:
        with self._lock:
            link, session = self.link, self.session
        if link is None or session is None:
            return
        try:
            link.send(session.send(data))
        except DeviceError as exc:
            self._lost(exc)

    # -- reconnect -------------------------------------------------------------------------------
    def _lost(self, exc: Exception) -> None:
        with self._lock:
            if self.link is not None:
                self.link.close()
                self.link, self.session = None, None
            self.connected = False
        self._start_reconnect()

    def _start_reconnect(self) -> None:
        with self._lock:
            if self._reconnecting or self._closed:
                return
            self._reconnecting = True
            self.reopener.lost()
        threading.Thread(target=self._reconnect_loop, name="delto-reconnect", daemon=True).start()

    def _reconnect_loop(self) -> None:
        """Reopen the link when the reopener says, until it is back or the driver closes."""
        reopener, closing = self.reopener, self._closing
        try:
            while not closing.wait(self.policy.reopen_period):
                while not reopener.due():  # a period is over; the clock may say not quite
                    if closing.wait(0.01):
                        return
                with self._connecting:
                    try:
                        if self.link is None:
                            self._connect(reopening=True)
                        else:  # a stop reopened it meanwhile
                            with self._lock:
                                self._count_reopened()
                    except DeltoctlError:
                        reopener.failed()  # the next round starts as the last one did
                        continue
                return
        finally:
            self._reconnecting = False

    def _count_reopened(self) -> None:
        self.reopener.reopened()
        self.stats["reconnects"] += 1


def receive(link: TcpLink, session: Session, timeout: float) -> Reply:
    """The reply ``session`` expects next, received over ``link``: NoAnswer when none
    arrives within ``timeout`` seconds (nor the rest of one within ``timeout`` of its first
    bytes); ProtocolError, from then on, when the bytes break the protocol."""
    event = session.next_event()
    deadline = 0.0
    while event is NEED_DATA:
        count = link.recv_into(session.room(), timeout)
        if not count:
            raise NoAnswer(f"no complete reply from {link.host}:{link.port} within "
                           f"{timeout:g} s ({session.buffered} bytes received)")
        session.received(count)
        event = session.next_event()
        if event is NEED_DATA:  # a reply in pieces (rare): the rest within what is left
            deadline = deadline or time.monotonic() + timeout
            timeout = deadline - time.monotonic()
    return event  # type: ignore[return-value]  # a host's session gives replies


def _picker(indices: list[int]) -> Callable[[tuple[int, ...]], tuple[int, ...]]:
    """The values at ``indices``, always as a tuple (``itemgetter`` of one gives the value)."""
    if len(indices) == 1:
        return lambda raw, i=indices[0]: (raw[i],)
    return itemgetter(*indices)


TOPIC_PART = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def _check_tactile_params(sensor: Any) -> None:
    """A tactile sensor's params, from an untrusted profile: the Image's encoding and topic."""
    encoding = sensor.params.get("encoding", "mono16")
    if encoding not in ("mono8", "mono16"):
        raise InvalidInput(f"sensor {sensor.name!r}: encoding {encoding!r} is not mono8 or "
                           "mono16")
    topic = sensor.params.get("topic")
    if topic is not None and not all(TOPIC_PART.fullmatch(p) for p in topic.strip("/").split("/")):
        raise InvalidInput(f"sensor {sensor.name!r}: topic {topic!r} is not a ROS topic name "
                           "(parts of letters, digits and _, joined by /)")


def _grid_label(sensor: Any) -> str:
    """A declared grid's rows×cols, from its ``cell_<row>_<col>`` interfaces."""
    cells = [i.name.split("_")[1:] for i in sensor.state_interfaces
             if i.name.startswith("cell_")]
    try:
        return f"{max(int(r) for r, _ in cells) + 1}×{max(int(c) for _, c in cells) + 1}"
    except ValueError:
        return "?"
