"""Recorded commands, and playing them back.

Recording (``jog --record``): every driver's move loop calls its ``on_cycle`` hook once a cycle
with the state it read and the setpoints it sent; ``CommandLog`` turns each call into one row
of the recording: every state of the System, and each joint's setpoint as
``<joint>/position_command``, ``<joint>/velocity_command``, ``<joint>/effort_command`` (NaN
where not commanded, and for the joints of the other blocks), on the /joint_commands topic.

Replaying (``replay``): ``read_recording_commands`` reads the rows back; ``check_commands``
refuses, before anything moves, a command outside the profile's limits or a setpoint held
longer than ``MAX_HOLD_S``; ``Replay`` sends each row at its recorded time to the blocks it
commands, reading them first, and compares what they report with what was recorded (RMS and
max per joint): a joint outside its limits or further than ``max_deviation`` from the
recording stops the replay. A recording is untrusted: on a device (``plan_replay``), the limits
are those of the named profile or of the catalog's, never the recording's, and its bus URLs
never choose a device.
"""

from __future__ import annotations

import bisect
import math
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from deltoctl.core.driver import SETPOINT_FIELDS, Setpoint
from deltoctl.errors import DeviceError, InvalidInput, OutsideEnvelope, Refused
from deltoctl.record.command_topics import (
    COMMANDS_TOPIC,
    STATES_TOPIC,
    command_key,
    commanded_joints,
)

MAX_DEVIATION = 0.2  # rad or m: a replayed joint further than this from its recording stops

if TYPE_CHECKING:
    from deltoctl.core.driver import Driver
    from deltoctl.core.system import System
    from deltoctl.profile.model import Component, Profile

NAN = float("nan")
# a replay is of a fault, minutes at most, and is read whole before anything moves: 200,000
# rows (16 minutes at the 200 Hz a jog records) of 500,000 joint setpoints in all (2 minutes
# of a 20-joint hand), about 120 MB held
MAX_COMMAND_ROWS = 200_000
MAX_COMMAND_SETPOINTS = 500_000
MAX_HOLD_S = 0.5  # s: the longest a recording may leave one setpoint to stand


# -- recording -----------------------------------------------------------------------------------

class CommandLog:
    """Sets the ``on_cycle`` hook of every block's driver; each call is one row for
    ``recorder`` (a RecorderProcess made with ``commands=True``). Blocks on several links move
    in threads of their own: rows are written one at a time, in time order."""

    def __init__(self, system: System, recorder: Any) -> None:
        self.system, self.recorder = system, recorder
        joints = [j.name for j in commanded_joints(system.profile)]
        self.keys = {j: tuple(command_key(j, f) for f in SETPOINT_FIELDS) for j in joints}
        self.blank = dict.fromkeys([k for keys in self.keys.values() for k in keys], NAN)
        self.lock = threading.Lock()
        self.rows = 0
        self.last_ns = 0

    def __enter__(self) -> CommandLog:
        for m in self.system:
            m.driver.on_cycle = self.cycle
        return self

    def __exit__(self, *exc: object) -> None:
        for m in self.system:
            m.driver.on_cycle = None

    def cycle(self, t_ns: int, values: dict[str, float], setpoints: dict[str, Setpoint]) -> None:
        row = {**values, **self.blank}
        for joint, fields in setpoints.items():
            keys = self.keys.get(joint)
            if keys is not None:
                row.update(zip(keys, fields))
        with self.lock:
            self.last_ns = max(t_ns, self.last_ns + 1)
            self.recorder.write(row, self.last_ns)
            self.rows += 1


# -- reading -------------------------------------------------------------------------------------

