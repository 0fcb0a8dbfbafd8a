"""The Bioscara arm: four uStepper joints on one I2C bus (reference §1.2-1.6).

Joints read position, velocity and their flags every cycle; motion needs the joint homed and
enabled; homing runs each joint into its hard stop in the profile's order and stores the
offset in the joint (HOMEOFFSET), so it survives a host restart while the joint is powered.
A verb leaves every joint it commanded stopped and disabled (back-drivable), as the Bioscara
hardware interface does on deactivate.
"""

from __future__ import annotations

import math
import time
from typing import Any

from deltoctl import registry
from deltoctl.core.driver import Block, Driver, HomeProgress, MoveResult, Progress
from deltoctl.core.exchange import ExchangePolicy
from deltoctl.errors import (
    DeltoctlError,
    DeviceError,
    DeviceFault,
    InvalidInput,
    NoAnswer,
    NotHomed,
    Refused,
)
from deltoctl.families.bioscara import codec
from deltoctl.profile.model import Component
from deltoctl.transport import i2c
from deltoctl.transport.i2c import I2CBus  # what every I2C link gives

POLL_HOMING = 0.1  # s between flag polls while homing, as the Bioscara driver does
POLL_MOVE = 0.02
TOLERANCE = 1e-3  # rad or m: the closed-loop steppers settle far closer than this
# a position move raises no flag: a joint has arrived when it is within tolerance, not BUSY,
# and its encoder says it is still (under STILL of its profile's speed) this many reads in a row
SETTLE_READS = 3
STILL = 0.05
SCAN = range(0x08, 0x78)  # the addresses i2cdetect scans
NAN = float("nan")
POLICY = ExchangePolicy(tries=3, pause=50e-6)  # as the Bioscara driver's I2C layer


def transfer(bus: I2CBus, address: int, data: bytes, length: int) -> bytes:
    """One combined transaction under the joints' exchange policy (i2c.exchange)."""
    return i2c.exchange(bus, address, lambda: bus.transfer(address, data, length), POLICY.run,
                        POLICY.tries)


def _encoded(request: codec.Request) -> tuple[codec.Request, tuple[bytes, int]]:
    return request, codec.Host.encode(request)


FLOAT32_MAX = 3.4028234663852886e38  # the largest value a joint's float register holds


