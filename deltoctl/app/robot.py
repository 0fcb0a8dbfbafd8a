"""The robot as a library: ``open_robot`` composes the System of a profile's blocks (each
block's simulator first, with ``sim=True`` or a block's ``use_mock_hardware``), and ``Robot``
holds the procedures every front end runs — the CLI's verbs, the fleet agent's, a pytest
suite's, a script's. They return the data a verb's JSON holds and collect warnings in
``robot.warnings()``; they never print, prompt or exit. The safety envelope is the System's:
a refused target raises ``deltoctl.errors.Refused`` before a byte is sent."""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from deltoctl.core.runner import check_loop
from deltoctl.errors import DeviceError, InvalidInput

if TYPE_CHECKING:
    from deltoctl.app.config import Snapshot
    from deltoctl.app.motion import HomePlan
    from deltoctl.app.replay import ReplayPlan
    from deltoctl.app.sinks import LinkWatch
    from deltoctl.cmdline import Options
    from deltoctl.core.system import Member, System
    from deltoctl.profile.model import Profile
    from deltoctl.sim.controls import Controls


@dataclass(frozen=True)
class Frame:
    """One cycle of a stream: when (integer ns since the epoch) and the values by interface."""

    t_ns: int
    values: dict[str, float | None]


def _targets(targets: Mapping[str, str] | Sequence[str] | str | None) -> list[str]:
    """``{"bus": "url"}``, ``["bus=url", …]`` or one URL → the System's ``BUS=URL`` list."""
    if targets is None:
        return []
    if isinstance(targets, str):
        return [targets]
    if isinstance(targets, Mapping):
        return [f"{bus}={url}" for bus, url in targets.items()]
    return list(targets)


def load(profile: str | Path | Profile) -> Profile:
    from deltoctl.profile.model import Profile

    if isinstance(profile, Profile):
        return profile
    from deltoctl.profile.catalog import load_profile

    return load_profile(profile)


@contextlib.contextmanager
def open_robot(profile: str | Path | Profile,
               targets: Mapping[str, str] | Sequence[str] | str | None = None, *,
               sim: bool | Mapping[str, Any] = False, hardware: Sequence[str] = (),
               allow_model_mismatch: bool = False, probe: bool = False,
               notice: Callable[[str], None] | None = None,
               served_by: str | None = None, reuse: bool = False,
               warn: Callable[[str], None] | None = None,
               allow_motion: bool = True) -> Iterator[Robot]:
    """The robot of ``profile`` (a catalog name, a file, or a loaded Profile), configured and
    active, its blocks left safe and released on the way out.

    ``targets``: where the blocks are (``{"bus": "tcp://…"}``, ``["bus=url"]``, or one URL);
    ``sim``: start each block's simulated device first and drive it through its real
    transport (a mapping: with those faults of ``deltoctl sim serve``, e.g.
    ``{"missing": ("head_y",)}``); ``reuse``: with ``sim``, drive the ``deltoctl sim serve``
    of this profile and faults that runs for this user instead, when one serves every block
    (told to ``notice``; ``warn`` hears of a server's file that cannot be trusted);
    ``hardware``: only these blocks; ``probe``: a bus where nothing answers is still opened
    (detect); ``notice``: told first when a block runs on its simulator because its profile
    asks for mock hardware; ``served_by``: the targets are simulators another process serves
    (``deltoctl agent --sim``), said so on every block; without ``allow_motion``, every move,
    command and actuation is refused (``Refused``) before a byte is sent."""
    from deltoctl.errors import NotHomed
    from deltoctl.sim import running

    prof = load(profile)
    found = (running.find(prof, sim if isinstance(sim, Mapping) else {}, hardware,
                          warn or _ignore) if sim and reuse else None)
    if found is not None:
        (notice or _ignore)(f"using {found.name} of {found.profile}; --sim-fresh starts one of "
                            "its own")
        targets, sim, served_by = [*_targets(targets), *found.targets], False, found.name
    try:
        with _opened(prof, _targets(targets), sim, hardware, allow_model_mismatch, probe,
                     notice, served_by, allow_motion) as robot:
            yield robot
    except NotHomed as exc:
        if sim and found is None:
            exc.hint = running.fresh_hint(prof.name)
        raise


def _ignore(message: str) -> None:
    pass