@dataclass
class Recorded:
    """The commands of a recording: per row its time and each commanded joint's setpoint,
    and the positions recorded with it."""

    path: Path
    profile_yaml: str | None
    times: list[int] = field(default_factory=list)
    setpoints: list[dict[str, Setpoint]] = field(default_factory=list)
    positions: list[dict[str, float]] = field(default_factory=list)

    @property
    def joints(self) -> list[str]:
        """The joints commanded at least once, in order of first command."""
        seen: dict[str, None] = {}
        for row in self.setpoints:
            seen.update(dict.fromkeys(row))
        return list(seen)

    @property
    def seconds(self) -> float:
        return (self.times[-1] - self.times[0]) / 1e9 if self.times else 0.0

    def start_pose(self) -> dict[str, float]:
        """Each commanded joint's first recorded position."""
        pose: dict[str, float] = {}
        for row in self.positions:
            for joint, value in row.items():
                if joint not in pose and value == value:
                    pose[joint] = value
        return {j: pose[j] for j in self.joints if j in pose}


def _rows(rec: Any, topic: str) -> Iterator[tuple[int, dict[str, float]]]:
    """(time, interface → value) for each JointState message of ``topic``, one at a time;
    more than MAX_COMMAND_ROWS messages are refused as they are read (a summary may lie
    about its count, and a file without one gives none)."""
    import struct

    from deltoctl.record.reader import Cdr, damaged, joint_state

    channel = rec.channel(topic)
    if channel is None:
        return
    names: dict[str, str] = {}  # one copy of each interface name for every row
    for count, (t, data) in enumerate(rec.read(channel.id), 1):
        if count > MAX_COMMAND_ROWS:
            raise _too_many(rec.path, f"more than {MAX_COMMAND_ROWS} {topic} messages")
        try:
            layout = joint_state(Cdr(data), topic)
            row = {names.setdefault(name, name): struct.unpack_from("<d", data, at)[0]
                   for name, at in layout}
        except (struct.error, IndexError, ValueError):
            raise damaged(rec.path, f"a {topic} message at {t} ns is not a "
                                     "sensor_msgs/JointState") from None
        yield t, row


def _too_many(path: Path, what: str) -> InvalidInput:
    return InvalidInput(f"{path}: {what}, more than a replay takes ({MAX_COMMAND_ROWS} "
                        f"command rows, {MAX_COMMAND_SETPOINTS} joint setpoints)",
                        "replay a shorter recording of the fault (`deltoctl jog --record`)")


def _setpoints(values: dict[str, float]) -> dict[str, Setpoint]:
    """Each joint's (position, velocity, effort) setpoint in a row, if any is commanded."""
    row: dict[str, Setpoint] = {}
    for joint in dict.fromkeys(k.rpartition("/")[0] for k in values):
        sp = [values.get(command_key(joint, f), NAN) for f in SETPOINT_FIELDS]
        if any(v == v for v in sp):
            p, v, e = (x if x == x else NAN for x in sp)  # one NaN object for every row
            row[joint] = (p, v, e)
    return row