class Joint:
    """The master side of one joint: its register commands, flags and transmission."""

    def __init__(self, bus: I2CBus, comp: Component) -> None:
        p = comp.params
        try:
            self.address = int(str(p["i2c_address"]), 16)
            self.reduction = float(p["reduction"])
            self.low, self.high = float(p["min"]), float(p["max"])
            self.drive, self.hold = int(p["drive_current"]), int(p["hold_current"])
            self.stall_threshold = int(p["stall_threshold"])
            self.max_acceleration = float(p["max_acceleration"])
            self.max_velocity = float(p["max_velocity"])
            home = comp.command("home")  # its params: speed, threshold, current, acceleration
            self.homing = {k: float(v) for k, v in (home.params if home else {}).items()}
        except (KeyError, ValueError) as exc:
            raise InvalidInput(f"joint {comp.name}: param {exc} is missing or not a number "
                               "(i2c_address, reduction, min, max, drive_current, hold_current, "
                               "stall_threshold, max_acceleration, max_velocity, and the home "
                               "interface's speed, threshold, current, acceleration)") from None
        wide = {k: v for k, v in (("max_acceleration", self.max_acceleration),
                                  ("max_velocity", self.max_velocity), *self.homing.items())
                if not abs(v) <= FLOAT32_MAX}
        if wide:
            named = ", ".join(f"{k} {v:g}" for k, v in wide.items())
            raise InvalidInput(f"joint {comp.name}: {named}: the joint takes a 32-bit float, "
                               f"up to {FLOAT32_MAX:.3g}")
        if not 0 < self.max_velocity < math.inf:  # every move's speed and time divide by it
            raise InvalidInput(f"joint {comp.name}: max_velocity {self.max_velocity:g} must be a "
                               "speed above 0")
        self.bus, self.name = bus, comp.name
        self.offset = 0.0
        self.flags = codec.INITIAL_FLAGS
        self.mode: str | None = None  # the command interface in use
        # the requests of every cycle, encoded once
        self._position = _encoded(codec.read(codec.ANGLEMOVED))
        self._rpm = _encoded(codec.read(codec.GETENCODERRPM))
        self._ping = _encoded(codec.read(codec.PING))

    # flags
    @property
    def homed(self) -> bool:
        return not self.flags & codec.NOTHOMED

    @property
    def stalled(self) -> bool:
        return bool(self.flags & codec.STALL)

    @property
    def busy(self) -> bool:
        return bool(self.flags & codec.BUSY)

    # wire: through the host role of the codec
    def exchange(self, request: codec.Request,
                 encoded: tuple[bytes, int] | None = None) -> codec.Reply:
        data, length = encoded or codec.Host.encode(request)
        reply = codec.Host.decode(request, transfer(self.bus, self.address, data, length))
        self.flags = reply.flags
        return reply

    def command(self, request: codec.Request) -> int:
        return self.exchange(request).flags

    def _get(self, request: codec.Request, encoded: tuple[bytes, int] | None = None) -> float:
        value = self.exchange(request, encoded).value
        assert value is not None  # a float read's reply has one
        return value

    def ping(self) -> int:
        return self.exchange(*self._ping).flags

    def position(self) -> float:
        return codec.from_motor_degrees(self._get(*self._position), self.reduction, self.offset)

    def velocity(self) -> float:
        return codec.from_motor_rpm(self._get(*self._rpm), self.reduction)

    def read_home_offset(self) -> float:
        return self._get(codec.read(codec.HOMEOFFSET))

    # commands
    def activate(self) -> None:
        """Enable (drive, hold), stall guard, and the joint's acceleration and velocity."""
        self.command(codec.setup_command(self.drive, self.hold))
        if self.stall_threshold > 0:
            self.command(codec.u8_command(codec.ENABLESTALLGUARD, self.stall_threshold))
        self.set_limits(self.max_acceleration, self.max_velocity)

    def set_limits(self, acceleration: float, velocity: float) -> None:
        scale = abs(self.reduction)  # joint units → motor degrees
        self.command(codec.float_command(codec.SETMAXACCELERATION,
                                         codec.to_motor_degrees(acceleration, scale, 0.0)))
        self.command(codec.float_command(codec.SETMAXVELOCITY,
                                         codec.to_motor_degrees(velocity, scale, 0.0)))

    def stop(self) -> None:
        self.command(codec.u8_command(codec.STOP, 0))

    def disable(self) -> None:
        """stop → hold current 0 → drive current 0 → freewheel: back-drivable."""
        self.stop()
        self.command(codec.u8_command(codec.SETHOLDCURRENT, 0))
        self.command(codec.u8_command(codec.SETCURRENT, 0))
        self.command(codec.u8_command(codec.SETBRAKEMODE, 0))
        self.mode = None

    def claim(self, mode: str) -> None:
        """One command interface per joint; position and velocity only once homed."""
        if self.mode not in (None, mode):
            raise Refused(f"{self.name} is commanded through {self.mode}; stop it before "
                          f"commanding {mode}")
        if mode != "home" and not self.homed:
            raise NotHomed(f"{self.name} is not homed: position and velocity commands are "
                          "refused", hint="run `deltoctl home` first")
        if self.busy:
            raise Refused(f"{self.name} is busy with a blocking command ({codec.ERRORS[-109]})")
        self.mode = mode

    def set_position(self, position: float) -> None:
        self.claim("position")
        self._after_motion(self.command(codec.float_command(
            codec.MOVETOANGLE, codec.to_motor_degrees(position, self.reduction, self.offset))))

    def set_velocity(self, velocity: float) -> None:
        """A velocity set point; the joint's deadman stops it unless one comes every 50 ms."""
        self.claim("velocity")
        self._after_motion(self.command(codec.float_command(
            codec.SETRPM, codec.to_motor_rpm(velocity, self.reduction))))

    def _after_motion(self, flags: int) -> None:
        if flags & codec.NOTENABLED:
            raise DeviceFault(f"{self.name} is {codec.ERRORS[codec.NOT_ENABLED]}",
                              codec.NOT_ENABLED)

    def start_homing(self) -> None:
        """HOME toward the hard stop the homing speed points at; that stop becomes the offset."""
        speed = self.homing.get("speed", 0.0)
        if not speed:
            raise InvalidInput(f"{self.name}: the home interface has no speed param")
        self.claim("home")
        self.activate()
        self.set_limits(self.homing.get("acceleration", self.max_acceleration),
                        self.max_velocity)
        self.offset = self.high if speed > 0 else self.low
        self.command(codec.home_command(codec.to_motor_rpm(speed, self.reduction),
                                        int(self.homing.get("threshold", 0)),
                                        int(self.homing.get("current", self.drive))))

    def finish_homing(self) -> None:
        self.set_limits(self.max_acceleration, self.max_velocity)
        self.stop()
        if not self.ping() & codec.NOTHOMED:
            self.command(codec.float_command(codec.HOMEOFFSET, self.offset))
        self.disable()