@contextlib.contextmanager
def _opened(prof: Profile, urls: list[str], sim: bool | Mapping[str, Any],
            hardware: Sequence[str], allow_model_mismatch: bool, probe: bool,
            notice: Callable[[str], None] | None, served_by: str | None,
            allow_motion: bool = True) -> Iterator[Robot]:
    from deltoctl.app.joint_calibration import compare_on_open
    from deltoctl.core.system import System, mock_blocks, select_blocks
    from deltoctl.sim.controls import Controls

    with contextlib.ExitStack() as stack:
        simulated = (dict.fromkeys(hardware or [hw.name for hw in prof.hardware], "--sim")
                     if sim else mock_blocks(prof, hardware))
        controls = Controls()
        if simulated:
            served = serve_simulators(stack, prof, list(simulated),
                                      sim if isinstance(sim, Mapping) else None, controls)
            urls += [f"{bus}={url}" for bus, url in served.items()]
            for name, why in simulated.items():
                if why != "--sim" and notice is not None:
                    notice(f"{name}: simulated ({why}): no hardware is driven")
        if served_by:
            simulated = {hw.name: simulated.get(hw.name, served_by)
                         for hw in select_blocks(prof, hardware)}
        with System(prof, urls, hardware, probe=probe, allow_model_mismatch=allow_model_mismatch,
                    simulated=simulated, allow_motion=allow_motion) as system:
            robot = Robot(system, controls if controls.words() else None)
            robot.calibration_warnings = compare_on_open(system)
            yield robot


def serve_simulators(stack: contextlib.ExitStack, profile: Profile, blocks: Sequence[str] = (),
                     faults: Mapping[str, Any] | None = None,
                     controls: Controls | None = None) -> dict[str, str]:
    """Start the simulated devices of ``blocks`` (every block without), with ``faults`` (those
    of ``deltoctl sim serve``), closed with ``stack``, their control lines added to
    ``controls``; returns ``{bus: target URL}``."""
    from deltoctl.sim.serve import ServeOptions, serve_profile

    try:
        options = ServeOptions(**dict(faults or {}))
    except TypeError as exc:
        raise InvalidInput(f"sim: {exc}") from None
    return dict(serve_profile(stack, profile, options, list(blocks), controls)["buses"])


def block_entry(m: Member, **data: Any) -> dict[str, Any]:
    """One block in a result: the same keys first whatever the family."""
    return {"name": m.name, "family": m.family.name, "target": m.url or None,
            "simulated": m.simulated is not None, "state": m.lifecycle.state, **data}


# groups that gather other groups (MH5's torque_control)
NESTED = {"arms": ("left_arm", "right_arm"), "legs": ("left_leg", "right_leg")}


def _groups(joints: Sequence[Any]) -> list[str]:
    """The joints' groups (their ``group`` param), and arms/legs where both halves are."""
    groups = {str(j.params["group"]) for j in joints if j.params.get("group")}
    groups |= {name for name, halves in NESTED.items() if set(halves) <= groups}
    return sorted(groups)


def target_names(profile: Profile) -> list[str]:
    """What may name joints of ``profile`` (``select_joints``): its joint groups, all, and
    each joint."""
    joints = list(profile.joints())
    return [*_groups(joints), "all", *(j.name for j in joints)]


def select_joints(profile: Profile, target: str, capability: str,
                  hardware: Sequence[str] = ()) -> list[str]:
    """The joints of the blocks that offer ``capability`` (of ``hardware`` only, when given)
    named by a joint, a group (the joints' ``group`` param, and arms/legs) or ``all``."""
    from deltoctl import registry

    def offers(hw: Any) -> bool:
        family = registry.of_block(profile.family_of(hw), hw.plugin)
        return family is not None and capability in family.capabilities and (
            not hardware or hw.name in hardware)

    joints = [j for hw in profile.hardware if offers(hw) for j in hw.joints]
    if not joints:
        raise InvalidInput(f"{profile.name} has no joints with {capability}")
    if target == "all":
        return [j.name for j in joints]
    groups = set(NESTED.get(target, (target,)))
    chosen = [j.name for j in joints if j.name == target or j.params.get("group") in groups]
    if not chosen:
        from deltoctl.suggest import did_you_mean

        known = _groups(joints)
        near = did_you_mean(target, [*known, "all", *(j.name for j in joints)])
        listed = f" (groups: {', '.join([*known, 'all'])})"
        raise InvalidInput(f"{target!r} is neither a joint nor a group of {profile.name}"
                           + (near or listed))
    return chosen