def read_recording_commands(path: Path) -> Recorded:
    """The commands, positions and profile (YAML text) of a recording made with commands.
    The rows are read one at a time and only the commanded joints of each kept: the commands
    first, bounded as they are read, then each commanded joint's recorded position."""
    from deltoctl.record.reader import read_recording

    rec = read_recording(path, keep=(COMMANDS_TOPIC, STATES_TOPIC))
    channel = rec.channel(COMMANDS_TOPIC)
    if channel is None or channel.type != "sensor_msgs/msg/JointState":
        raise InvalidInput(f"{path} holds no recorded commands (no {COMMANDS_TOPIC} topic): it "
                           "was recorded without them",
                           "record a motion with its commands: deltoctl jog JOINT DELTA "
                           "--record FILE.mcap")
    if channel.count > MAX_COMMAND_ROWS:  # the summary's count: known before reading any
        raise InvalidInput(f"{path}: {channel.count} recorded commands, more than the "
                           f"{MAX_COMMAND_ROWS} a replay takes",
                           "replay a shorter recording of the fault (`deltoctl jog --record`)")
    recorded = Recorded(rec.path, rec.metadata.get("profile", {}).get("yaml"))
    rows: list[tuple[int, dict[str, Setpoint]]] = []
    setpoints = 0
    for t, values in _rows(rec, COMMANDS_TOPIC):
        row = _setpoints(values)
        setpoints += len(row)
        if setpoints > MAX_COMMAND_SETPOINTS:
            raise _too_many(path, f"more than {MAX_COMMAND_SETPOINTS} joint setpoints")
        if row:
            rows.append((t, row))
    if not rows:
        raise InvalidInput(f"{path}: its {COMMANDS_TOPIC} topic holds no command to replay")
    rows.sort(key=lambda r: r[0])  # in time order already, as the recorder writes them
    times = {t for t, _ in rows}
    joints = {j for _, row in rows for j in row}
    positions: dict[int, dict[str, float]] = {}  # at each commanded time
    for t, state in _rows(rec, STATES_TOPIC):
        if t in times:
            positions[t] = {j: state[f"{j}/position"] for j in joints
                            if f"{j}/position" in state}
    for t, row in rows:
        at = positions.get(t, {})
        recorded.times.append(t)
        recorded.setpoints.append(row)
        recorded.positions.append({j: at.get(j, NAN) for j in row})
    return recorded


def recorded_profile(recorded: Recorded) -> Profile:
    """The profile the recording was made with, from its ``profile`` metadata: untrusted
    text, loaded as a profile file is (size and YAML bounds, validation)."""
    from deltoctl.profile.catalog import profile_from_text

    text = recorded.profile_yaml
    if not text:
        raise InvalidInput(f"{recorded.path} holds no profile (no 'profile' metadata with "
                           "YAML)", "pass the profile it was recorded with: -p PROFILE")
    return profile_from_text(text, f"{recorded.path} (profile metadata)")


def catalog_profile(recorded: Profile) -> Profile | None:
    """The catalog's profile of a recorded one: by its name, else the one catalog profile
    of its model. Only catalog names are looked up: nothing in the file names a path."""
    from deltoctl.profile.catalog import catalog_files, load_profile

    files = catalog_files()
    if recorded.name in files:
        return load_profile(files[recorded.name])
    if not recorded.model:
        return None
    same = [p for p in map(load_profile, files.values()) if p.model == recorded.model]
    return same[0] if len(same) == 1 else None


def device_profile(recorded: Recorded, named: Profile | None) -> tuple[Profile, Profile | None]:
    """The profile whose limits a replay on a device keeps — ``named`` (-p), else the
    catalog's for the recorded profile — never the recording's own; and the recorded
    profile (None when the file has none and ``named`` is given)."""
    if named is not None and not recorded.profile_yaml:
        return named, None
    theirs = recorded_profile(recorded)
    ours = named or catalog_profile(theirs)
    if ours is None:
        raise InvalidInput(f"{recorded.path} was recorded with profile {theirs.name!r} "
                           f"(model {theirs.model or 'not given'}), which is not in the "
                           "catalog: on a device, the limits are those of a profile you name",
                           "pass the robot's profile: -p PROFILE")
    return ours, theirs


def check_recorded_profile(ours: Profile, theirs: Profile | None, path: Path) -> list[str]:
    """Refuse (exit 5) a recorded profile looser than the one in force (wider limits,
    higher caps, a larger jog step); the other differences, as one warning."""
    if theirs is None:
        return []
    looser, other = profile_changes(ours, theirs)
    if looser:
        raise Refused(f"{path}: its profile is looser than {ours.name}, whose limits a replay "
                      f"on a device keeps: {'; '.join(looser)}; nothing moved",
                      "replay it on the simulators (without --device), or record it again "
                      "within the robot's limits")
    return [f"the recording's profile differs from {ours.name}, whose limits apply: "
            f"{'; '.join(other)}"] if other else []