class BioscaraDriver(Driver):
    extra_states = ("flags",)  # recorded beside each joint's state interfaces

    def __init__(self, block: Block) -> None:
        super().__init__(block)
        self.bus: I2CBus | None = None
        self.joints: dict[str, Joint] = {}
        self.present: list[Joint] = []
        self.touched: set[str] = set()  # joints this session commanded, stopped at the end
        self._followed: dict[str, tuple[float, float]] = {}  # replayed goals and speeds

    @property
    def stats(self) -> dict[str, int]:
        bus = self.bus.stats if self.bus else {"packets": 0, "errors": 0}
        return {"packets": bus["packets"], "errors": bus["errors"], "reconnects": 0}

    def configure(self) -> None:
        self.bus = registry.open_link(self.url, self.block.links)  # by its scheme
        self.joints = {c.name: Joint(self.bus, c) for c in self.hw.joints}
        for joint in self.joints.values():
            try:
                joint.ping()
            except NoAnswer:
                continue
            if joint.homed:  # the offset survived in the joint while it stayed powered
                joint.offset = joint.read_home_offset()
            self.present.append(joint)
        self.roll_call([j.name for j in self.joints.values() if j not in self.present],
                       bool(self.present), "joint",
                       "check the joints' power and the I2C wiring, then run deltoctl detect "
                       "to see what the bus holds")
        self.connected = True

    def identify(self) -> dict:
        joints: dict[str, dict] = {}
        for name, j in self.joints.items():
            answers = j in self.present
            joints[name] = {"address": f"{j.address:#04x}", "answers": answers}
            if answers:
                joints[name].update(flags=codec.describe_flags(j.flags), homed=j.homed,
                                    home_offset=round(j.offset, 6) if j.homed else None)
        return {"bus": self.url, "joints": joints}

    def read(self) -> dict[str, float]:
        values = self.values
        ok = True
        for joint in self.present:
            name = joint.name
            try:
                values[name + "/position"] = joint.position()
                values[name + "/velocity"] = joint.velocity()
            except DeltoctlError:
                ok = False
                continue
            values[name + "/home"] = 0.0 if joint.flags & codec.NOTHOMED else 1.0
            values[name + "/flags"] = float(joint.flags)
        self.connected = ok
        return values

    def joint(self, name: str) -> Joint:
        joint = self.joints.get(name)
        if joint is None or joint not in self.present:
            raise NoAnswer(f"joint {name!r} does not answer on {self.url}")
        return joint

    def set_command(self, name: str, value: float) -> None:
        """``jN/position`` or ``jN/velocity``: one command mode per joint, homed first."""
        joint_name, _, interface = name.partition("/")
        joint = self.joint(joint_name)
        self.touched.add(joint_name)
        if joint.mode is None:
            joint.activate()
        if interface == "position":
            joint.set_position(value)
        elif interface == "velocity":
            joint.set_velocity(value)
        else:
            raise InvalidInput(f"{name} is not a position or velocity command interface")

    # -- configuration -----------------------------------------------------------------------------
    def config_read(self) -> dict[str, dict[str, dict[str, Any]]]:
        """Per joint that answers: what it reports (its flags, the home offset it keeps while
        powered) and the parameters the driver sends it from the profile when enabling it
        (the joint has no read for them)."""
        parts = {}
        for joint in self.present:
            comp = next(c for c in self.hw.joints if c.name == joint.name)
            unit = "m" if comp.joint_type == "prismatic" else "rad"
            flags = joint.ping()
            parts[joint.name] = {
                "flags": {"value": flags, "access": "R", "state": True,
                          "meaning": codec.describe_flags(flags)},
                "home offset": {"value": joint.read_home_offset(), "access": "RW",
                                "unit": unit, "opt_in": "home-offset",
                                "note": "the joint's zero, stored by homing"},
                **self._profile_entries(joint, unit),
            }
        return parts

    @staticmethod
    def _profile_entries(joint: Joint, unit: str) -> dict[str, dict[str, Any]]:
        def entry(value: Any, unit: str | None = None) -> dict[str, Any]:
            return {"value": value, "access": "profile", **({"unit": unit} if unit else {})}

        homing_units = {"speed": f"{unit}/s", "acceleration": f"{unit}/s²",
                        "current": "% of 2.5 A"}
        return {
            "i2c address": entry(f"{joint.address:#04x}"),
            "reduction": entry(joint.reduction),
            "min": entry(joint.low, unit), "max": entry(joint.high, unit),
            "drive current": entry(joint.drive, "% of 2.5 A"),
            "hold current": entry(joint.hold, "% of 2.5 A"),
            "stall threshold": entry(joint.stall_threshold),
            "max acceleration": entry(joint.max_acceleration, f"{unit}/s²"),
            "max velocity": entry(joint.max_velocity, f"{unit}/s"),
            **{f"homing {k}": entry(v, homing_units.get(k)) for k, v in joint.homing.items()},
        }

    def config_write(self, changes: dict[str, dict[str, Any]],
                     allow: frozenset[str] = frozenset()) -> dict[str, dict[str, Any]]:
        """The home offset is the one value a joint keeps: written only with ``allow``
        "home-offset" (it moves where the joint believes it is), then read back."""
        import math

        for part, items in changes.items():
            joint = self.joint(part)
            for name, value in items.items():
                if name != "home offset":
                    raise InvalidInput(f"{part}: {name!r} is not written to the joint (the "
                                       "driver sends its parameters from the profile)")
                if (not isinstance(value, (int, float)) or isinstance(value, bool)
                        or not math.isfinite(value)):
                    raise InvalidInput(f"{part}: the home offset must be a number, not "
                                       f"{value!r}")
            if joint.busy:
                raise Refused(f"{part} is busy with a blocking command (homing?)")
        if changes and "home-offset" not in allow:
            raise Refused(f"{', '.join(changes)}: a home offset is written only when asked",
                          hint="pass --allow home-offset")
        read_back = {}
        for part, items in changes.items():
            joint = self.joint(part)
            joint.command(codec.float_command(codec.HOMEOFFSET, float(items["home offset"])))
            value = joint.read_home_offset()
            if joint.homed:  # positions read from now on count from it
                joint.offset = value
            read_back[part] = {"home offset": value}
        return read_back

    # -- detect ------------------------------------------------------------------------------------
    def detect(self) -> dict:
        assert self.bus is not None
        found = [a for a in SCAN if self.bus.probe(a)]
        expected = {j.address: j.name for j in self.joints.values()}
        missing = [expected[a] for a in sorted(set(expected) - set(found))]
        unexpected = [f"{a:#04x}" for a in found if a not in expected]
        checks = [{"what": f"{name} at {addr:#04x}", "profile": "joint",
                   "device": "answers" if addr in found else "no answer", "part": name,
                   "match": addr in found, "missing": addr not in found}
                  for addr, name in sorted(expected.items())]
        checks += [{"what": f"device at {a}", "profile": "—", "device": "answers",
                    "match": False} for a in unexpected]
        return {"bus": self.url, "found": [f"{a:#04x}" for a in found], "missing": missing,
                "unexpected": unexpected, "grid": i2cdetect_grid(found), "checks": checks,
                "summary": f"{self.hw.name}: {len(expected) - len(missing)} of {len(expected)} "
                           f"joints answer on "
                           f"{self.url}" + (f" (missing: {', '.join(missing)})" if missing
                                            else "")}

    # -- motion ------------------------------------------------------------------------------------
    def check_motion(self, names: list[str]) -> None:
        for name in names:
            joint = self.joint(name)
            if not joint.homed:
                raise NotHomed(f"{name} is not homed: it may not move",
                              hint="run `deltoctl home` first")

    def move(self, targets: dict[str, float], velocity: float | None = None,
             progress: Progress | None = None) -> MoveResult:
        """Position moves (the joints run their own profiles); settled once every joint is
        within tolerance, not BUSY and still for SETTLE_READS reads, no sooner than its
        profile could end; unsettled when the timeout passes. Fails naming a stalled joint,
        which is left disabled."""
        profile = self.profile
        self.check_motion(list(targets))
        tolerance = profile.safety.home_tolerance or TOLERANCE
        start = self.read()
        first = max((abs(t - start[f"{j}/position"]) for j, t in targets.items()),
                    default=0.0) or 1.0
        speeds = {j: min(velocity or math.inf, self.joint(j).max_velocity) for j in targets}
        for name, target in targets.items():
            self._goal(name, target, speeds[name] if velocity else None)
        # no profile ends sooner than its distance at full speed
        soonest = {j: abs(t - start[f"{j}/position"]) / speeds[j] for j, t in targets.items()}
        hook = self.on_cycle
        # the setpoint each cycle: the goal, and the speed limit of its profile
        setpoints = {j: (t, speeds[j], NAN) for j, t in targets.items()} if hook is not None else {}
        if hook is not None:  # the state the goals were sent from
            hook(time.time_ns(), start, setpoints)
        began = time.monotonic()
        # the move's own time and home_timeout more (else 5 s), as every family's
        timeout = max(soonest.values(), default=0.0) + (profile.safety.home_timeout or 5.0)
        errors: dict[str, float] = {}
        still = dict.fromkeys(targets, 0)  # reads in a row each joint has been still
        while True:
            values = self.read()
            if hook is not None:
                hook(time.time_ns(), values, setpoints)
            for name in targets:
                if self.joints[name].stalled:
                    self._stalled(name)
            errors = {j: abs(t - values[f"{j}/position"]) for j, t in targets.items()}
            worst = max(errors.values(), default=0.0)
            if progress:
                progress(max(0.0, 1.0 - worst / first))
            elapsed = time.monotonic() - began
            for j in targets:
                here = (errors[j] <= tolerance and not self.joints[j].busy
                        and abs(values.get(f"{j}/velocity", math.inf)) <= STILL * speeds[j])
                still[j] = still[j] + 1 if here else 0
            unsettled = [j for j in targets if still[j] < SETTLE_READS or elapsed < soonest[j]]
            if not unsettled or elapsed > timeout or self.halted.is_set():
                break
            time.sleep(POLL_MOVE)
        return MoveResult(not unsettled, elapsed, errors, unsettled)

    def _goal(self, name: str, target: float, speed: float | None) -> None:
        """Enable the joint, its speed limit (None: the profile's), then the position goal."""
        joint = self.joint(name)
        self.touched.add(name)
        joint.activate()
        if speed is not None:
            joint.set_limits(joint.max_acceleration, speed)
        joint.set_position(target)

    def follow(self, setpoints: dict[str, tuple[float, float, float]]) -> None:
        """A recorded position goal and speed limit each, sent when they differ from the ones
        sent before (the joints run their own profiles, as in the move that was recorded);
        refused for a joint that is not homed, as a move is."""
        sent = self._followed
        goals = {j: sp for j, sp in setpoints.items()
                 if sp[0] == sp[0] and sent.get(j) != sp[:2]}
        self.check_motion(list(goals))
        for name, (target, speed, _) in goals.items():
            joint = self.joint(name)
            ok = speed == speed and speed > 0
            self._goal(name, target, min(speed, joint.max_velocity) if ok else None)
            sent[name] = (target, speed)

    def _stalled(self, name: str) -> None:
        joint = self.joints[name]
        position = self.values.get(f"{name}/position", float("nan"))
        joint.disable()
        raise DeviceFault(f"{name} stalled at {position:.4f} and was stopped; it is disabled",
                          codec.STALLED,
                          hint="clear the obstruction, then jog again (enabling clears STALL)")

    def home(self, names: list[str], force: bool = False,
             progress: HomeProgress | None = None) -> dict[str, str]:
        """Home each joint in turn (start, poll BUSY every 100 ms, store the offset);
        Ctrl-C or a timeout aborts the running one with STOP. Returns joint → outcome."""
        timeout = self.profile.safety.home_timeout or 120.0
        outcome: dict[str, str] = {}
        for name in names:
            joint = self.joint(name)
            if joint.homed and not force:
                outcome[name] = "already homed"
                if progress:
                    progress(name, outcome[name], 1.0)
                continue
            self.touched.add(name)
            try:
                joint.start_homing()
                began = time.monotonic()
                if progress:
                    progress(name, "homing", 0.0)
                while joint.ping() & codec.BUSY:
                    if self.halted.is_set():
                        raise KeyboardInterrupt
                    if time.monotonic() - began > timeout:
                        raise DeviceError(f"{name} did not find its hard stop within "
                                          f"{timeout:g} s; homing aborted")
                    time.sleep(POLL_HOMING)
            except BaseException:
                joint.stop()  # STOP clears BUSY: the firmware aborts the HOME
                joint.disable()
                raise
            joint.finish_homing()
            if not joint.homed:
                raise DeviceError(f"{name}: homing ended but the joint is not homed "
                                  "(aborted, or it stalled)")
            outcome[name] = "homed"
            if progress:
                progress(name, "homed", 1.0)
        return outcome

    def stop(self) -> None:
        """Stop and disable the joints this session commanded (the deadman's safe state)."""
        for name in sorted(self.touched):
            joint = self.joints[name]
            try:
                joint.disable()
            except DeltoctlError:
                self.warnings.append(f"{name} did not answer the stop; its deadman stops it")
        self.touched.clear()

    def make_safe(self) -> None:
        """STOP to every joint, whatever this session commanded: a move or homing a killed
        process started ends."""
        for name, joint in self.joints.items():
            try:
                joint.stop()
            except DeltoctlError:
                self.warnings.append(f"{name} did not answer the stop; its deadman stops it")

    def cleanup(self) -> None:
        self.bus = None  # the System closes the shared bus
        self.connected = False


def i2cdetect_grid(found: list[int]) -> str:
    """The bus as ``i2cdetect`` prints it: addresses that answered, ``--`` for silence."""
    lines = ["     " + "  ".join(f"{c:x}" for c in range(16))]
    for row in range(0, 0x80, 0x10):
        cells = []
        for a in range(row, row + 0x10):
            cells.append(f"{a:02x}" if a in found else "--" if a in SCAN else "  ")
        lines.append(f"{row:02x}: " + " ".join(cells))
    return "\n".join(lines)