def joints_named(target: str, joints: Sequence[str]) -> str:
    """``5 joint(s) of left_arm (l_sho_p, …)``, ``head_y``: what a verb acts on, in words."""
    if [target] == list(joints):
        return target
    shown = ", ".join(joints[:6]) + (f" and {len(joints) - 6} more" if len(joints) > 6 else "")
    which = "" if target == "all" else f" of {target}"
    return f"{len(joints)} joint(s){which} ({shown})"


def servo_named(system: System, joint: str) -> str:
    """``head_y (ID 52)``: a joint and the address of its servo on the bus."""
    hw = system.member(joint).hw
    address = next((j.address for j in hw.joints if j.name == joint), None)
    return joint if address is None else f"{joint} (ID {address})"


def _cannot(system: System, capability: str, what: str) -> None:
    unable = [m.name for m in system if not m.can(capability)]
    if unable:
        system.notes.append(f"{', '.join(unable)}: {what}")


class Robot:
    """An open robot: one System of blocks, and the procedures run on it."""

    def __init__(self, system: System, controls: Controls | None = None) -> None:
        self.system = system
        self.controls = controls  # the control lines of the simulators it started
        self.calibration_warnings: list[str] = []  # the servos against their calibration file

    def control(self, line: str) -> str:
        """Run a control line (``hand elbow_flex 30``) on the simulators this robot started;
        its reply, or an InvalidInput naming what is wrong."""
        if self.controls is None or not self.controls.words():
            raise InvalidInput(f"{line!r}: no simulator of this robot answers control lines "
                               "(--sim starts them; a `deltoctl sim serve` reads them on its "
                               "input)")
        return self.controls.run(line)

    @property
    def profile(self) -> Profile:
        return self.system.profile

    @property
    def blocks(self) -> list[Member]:
        return list(self.system)

    def warnings(self) -> list[str]:
        """What went wrong without failing (a block left out, a model mismatch allowed, a
        link re-established): a verb that ends with some exits 3."""
        return self.system.warnings()

    def read(self) -> dict[str, float]:
        """One cycle's state of every block (a copy)."""
        return dict(self.system.read())

    def block_of(self, name: str) -> str:
        """The block a joint, sensor, GPIO or interface (``gpio/output_1``) belongs to."""
        return self.system.member(name).name

    def make_safe(self) -> None:
        """Every block in its safe state (duty 0, torque off, stop), whatever was sent."""
        self.system.make_safe()

    def link_stats(self) -> dict[str, dict[str, int]]:
        """Each block's communication statistics so far: packets, errors, reconnects."""
        return {m.name: dict(m.driver.stats) for m in self.system}

    # -- the lifecycle verbs -------------------------------------------------------------------

    def connect(self, count: int = 20) -> dict[str, Any]:
        """Time ``count`` round trips to every block."""
        import statistics

        blocks = []
        for m in self.system:
            rtts = []
            for _ in range(count):
                start = time.perf_counter()
                m.driver.round_trip()
                rtts.append((time.perf_counter() - start) * 1e3)
            if not m.driver.connected:
                raise DeviceError(f"{m.name} ({m.url}) stopped answering during the round "
                                  "trips")
            blocks.append(block_entry(m, reachable=True, round_trips=len(rtts), rtt_ms={
                "median": round(statistics.median(rtts), 3), "min": round(min(rtts), 3),
                "max": round(max(rtts), 3)}, lifecycle=m.lifecycle.history))
        return {"profile": self.profile.name, "blocks": blocks}

    def identify(self) -> dict[str, Any]:
        """What each block's device says it is, against the profile."""
        blocks = [block_entry(m, identity=m.driver.identify())
                  for m in self.system.able("identify")]
        _cannot(self.system, "identify", "cannot identify")
        return {"profile": self.profile.name, "blocks": blocks}

    def detect(self) -> dict[str, Any]:
        """What is on each block's device or bus, against the profile, judged
        (deltoctl.app.checks.detect_checks): ``checks`` and ``failed``; a part that does not
        answer fails, another difference is a warning."""
        from deltoctl.app.checks import WARN, detect_checks, failed

        blocks = []
        for m in self.system.able("detect"):
            found = m.driver.detect()
            blocks.append(block_entry(m, summary=found.pop("summary"),
                                      checks=found.pop("checks"), details=found))
        checks = detect_checks(blocks)
        differ = [f"{c['id']}: {c['what']}" for c in checks if c["verdict"] == WARN]
        if differ:
            self.system.notes.append("the device differs from the profile: "
                                     + "; ".join(differ))
        return {"profile": self.profile.name, "blocks": blocks, "checks": checks,
                "failed": failed(checks)}

    # -- GPIO ----------------------------------------------------------------------------------

    def gpio_names(self, kind: str = "state") -> list[str]:
        return [n for m in self.system for c in m.hw.gpios for n in c.interface_names(kind)]

    def gpio(self) -> dict[str, float]:
        """Every GPIO state interface's value."""
        if not any(hw.gpios for hw in self.profile.hardware):
            raise InvalidInput(f"{self.profile.name} has no GPIO")
        values = self.system.read()
        gpio = {n: values[n] for n in self.gpio_names() if n in values}
        if not gpio:
            raise DeviceError("the devices send no GPIO values (no GPIO on this model, or IO "
                              "is false in the profile)")
        return gpio

    def gpio_output(self, name: str) -> str:
        """The GPIO command interface ``name`` means (``output_2`` alone: the one of that
        name)."""
        commands = self.gpio_names("command")
        if "/" in name:
            return name
        found = [n for n in commands if n.endswith("/" + name)]
        if len(found) == 1:
            return found[0]
        if found:
            raise InvalidInput(f"{name} is ambiguous: name one of {', '.join(found)}")
        from deltoctl.suggest import did_you_mean

        raise InvalidInput(f"{self.profile.name} has no GPIO output {name!r}"
                           + (did_you_mean(name, commands) or
                              f" (its outputs: {', '.join(commands) or 'none'})"))

    def set_gpio(self, name: str, value: float) -> dict[str, float]:
        """Set one GPIO output and read it back; returns every GPIO state after."""
        if not math.isfinite(value):
            raise InvalidInput(f"a GPIO value must be finite, got {value!r}")
        full = self.gpio_output(name)
        m = self.system.member(full)
        if not m.can("gpio"):
            raise InvalidInput(f"{m.name} has no GPIO outputs to set")
        self.system.set_command(full, value)
        after = dict(self.system.read())
        if full in after and after[full] != value:
            raise DeviceError(f"{full} reads back {after[full]:g} after setting it to "
                              f"{value:g}")
        return {n: after[n] for n in self.gpio_names() if n in after}

    # -- motion --------------------------------------------------------------------------------

    def move(self, targets: Mapping[str, float | str], velocity: float | str | None = None,
             progress: Callable[[float], None] | None = None) -> dict[str, Any]:
        """Move joints to absolute targets (``30deg``, ``12mm``, or a bare number in radians
        or metres), the blocks on several links at once; the blocks that moved are stopped on
        the way out. A unit that is not the joint's is ``InvalidInput``; a target outside the
        envelope is refused (``Refused``) before anything is sent, with no effect at all (no
        stop either). Returns the report a ``jog --json`` prints (its data, the blocks and
        ``settled``, ``seconds``, ``unsettled``, in one dict)."""
        from deltoctl.app.motion import joint_positions, joint_speed, move

        self.system.check_allowed(f"moving {', '.join(targets)}")
        positions = joint_positions(self.profile, targets)
        speed = joint_speed(self.profile, list(positions), velocity, "velocity")
        return move(self.system, positions, speed, progress)

    def home(self, joints: Sequence[str] = (), force: bool = False,
             velocity: float | str | None = None, plan: HomePlan | None = None,
             progress: Callable[[float], None] | None = None,
             show: Callable[[str, str, float], None] | None = None) -> dict[str, Any]:
        """Home the robot's joints (or ``joints``): homing routines into their hard stops
        (``show`` follows each joint), the others to the profile's home pose (``progress``)
        at ``velocity`` (``20deg/s``, a bare number in rad/s or m/s). ``plan``: the homing
        planned already (``motion.plan_home``), e.g. to confirm it first."""
        from deltoctl.app.motion import home, joint_speed, plan_home

        self.system.check_allowed("homing")
        if plan is None:
            plan = plan_home(self.profile, [m.name for m in self.system], joints)
        speed = joint_speed(self.profile, list(plan.targets), velocity, "velocity")
        return home(self.system, plan, force, speed, progress, show)

    def plan_jog(self, steps: Sequence[tuple[str, float | str | None]],
                 to: float | str | None = None,
                 velocity: float | str | None = None) -> tuple[dict[str, float], list[str]]:
        """Each joint's target — its step (a number in rad or m, or ``5deg``, in the joint's
        unit) from where it is now, or ``to`` — checked against the envelope at
        ``velocity``, and each move in words (for a confirmation); nothing moves. The joints
        are those of ``motion.jog_pairs``."""
        from deltoctl.app.motion import jog_targets, joint_speed

        targets, moves = jog_targets(self.system, steps, to)
        self.system.check_move(targets, joint_speed(self.profile, list(targets), velocity,
                                                    "velocity"))
        return targets, moves

    def jog_targets(self, deltas: Mapping[str, float | str]) -> dict[str, float]:
        """Each joint's target ``delta`` (a number in rad or m, or a quantity such as
        ``5deg``, in the joint's unit) from where it is now (not checked yet)."""
        from deltoctl.app.motion import jog_targets, moving_joints

        moving_joints(self.profile, list(deltas))
        return jog_targets(self.system, list(deltas.items()))[0]

    def jog(self, deltas: Mapping[str, float | str], velocity: float | str | None = None,
            progress: Callable[[float], None] | None = None) -> dict[str, Any]:
        """Move joints by ``deltas`` from where they are (``max_jog_step`` bounds each)."""
        return self.move(self.jog_targets(deltas), velocity, progress)

    def new_recording(self, output: Path,
                      force: bool = False) -> contextlib.AbstractContextManager[Path]:
        """The file a recording of moves goes to (``{serial}`` filled), created now and
        removed again when what follows fails before writing to it."""
        from deltoctl.app.recording import new_output

        return new_output(output, self.system, force)

    def recorded(self, output: Path, moves: Callable[[], dict[str, Any]]) -> dict[str, Any]:
        """Run ``moves`` (moves of this robot, returning their report) while their cycles'
        states and commands go to ``output`` (for ``replay``); the report gains
        ``recording``."""
        from deltoctl.app.recording import recorded_moves

        return recorded_moves(self.system, output, moves)

    # -- calibration and servos ----------------------------------------------------------------

    def calibrate_ft(self, samples: int = 50, force_tolerance: float = 0.3,
                     torque_tolerance: float = 0.03, output_dir: Path | None = None,
                     confirm: Callable[[str], None] | None = None,
                     verify: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """Tare every F/T sensor and judge the residual (see ``deltoctl.app.calibrate``);
        ``confirm`` is told what the tare will do first (it raises to stop); ``verify``: the
        checks after it, in ``checks`` (the options of ``calibrate.verify_ft``: mass, sensor,
        watch, ask, timeout, drift_limit)."""
        from deltoctl.app.calibrate import tare_description, tare_ft, verify_ft

        if confirm is not None:
            confirm(tare_description(self.system))
        result = tare_ft(self.system, samples, force_tolerance, torque_tolerance, output_dir)
        if verify is not None:
            result["checks"] = verify_ft(self.system, result, samples=samples, **verify)
        return result

    def calibrate_imu(self, samples: int = 100, ask: Callable[[str], None] | None = None,
                      timeout: float = 120.0, output_dir: Path | None = None,
                      confirm: Callable[[str], None] | None = None) -> dict[str, Any]:
        """Self-test and gravity check of every IMU; with ``ask`` (told which face to put
        down), the six-position tumble too, saved in ``output_dir``. ``confirm`` is told
        what will happen first (it raises to stop)."""
        from deltoctl.app.imu_calibration import calibrate_imu, self_test_description

        if confirm is not None:
            confirm(self_test_description(self.system, ask is not None))
        return calibrate_imu(self.system, samples, ask, timeout, output_dir)

    def calibrate_servos(self, half_turn: bool = False, name: str = "my_arm",
                         output: Path | None = None,
                         confirm: Callable[[str], None] | None = None,
                         force: bool = False) -> dict[str, Any]:
        """Each servo block's calibration saved in its family's file format (a Feetech SO
        arm's as LeRobot's calibration JSON) at ``output`` or where the format's tools look
        for it under the device name ``name``; with ``half_turn``, each servo's present pose
        made the middle of its turn first. ``confirm`` is told what will happen first (it
        raises to stop)."""
        from deltoctl.app.calibrate import (
            calibrate_servos,
            check_device_name,
            servo_calibration_description,
        )

        check_device_name(name)
        if half_turn:
            self.system.check_allowed("half-turn homing")
        description = servo_calibration_description(self.system, half_turn)
        if confirm is not None:
            confirm(description)
        return calibrate_servos(self.system, half_turn, name, output, force)

    def calibrate_joints(self, middle: Callable[[], None] | None = None,
                         done: Callable[[list[dict[str, Any]]], bool] | None = None,
                         seconds: float | None = None, allow: Sequence[str] = (),
                         lerobot: str | None = None, full_turn: Sequence[str] = (),
                         confirm: Callable[[str], None] | None = None,
                         hand: Sequence[str] = (), name: str | None = None) -> dict[str, Any]:
        """LeRobot's joint calibration with this robot's profile (deltoctl.app.joint_calibration):
        each joint's homing offset from the arm's middle pose (``middle``, when given, returns
        once the limp arm is put there; without it the pose is read as the arm stands, before
        the torque goes off); then, torque off, the range moved by hand is sampled until
        ``done(rows)`` (told each sample's per-joint present/min/max) says so or ``seconds``
        pass (``hand``: control lines run on this robot's simulators, one after each sample),
        checked against the profile's limits (a joint short of or beyond them is a warning),
        written into the servos when ``allow`` holds every one of ``PERMISSIONS`` (else the
        file only, a warning saying so), saved in deltoctl's file (the arm ``name``'s, when
        given) and, with ``lerobot`` (a device id), in LeRobot's. ``full_turn`` joints take
        the whole turn, unrecorded. ``confirm`` is told what will happen first (it raises to
        stop)."""
        from deltoctl.app import joint_calibration as jc

        if hand:
            self.control("help")  # no simulator to turn by hand: said before anything
        for w in self.calibration_warnings:  # the file's: stale once calibrated again
            if w in self.system.notes:
                self.system.notes.remove(w)
        return jc.calibrate(self.system, self.control, jc.Steps(middle, done, seconds, hand),
                            allow, lerobot, full_turn, confirm, name)

    def _registers(self, joint: str) -> Any:
        m = self.system.member(joint)
        if not m.can("registers"):
            raise InvalidInput(f"{joint} is in {m.name}, which has no registers")
        return m.driver

    def servo_named(self, joint: str) -> str:
        """``head_y (ID 52)``: a joint and the address of its servo on the bus."""
        return servo_named(self.system, joint)

    def registers(self, joint: str, items: Sequence[str] = ()) -> dict[str, Any]:
        """A servo's control table items (every one without ``items``)."""
        return self._registers(joint).read_registers(joint, list(items))

    def write_register(self, joint: str, item: str, value: int) -> int:
        """Write one item and read it back; a different read-back is a DeviceError."""
        self.system.check_allowed(f"writing {item} of {joint}")
        after = self._registers(joint).write_register(joint, item, value)
        if after != value:
            raise DeviceError(f"{item} reads back {after} after writing {value}")
        return after

    def _per_block(self, joints: Sequence[str] | str,
                   capability: str) -> dict[Any, list[str]]:
        if isinstance(joints, str):
            joints = select_joints(self.profile, joints, capability)
        groups = {m.driver: [j.name for j in m.hw.joints if j.name in joints]
                  for m in self.system.able(capability)}
        return {driver: js for driver, js in groups.items() if js}

    def torque(self, joints: Sequence[str] | str, on: bool) -> list[str]:
        """Switch the joints' torque (``joints``: their names, or a joint, a group such as
        ``left_arm`` or ``all``); returns those done."""
        self.system.check_allowed("switching torque")
        return [j for driver, js in self._per_block(joints, "torque").items()
                for j in driver.set_torque(js, on)]

    def reboot(self, joints: Sequence[str] | str) -> list[str]:
        """Reboot the joints' servos (their names, or a joint, a group or ``all``); returns
        those that acknowledged."""
        self.system.check_allowed("rebooting servos")
        return [j for driver, js in self._per_block(joints, "reboot").items()
                for j in driver.reboot(js)]

    # -- configuration -------------------------------------------------------------------------

    def config_snapshot(self) -> dict[str, Any]:
        """Every block's configuration, as a snapshot document (``config.dump_yaml`` writes
        it)."""
        return self.config_read()[0]

    def config_read(self) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
        """The snapshot document, and each block's live configuration it was made of (what
        ``config.write_snapshot`` names the file by)."""
        from deltoctl.app import config

        return config.snapshot(self.system)

    def config_diff(self, snapshot: str | Path | Snapshot) -> list[dict[str, Any]]:
        """The items where the devices differ from a snapshot (or its file); notes are
        warnings."""
        from deltoctl.app import config

        rows, notes = config.compare_live(self.system, _snapshot(snapshot))
        self.system.notes.extend(notes)
        return rows

    def config_restore(self, snapshot: str | Path | Snapshot, allow: Sequence[str] = (),
                       confirm: Callable[[str], None] | None = None) -> list[dict[str, Any]]:
        """Write back what differs from a snapshot (or its file) — safety settings only when
        ``allow`` names them —, each item verified by reading it back; returns each item's
        fate. Refused (its ``rows`` and ``notes``: the plan) before anything is written or
        ``confirm`` is told what will be written (it raises to stop)."""
        from deltoctl.app import config

        self.system.check_allowed("restoring a configuration")
        permitted = frozenset(config.permission(a) for a in allow)
        rows, notes = config.plan_restore(self.system, _snapshot(snapshot), permitted)
        refused = [r for r in rows if r["status"] == "refused"]
        if refused:
            exc = config.refusal(refused, permitted)
            exc.rows, exc.notes = rows, notes
            raise exc
        self.system.notes.extend(notes)
        writes = [r for r in rows if r["status"] == "write"]
        if writes and confirm is not None:
            confirm(config.description(writes))
        if writes:
            config.write_changes(self.system, rows, permitted)
        return rows

    # -- data ----------------------------------------------------------------------------------

    def joint_types(self) -> dict[str, str]:
        """Each joint's ros2_control type (revolute, continuous, prismatic …): what its
        position is, an angle or a length."""
        return {j.name: j.joint_type for j in self.profile.joints()}

    def interfaces(self, patterns: Sequence[str] = ()) -> list[str]:
        """The state interfaces whose names match the globs (every one without globs)."""
        import fnmatch

        names = self.system.state_interfaces()
        globs = [p for item in patterns for p in item.split(",") if p]
        if not globs:
            return names
        chosen = [n for n in names if any(fnmatch.fnmatchcase(n, g) for g in globs)]
        if not chosen:
            from deltoctl.suggest import did_you_mean

            typed = globs[0].translate(str.maketrans("", "", "*?[]"))
            raise InvalidInput(f"--interfaces {','.join(globs)} matches no interface"
                               + did_you_mean(typed, names))
        return chosen

    def stream(self, rate: float = 50.0, duration: float | None = None,
               interfaces: Sequence[str] = ()) -> Iterator[Frame]:
        """Frames at ``rate`` Hz until ``duration`` passes (or the caller stops iterating)."""
        from deltoctl.core.loop import CycleLoop

        check_loop(rate, duration)
        names = self.interfaces(interfaces)
        for _ in CycleLoop(rate, duration):
            values = self.system.read()
            yield Frame(time.time_ns(), {n: values.get(n) for n in names})


    def cycles(self, rate: float, duration: float | None,
               sinks: Sequence[Any]) -> tuple[dict[str, Any], LinkWatch]:
        """Run the cycle loop at ``rate`` Hz until ``duration`` passes (or Ctrl-C), each
        cycle's values to ``sinks``; returns the loop's statistics and the lost-link watch,
        whose ``finish()`` says how the links ended (``Unreachable`` when one is still down,
        a warning when one came back)."""
        from deltoctl.app.sinks import LinkWatch
        from deltoctl.core.runner import run_cycles

        check_loop(rate, duration)
        links = LinkWatch(self.system)
        stats = run_cycles(self.system, rate, duration, [*sinks[:1], links, *sinks[1:]])
        return stats.summary(), links

    def loop_warnings(self, rate: float, loop: Mapping[str, Any]) -> list[str]:
        """Why a loop ran below ``rate`` when a serial adapter's latency timer explains it."""
        from deltoctl.app.latency import loop_warnings

        return loop_warnings([m.url for m in self.system.members], rate, loop["real_rate"])

    def record(self, output: str | Path, rate: float = 100.0, duration: float | None = None,
               gpio_type: str = "group-values") -> dict[str, Any]:
        """Record every block's state interfaces to MCAP until ``duration`` passes (or
        Ctrl-C); the file is valid either way. A link still down at the end is
        ``Unreachable``; one that came back is a warning."""
        result, links = self.record_to(Path(output), rate, duration, gpio_type)
        links.finish()
        return result

    def record_to(self, output: Path, rate: float = 100.0, duration: float | None = None,
                  gpio_type: str = "group-values", sinks: Sequence[Any] = (),
                  show: Callable[[float, int, float | None], None] | None = None,
                  force: bool = False) -> tuple[dict[str, Any], LinkWatch]:
        """``record``, with more ``sinks`` and a ``show`` of its progress, an existing file
        overwritten with ``force``; the lost-link watch's ``finish()`` is the caller's."""
        from deltoctl.app.recording import record

        return record(self.system, output, rate, duration, gpio_type, sinks, show, force)

    def replay(self, recording: str | Path, max_deviation: float = 0.2,  # MAX_DEVIATION
               tolerance: float | None = None, plan: ReplayPlan | None = None,
               on_simulator: bool | None = None, on_device: bool | None = None,
               progress: Callable[[float], None] | None = None,
               notice: Callable[[str], None] | None = None) -> dict[str, Any]:
        """Play a recording's commands (``jog --record``) back on this robot under its own
        profile's limits (a looser recorded profile is refused; differences are warnings):
        first to the recorded start pose, then at the recorded timing. A joint outside its
        limits or further than ``max_deviation`` from the recording stops every block it
        commands (``Deviated``, exit 5; its ``report`` is the replay until then). Returns the
        per-joint comparison. ``plan``: the recording planned already (its notes are the
        caller's); ``on_simulator``, ``on_device``: where it runs (by default, simulated when
        every block is)."""
        from deltoctl.app.replay import plan_replay, replay_report, run_replay

        path = Path(recording)
        if plan is None:
            plan = plan_replay(path, self.profile, True, [m.name for m in self.system])
            self.system.notes.extend(plan.notes)
        simulated = all(m.simulated for m in self.system.members)
        on_simulator = simulated if on_simulator is None else on_simulator
        result, stopped = run_replay(self.system, plan.recorded, max_deviation, on_simulator,
                                     progress, notice)
        report = replay_report(path, self.system, plan.recorded, result, tolerance,
                               not simulated if on_device is None else on_device,
                               max_deviation, stopped)
        if stopped is not None:
            stopped.report = report
            raise stopped
        return report


def _snapshot(snapshot: str | Path | Snapshot) -> Snapshot:
    from deltoctl.app.config import load_snapshot

    return load_snapshot(Path(snapshot)) if isinstance(snapshot, (str, Path)) else snapshot


SWITCH = {"on": 1.0, "true": 1.0, "off": 0.0, "false": 0.0}


def gpio_value(text: str) -> float:
    """A GPIO value as typed: on, off (true, false) or a finite number."""
    try:
        number = SWITCH[text.lower()] if text.lower() in SWITCH else float(text)
    except ValueError:
        raise InvalidInput(f"value must be on, off or a number, got {text!r}") from None
    if not math.isfinite(number):
        raise InvalidInput(f"value must be finite, got {text!r}")
    return number


@contextlib.contextmanager
def open_selected(opts: Options, allow_model_mismatch: bool = False,
                  profile: Profile | None = None, probe: bool = False, *,
                  notice: Callable[[str], None] | None = None,
                  warn: Callable[[str], None] | None = None, served_by: str | None = None,
                  make_safe: bool = False) -> Iterator[Robot]:
    """The robot the global options ``opts`` select (see open_robot): ``profile`` when loaded
    already, else --profile's; --target's links, or with --sim simulators with --sim-option's
    faults (the ``sim serve`` of the profile running for the user unless --sim-fresh); only
    --hardware's blocks. ``make_safe``: every block set safe on the way out, whatever was
    sent."""
    prof = profile or opts.load_profile()
    with open_robot(prof, opts.target, sim=opts.sim_of(prof), hardware=opts.hardware,
                    allow_model_mismatch=allow_model_mismatch, probe=probe, notice=notice,
                    served_by=served_by, reuse=not opts.sim_fresh, warn=warn) as robot:
        try:
            yield robot
        finally:
            if make_safe:
                robot.make_safe()