def _looser_bound(what: str, ours: float | None, theirs: float | None, wider: int,
                  looser: list[str], other: list[str]) -> None:
    """One bound compared: ``wider`` is +1 where a larger value is looser (an upper limit,
    a cap), -1 where a smaller one is (a lower limit); none at all is loosest."""
    if ours == theirs or (ours is not None and theirs is not None
                          and math.isclose(ours, theirs, rel_tol=1e-9, abs_tol=1e-9)):
        return
    shown = f"{what} {_show(theirs)} recorded, {_show(ours)} in force"
    if ours is not None and (theirs is None or (theirs - ours) * wider > 0):
        looser.append(shown)
    else:
        other.append(shown)


def _show(value: float | None) -> str:
    return "none" if value is None else f"{value:.4f}".rstrip("0").rstrip(".")


LIMIT_FIELDS = (("lower", -1), ("upper", 1), ("velocity", 1), ("effort", 1),
                ("acceleration", 1), ("deceleration", 1), ("jerk", 1))


def profile_changes(ours: Profile, theirs: Profile) -> tuple[list[str], list[str]]:
    """What a recorded profile changes in the one in force, in words: (looser, other).
    Looser: a joint limit or soft limit wider or gone, limits disabled, a larger
    max_jog_step or current_cap. Joints only one of them has are not compared."""
    from deltoctl.profile.model import Limits

    looser: list[str] = []
    other: list[str] = []
    for key, wider in (("max_jog_step", 1), ("current_cap", 1)):
        _looser_bound(f"safety.{key}", getattr(ours.safety, key),
                      getattr(theirs.safety, key), wider, looser, other)
    for joint in ours.joints():
        rec = theirs.component(joint.name)
        if rec is None or rec.kind != "joint":
            continue
        if joint.enable_limits and not rec.enable_limits:
            looser.append(f"{joint.name}: limits disabled")
        mine, recorded = joint.limits or Limits(), rec.limits or Limits()
        for name, wider in LIMIT_FIELDS:
            _looser_bound(f"{joint.name} {name} limit", getattr(mine, name),
                          getattr(recorded, name), wider, looser, other)
        if joint.soft_limits is not None or rec.soft_limits is not None:
            soft, rsoft = joint.soft_limits, rec.soft_limits
            for name, wider in (("lower", -1), ("upper", 1)):
                _looser_bound(f"{joint.name} soft {name} limit",
                              getattr(soft, name) if soft else None,
                              getattr(rsoft, name) if rsoft else None, wider, looser, other)
    return looser, other


# -- checks --------------------------------------------------------------------------------------

def _bounded(joint: Component, what: str, value: float, bound: float | None, at: str) -> None:
    if not math.isfinite(value) or (bound is not None and abs(value) > bound + 1e-9):
        limit = "" if bound is None else f" (its limit: {bound:.4f})"
        raise OutsideEnvelope(f"{at}: {joint.name} {what} command {value:.4f} is beyond its "
                              f"limits{limit}; nothing moved")


def commanded_components(profile: Profile, recorded: Recorded) -> dict[str, Component]:
    """The profile's joint of each commanded name; a joint it lacks is invalid input."""
    comps: dict[str, Component] = {}
    for name in recorded.joints:
        comp = profile.component(name)
        if comp is None or comp.kind != "joint":
            raise InvalidInput(f"{recorded.path} commands {name!r}, which is no joint of "
                               f"{profile.name}", "replay takes the recording's own profile "
                               "unless -p PROFILE (or DELTOCTL_PROFILE) names another")
        comps[name] = comp
    return comps


def check_commands(profile: Profile, recorded: Recorded) -> None:
    """Refuse (exit 5) before anything moves: a start pose or a position command outside a
    joint's limits or soft limits, a position step larger than max_jog_step (from the one
    before, the first from the start pose), a velocity or effort beyond the joint's limit.
    A gap longer than ``MAX_HOLD_S`` between two rows, or between two commands of one joint,
    is refused too: a replay never holds a setpoint longer than the recording did, plus a
    little. A joint the profile lacks is invalid input (exit 2)."""
    from deltoctl.core.envelope import check_target

    comps = commanded_components(profile, recorded)
    last = recorded.start_pose()
    for joint, position in last.items():
        try:
            check_target(profile, comps[joint], position, None)
        except OutsideEnvelope as exc:
            raise OutsideEnvelope(f"the recorded start pose: {exc.message}; nothing moved") \
                from None
    t0 = recorded.times[0]
    held: dict[str, int] = {"": t0}  # the last row (""), and each joint's last command
    for t, row in zip(recorded.times, recorded.setpoints):
        at = f"at {(t - t0) / 1e9:.3f} s"
        for joint in ("", *row):
            gap = (t - held.get(joint, t)) / 1e9
            if gap > MAX_HOLD_S:
                raise Refused(f"{at}: no command for {joint or 'any joint'} in the {gap:.3f} s "
                              f"before (more "
                              f"than {MAX_HOLD_S} s): a replay would hold its setpoint that "
                              "long; nothing moved")
            held[joint] = t
        for joint, (position, velocity, effort) in row.items():
            comp = comps[joint]
            lim = comp.limits
            if position == position:
                if not math.isfinite(position):
                    _bounded(comp, "position", position, None, at)
                try:
                    check_target(profile, comp, position, last.get(joint))
                except OutsideEnvelope as exc:
                    raise OutsideEnvelope(f"{at}: {exc.message}; nothing moved", exc.hint) \
                        from None
                last[joint] = position
            if velocity == velocity:
                _bounded(comp, "velocity", velocity, lim.velocity if lim else None, at)
            if effort == effort:
                _bounded(comp, "effort", effort, lim.effort if lim else None, at)


# -- playing back --------------------------------------------------------------------------------

@dataclass
class Difference:
    """Recorded against replayed position of one joint."""

    block: str
    samples: int = 0
    squares: float = 0.0
    largest: float = 0.0

    def add(self, recorded: float, replayed: float) -> None:
        if recorded != recorded or replayed != replayed:
            return
        d = abs(replayed - recorded)
        self.samples += 1
        self.squares += d * d
        self.largest = max(self.largest, d)

    @property
    def rms(self) -> float:
        return math.sqrt(self.squares / self.samples) if self.samples else 0.0


@dataclass
class ReplayResult:
    rows: int = 0
    seconds: float = 0.0
    late_max_ms: float = 0.0  # the latest a row went out after its recorded time
    joints: dict[str, Difference] = field(default_factory=dict)


class Deviated(Refused):
    """A replayed joint outside its limits or too far from its recording (exit 5): every
    block was stopped; ``result`` is the replay so far (``report``: its comparison, once
    made)."""

    def __init__(self, message: str, result: ReplayResult) -> None:
        super().__init__(message)
        self.result = result
        self.report: dict[str, Any] | None = None


class Track:
    """One joint's recorded positions over time (the rows that command it: its block's
    cycles), read at any time by linear interpolation."""

    def __init__(self) -> None:
        self.times: list[int] = []
        self.positions: list[float] = []

    def add(self, t_ns: int, position: float) -> None:
        if position == position:
            self.times.append(t_ns)
            self.positions.append(position)

    def at(self, t_ns: int) -> float:
        times, positions = self.times, self.positions
        if not times:
            return NAN
        i = bisect.bisect_right(times, t_ns)
        if i == 0:
            return positions[0]
        if i == len(times):
            return positions[-1]
        t1, t2 = times[i - 1], times[i]
        f = (t_ns - t1) / (t2 - t1)
        return positions[i - 1] + f * (positions[i] - positions[i - 1])


class Replay:
    """The recording's rows on ``system``: each at its recorded time (from the first), to the
    blocks whose joints it commands, each block read first. What a block reads is compared
    with what was recorded at the same time since the start (a row sent late is compared
    with the recording as late); a joint outside its limits or soft limits, or further than
    ``max_deviation`` from the recording, raises ``Deviated`` before the row goes out. A
    block whose rows have ended stops at the next row."""

    def __init__(self, system: System, recorded: Recorded, max_deviation: float) -> None:
        self.system, self.recorded, self.max_deviation = system, recorded, max_deviation
        self.result = ReplayResult(joints={
            j: Difference(system.member(j).name) for j in recorded.joints})
        # per row: (driver, its joints' setpoints) for each block it commands
        self.plan: list[list[tuple[Driver, dict[str, Setpoint]]]] = []
        for row in recorded.setpoints:
            by_driver: dict[int, tuple[Driver, dict[str, Setpoint]]] = {}
            for joint, sp in row.items():
                driver = system.member(joint).driver
                by_driver.setdefault(id(driver), (driver, {}))[1][joint] = sp
            self.plan.append(list(by_driver.values()))
        # per row: the blocks whose last row was the one before (their move had ended: they
        # stop there, as the recorded move loop stopped them, not at the end of the replay)
        last = {id(d): (i, d) for i, blocks in enumerate(self.plan) for d, _ in blocks}
        self.ended: list[list[Driver]] = [[] for _ in self.plan]
        for i, driver in last.values():
            if i + 1 < len(self.plan):
                self.ended[i + 1].append(driver)
        comps = {j: system.profile.component(j) for j in recorded.joints}
        self.bounds = {j: (c.limits, c.soft_limits) if c else (None, None)
                       for j, c in comps.items()}
        self.tracks = {j: Track() for j in recorded.joints}
        for t, row in zip(recorded.times, recorded.positions):
            for joint, position in row.items():
                self.tracks[joint].add(t, position)

    def run(self, progress: Any = None) -> ReplayResult:
        """Play every row (the caller stops the System after, whatever happens)."""
        recorded, result = self.recorded, self.result
        t0 = recorded.times[0]
        started = time.monotonic()
        total = len(recorded.times) or 1
        tracks = self.tracks
        for i, (t, blocks) in enumerate(zip(recorded.times, self.plan)):
            due = started + (t - t0) / 1e9
            wait = due - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            else:
                result.late_max_ms = max(result.late_max_ms, -wait * 1e3)
            elapsed = time.monotonic() - started
            now_ns = t0 + int(elapsed * 1e9)
            for driver in self.ended[i]:
                driver.stop()
            for driver, _ in blocks:
                driver.start_read()
            for driver, setpoints in blocks:
                values = driver.read()
                if not driver.connected:
                    raise DeviceError(f"the link to {driver.hw.name} was lost during the "
                                      "replay; every block was stopped")
                for joint in setpoints:
                    expected = tracks[joint].at(now_ns)
                    position = values.get(f"{joint}/position", NAN)
                    result.joints[joint].add(expected, position)
                    problem = self.problem(joint, position, expected)
                    if problem:
                        result.seconds = elapsed
                        raise Deviated(f"at {elapsed:.3f} s: {joint} at {position:.4f} "
                                       f"{problem}; every block was stopped", result)
            self.system.follow(recorded.setpoints[i])  # checked against the envelope
            result.rows = i + 1
            if progress is not None:
                progress((i + 1) / total)
        result.seconds = time.monotonic() - started
        return result

    def problem(self, joint: str, position: float, expected: float) -> str | None:
        """Why a joint read at ``position`` must not go on (None: it may)."""
        lim, soft = self.bounds[joint]
        if lim is not None and position == position and not lim.contains(position):
            lower = "-inf" if lim.lower is None else f"{lim.lower:.4f}"
            upper = "inf" if lim.upper is None else f"{lim.upper:.4f}"
            return f"is outside its limits [{lower}, {upper}]"
        if soft is not None and position == position and not soft.contains(position):
            return f"is outside its soft limits [{soft.lower:.4f}, {soft.upper:.4f}]"
        if abs(position - expected) > self.max_deviation:  # False where either is NaN
            return (f"is {abs(position - expected):.4f} from its recorded position "
                    f"{expected:.4f}, more than the {self.max_deviation:g} allowed "
                    "(--max-deviation)")
        return None


# -- the procedure -------------------------------------------------------------------------------

@dataclass
class ReplayPlan:
    """A recording checked and ready to replay: its commands, the profile whose limits apply,
    what differs in the recorded profile (warnings), and the blocks it commands."""

    recorded: Recorded
    profile: Profile
    notes: list[str]
    blocks: list[str]

    def describe(self, path: Path, targets: Sequence[str]) -> str:
        """The replay on a device, as its confirmation says it."""
        rec = self.recorded
        return (f"move {', '.join(rec.joints)} to the recorded start pose, then replay "
                f"{len(rec.times)} commands ({rec.seconds:.2f} s) of {path.name} on "
                f"{', '.join(self.blocks)} at {', '.join(targets)}")


def plan_replay(path: Path, named: Profile | None, device: bool,
                hardware: Sequence[str] = ()) -> ReplayPlan:
    """Read and check a recording before anything is opened: on a device the limits are
    ``named``'s or the catalog's (never the file's; a looser recorded profile is refused),
    every command within them (exit 5), every commanded joint in the profile (exit 2)."""
    recorded = read_recording_commands(path)
    if device:
        profile, theirs = device_profile(recorded, named)
    else:
        profile, theirs = named or recorded_profile(recorded), None
    commanded_components(profile, recorded)
    notes = check_recorded_profile(profile, theirs, path)
    check_commands(profile, recorded)
    joints = recorded.joints
    blocks = [hw.name for hw in profile.hardware if any(j.name in joints for j in hw.joints)]
    left_out = [b for b in blocks if hardware and b not in hardware]
    if left_out:
        raise InvalidInput(f"the recording commands block(s) {', '.join(left_out)}, which "
                           "--hardware leaves out")
    return ReplayPlan(recorded, profile, notes, blocks)


def check_device_targets(profile: Profile, blocks: Sequence[str],
                         targets: Sequence[str]) -> None:
    """Every bus a replay on a device drives is named by a target (a simulated block
    aside): neither the recording's bus URLs nor a profile's choose a device."""
    from deltoctl import registry
    from deltoctl.core.system import mock_blocks, parse_targets

    mock = mock_blocks(profile, blocks)
    buses = {hw.bus or hw.name for hw in profile.hardware if hw.name in blocks
             and hw.name not in mock and (f := registry.of_block(profile.family_of(hw),
                                                                 hw.plugin)) and f.schemes}
    named, bare = parse_targets(profile, targets)
    missing = sorted(buses - set(named)) if not bare else []
    if missing:
        raise InvalidInput(f"replay --device: name the device of {', '.join(missing)} with "
                           f"-t {missing[0]}=URL (or rehearse with --sim); a replay never "
                           "takes a device from the recording or from a profile's bus URLs")


def replay_limits(plan: ReplayPlan, tolerance: str | None,
                  max_deviation: str | None) -> tuple[float | None, float]:
    """``--tolerance`` and ``--max-deviation`` (``1deg``, ``2mm``, a bare number in rad or m)
    in SI, each in the unit of every replayed joint (exit 2 otherwise); the deviation
    MAX_DEVIATION unless given."""
    from deltoctl.app.motion import joints_quantity

    joints = plan.recorded.joints
    limit = joints_quantity(plan.profile, joints, tolerance, "--tolerance")
    deviation = joints_quantity(plan.profile, joints, max_deviation, "--max-deviation")
    return limit, MAX_DEVIATION if deviation is None else deviation


def where_to_replay(plan: ReplayPlan, device: bool, hardware: Sequence[str],
                    targets: Sequence[str], sim: bool) -> tuple[list[str], bool]:
    """What the robot of a replay opens with: the blocks (those the recording commands,
    unless ``hardware`` names them) and whether on their simulators (always, unless
    ``device``); on a device, only the one ``targets`` names (or ``sim``'s)."""
    if targets and not device:
        raise InvalidInput("-t/--target names a device: add --device to replay on it "
                           "(replay runs on the simulators unless told otherwise)")
    blocks = list(hardware) or plan.blocks
    if device and not sim:
        check_device_targets(plan.profile, blocks, targets)
    return blocks, sim or not device


def _home_simulated(system: System, joints: list[str],
                    notice: Callable[[str], None] | None) -> None:
    """A simulator starts unhomed: joints with a homing routine run it first, so that
    positions mean what they meant on the robot (a device is refused instead)."""
    for block, names in system.by_block(joints).items():
        m = system.member(names[0])
        routine = [j for j in names if system.component(j).command("home")]
        if not routine or not m.can("home"):
            continue
        try:
            m.driver.check_motion(routine)
        except Refused:
            if notice is not None:
                notice(f"{block}: homing {', '.join(routine)} on the simulator first")
            m.driver.home(routine)


def run_replay(system: System, recorded: Recorded, max_deviation: float,
               on_simulator: bool, progress: Callable[[float], None] | None = None,
               notice: Callable[[str], None] | None = None) -> tuple[ReplayResult,
                                                                      Deviated | None]:
    """Move to the recorded start pose, then play the commands at their recorded timing;
    the blocks it commands are stopped on the way out. Returns the result, and why the
    replay was stopped (a joint outside its limits or too far from its recording) or None.
    A start pose outside the envelope, or a device not ready to move, is refused before
    anything is sent or stopped."""
    from deltoctl.core.runner import interrupted_by_signals

    joints = recorded.joints
    blocks = system.by_block(joints)
    for block, names in blocks.items():
        if not system.member(names[0]).can("jog"):
            raise InvalidInput(f"{block} cannot move its joints")
    player = Replay(system, recorded, max_deviation)
    start = recorded.start_pose()
    if start:
        system.check_move(start, jog=False)  # a known pose, as home's
    if not on_simulator:
        system.check_ready(joints)  # e.g. not homed
    try:
        with interrupted_by_signals():
            if on_simulator:
                _home_simulated(system, joints, notice)
                system.check_ready(joints)
            if start:
                moved = system.move(start, jog=False)  # a known pose, as home's
                if not moved.settled:
                    raise DeviceError("the recorded start pose was not reached: "
                                      f"{', '.join(moved.unsettled)}; nothing replayed")
            try:
                return player.run(progress), None
            except Deviated as exc:  # the finally below stops its blocks first
                return exc.result, exc
    finally:
        system.stop(blocks)


def replay_report(path: Path, system: System, recorded: Recorded, result: ReplayResult,
                  tolerance: float | None, on_device: bool, max_deviation: float,
                  stopped: Deviated | None = None) -> dict[str, Any]:
    """Per joint, RMS and max of replayed against recorded position; ``exceeded``: the
    joints beyond ``tolerance``; ``stopped``: why the replay was stopped, or None."""
    joints = {j: {"block": d.block, "samples": d.samples, "rms": round(d.rms, 6),
                  "max": round(d.largest, 6)} for j, d in result.joints.items()}
    exceeded = [j for j, d in result.joints.items()
                if tolerance is not None and d.largest > tolerance]
    return {
        "file": str(path), "profile": system.profile.name,
        "on": "device" if on_device else "simulator", "target": system.url,
        "commands": result.rows, "recorded_seconds": round(recorded.seconds, 3),
        "seconds": round(result.seconds, 3), "late_max_ms": round(result.late_max_ms, 3),
        "joints": joints, "tolerance": tolerance, "exceeded": exceeded,
        "max_deviation": max_deviation, "stopped": stopped.message if stopped else None,
    }
