"""Calibrating a servo arm's joints, LeRobot's procedure with the robot's profile: the arm put in
the middle of its range gives each joint's homing offset (that pose reads the middle of the turn,
the profile's zero); the torque off, each joint moved by hand through its range while its
present, lowest and highest positions are sampled; the range checked against the profile's
joint limits; then the homing offsets and position limits written into the servos (only with
the permissions ``config restore --allow`` asks for the same registers) and saved: deltoctl's
file, one per profile in the user's data directory, and LeRobot's on request.

On every later open of a profile that has a file, each servo's registers are compared with it:
a difference is a warning naming the joint and the register, as LeRobot's check at connect."""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any

from deltoctl.errors import DeltoctlError, DeviceError, InvalidInput, Refused

if TYPE_CHECKING:
    from deltoctl.core.system import Member, System

CAPABILITY = "calibrate_joints"
# the permissions that write what calibrate joints writes (the registers' own, as config
# restore names them)
PERMISSIONS = ("homing-offset", "min-position-limit", "max-position-limit")
FORMAT = "deltoctl joint calibration"
MAX_BYTES = 1 << 20
PERIOD = 0.05  # s between samples of the range
Rows = list[dict[str, Any]]


def calibration_file(profile_name: str, simulated: bool = False) -> Path:
    """deltoctl's calibration of a profile: $XDG_DATA_HOME/deltoctl/calibration/NAME.json; one
    made on simulators goes under sim/, never compared with a robot's servos (nor with a
    simulator's: it starts afresh)."""
    from deltoctl.data_paths import user_data_dir

    folder = user_data_dir("calibration", *(("sim",) if simulated else ()))
    return folder / f"{profile_name}.json"


def _simulated(system: System) -> bool:
    return any(m.simulated is not None for m in system.able(CAPABILITY))


def able(system: System) -> list[Member]:
    found = system.able(CAPABILITY)
    if not found:
        raise InvalidInput(f"{system.profile.name} has no servo joints deltoctl calibrates "
                           "(Dynamixel Protocol 2.0 and Feetech buses)")
    return found


def check_allow(allow: Sequence[str]) -> bool:
    """Whether ``allow`` (``--allow`` values) permits the writes: all of PERMISSIONS, or none
    (the file only); some of them is Refused naming the others, an unknown name an
    InvalidInput."""
    from deltoctl.app import config

    given = {config.permission(a) for a in allow}
    unknown = sorted(given - set(config.permission_names()))
    if unknown:
        raise InvalidInput(f"--allow {unknown[0]}: not a permission (these write the "
                           f"calibration: {', '.join(PERMISSIONS)})")
    missing = [p for p in PERMISSIONS if p not in given]
    if given & set(PERMISSIONS) and missing:
        raise Refused(f"nothing done: the calibration is written whole, also needs "
                      f"{' '.join('--allow ' + p for p in missing)}",
                      hint="name all three, or none to save the file only")
    return not missing


def description(system: System, write: bool) -> str:
    names = ", ".join(m.name for m in able(system))
    where = ("written into the servos (Homing Offset, position limits) and saved" if write
             else "saved to the calibration file only (no --allow: the servos are not written)")
    return (f"switch the torque off on {names}: the arm goes limp, support it; then each "
            f"joint's middle and range, {where}")


# -- the procedure -------------------------------------------------------------------------------

@dataclass(frozen=True)
class Steps:
    """How the operator's steps end: ``middle`` returns once the arm is in its middle pose
    (None: it is already); the range ends when ``done(rows)`` says so or ``seconds`` pass;
    ``hand``: control lines for the robot's simulators, one after each sample from the first
    on (each sees the pose the one before left)."""

    middle: Callable[[], None] | None = None
    done: Callable[[Rows], bool] | None = None
    seconds: float | None = None
    hand: Sequence[str] = ()

    def check(self) -> None:
        seconds = self.seconds
        if seconds is not None and not (math.isfinite(seconds) and 0 < seconds <= 3600):
            raise InvalidInput(f"--range-seconds must be above 0 and at most 3600, got "
                               f"{seconds:g}")
        if self.done is None and seconds is None:
            raise InvalidInput("the range needs an end: done, or seconds")


def calibrate(system: System, control: Callable[[str], str], steps: Steps,
              allow: Sequence[str] = (), lerobot: str | None = None,
              full_turn: Sequence[str] = (),
              confirm: Callable[[str], None] | None = None) -> dict[str, Any]:
    """The whole procedure (``Robot.calibrate_joints``); ``control`` runs a hand's line."""
    steps.check()
    system.check_allowed("calibrating joints")
    members = able(system)
    joints = [j.name for m in members for j in m.hw.joints]
    unknown = sorted(set(full_turn) - set(joints))
    if unknown:
        raise InvalidInput(f"--full-turn {unknown[0]}: not a calibrated joint (joints: "
                           f"{', '.join(joints)})")
    write = check_allow(allow)
    if confirm is not None:
        confirm(description(system, write))
    for m in members:
        m.driver.set_torque([j.name for j in m.hw.joints], False)
    if steps.middle is not None:
        steps.middle()
    held, offsets = start(system)
    pending = list(steps.hand)

    def sampled(rows: Rows) -> bool:
        if pending:  # one a sample, as a hand does one thing at a time
            control(pending.pop(0))
        return steps.done(rows) if steps.done is not None else False

    rows = calibration(system, held, offsets,
                       record_range(system, held, offsets, sampled, steps.seconds), full_turn)
    system.notes.extend(r["note"] for r in rows if r["note"])
    if write:
        _write_servos(system, rows)
    else:
        for r in rows:
            r["written"] = "not written"
        system.notes.append(
            f"not written to the servos: the homing offset and position limits of "
            f"{len(rows)} joint(s) (pass {' '.join('--allow ' + p for p in PERMISSIONS)}); "
            "saved in the file only")
    return {"profile": system.profile.name, **save(system, rows, lerobot), "written": write,
            "torque": "off", "joints": rows}


def start(system: System) -> tuple[dict[str, dict[str, Any]], dict[str, int]]:
    """After the arm is in its middle pose (torque off): what each servo holds and the homing
    offset that makes the pose read the middle of the turn, per joint."""
    held: dict[str, dict[str, Any]] = {}
    offsets: dict[str, int] = {}
    for m in able(system):
        for joint, entry in m.driver.joint_calibration().items():
            held[joint] = {**entry, "block": m.name}
        offsets.update(m.driver.middle_offsets())
    return held, offsets


def record_range(system: System, held: dict[str, dict[str, Any]], offsets: dict[str, int],
                 done: Callable[[Rows], bool], seconds: float | None = None) -> Rows:
    """Sample each joint's position under its new offset until ``done(rows)`` says so (it is
    shown each sample) or ``seconds`` pass: per joint ``present``, ``min``, ``max``."""
    olds = {j: e["homing_offset"] for j, e in held.items()}
    rows: dict[str, dict[str, Any]] = {}
    end = None if seconds is None else time.monotonic() + seconds
    while True:
        for m in able(system):
            for joint, here in m.driver.positions_under(offsets, olds).items():
                row = rows.setdefault(joint, {"joint": joint, "min": here, "max": here})
                row.update(present=here, min=min(row["min"], here), max=max(row["max"], here))
        table = [rows[j] for j in held if j in rows]
        if done(table) or (end is not None and time.monotonic() >= end):
            return table
        time.sleep(PERIOD)


def _component(system: System, joint: str) -> Any:
    return next(j for j in system.member(joint).hw.joints if j.name == joint)


def _radians(system: System, joint: str, raw: int, resolution: int) -> float:
    """A step under the new offset as the joint's position: the middle of the turn is zero."""
    comp = _component(system, joint)
    value = (raw - (resolution - 1) // 2) * 2 * math.pi / resolution
    return (-value if comp.inverse else value) + comp.offset


def _limits(system: System, joint: str) -> tuple[float, float] | None:
    limits = _component(system, joint).limits
    if limits is None or limits.lower is None or limits.upper is None:
        return None
    return limits.lower, limits.upper


def check_range(system: System, joint: str, low: float, high: float) -> tuple[str, str]:
    """The recorded range (rad) against the profile's limits: ``covers``, ``short`` (a
    limit not reached), ``beyond`` (a limit passed), or ``short, beyond``; and what to say."""
    from deltoctl.core.envelope import DEFAULT_TOLERANCE

    limits = _limits(system, joint)
    if limits is None:
        return "no limits", ""
    lower, upper = limits
    tolerance = system.profile.safety.home_tolerance or DEFAULT_TOLERANCE
    short = low > lower + tolerance or high < upper - tolerance
    beyond = low < lower - tolerance or high > upper + tolerance
    verdict = ", ".join(w for w, b in (("short", short), ("beyond", beyond)) if b) or "covers"
    span = (f"{joint}: the range moved, {math.degrees(low):.1f}°..{math.degrees(high):.1f}°, "
            f"{'does not cover' if short else 'goes beyond'} the profile's limits "
            f"{math.degrees(lower):.1f}°..{math.degrees(upper):.1f}°")
    if short and beyond:
        span = span.replace("does not cover", "does not match")
    return verdict, "" if verdict == "covers" else span


def calibration(system: System, held: dict[str, dict[str, Any]], offsets: dict[str, int],
                rows: Rows, full_turn: Sequence[str] = ()) -> Rows:
    """Each joint's new calibration (LeRobot's keys) and its check against the profile; a
    joint that did not move (its lowest = its highest) is a DeviceError naming it."""
    moved = {r["joint"]: r for r in rows}
    still = [j for j in held if j not in full_turn and (j not in moved
                                                        or moved[j]["min"] == moved[j]["max"])]
    if still:
        raise DeviceError(f"not moved through a range: {', '.join(still)}; nothing written",
                          hint="move each joint by hand from one end of its range to the "
                               "other before Enter (or give more --range-seconds)")
    out = []
    for joint, entry in held.items():
        top = entry["resolution"] - 1
        if joint in full_turn:
            low, high = 0, top
        else:
            low, high = (max(0, min(top, moved[joint][k])) for k in ("min", "max"))
        row = {"joint": joint, "block": entry["block"], "id": entry["id"],
               "drive_mode": entry.get("drive_mode", 0), "homing_offset": offsets[joint],
               "range_min": low, "range_max": high, "full_turn": joint in full_turn}
        if joint in full_turn:
            row["check"], row["note"] = "full turn", ""
        else:
            row["lower"] = _radians(system, joint, moved[joint]["min"], entry["resolution"])
            row["upper"] = _radians(system, joint, moved[joint]["max"], entry["resolution"])
            row["check"], row["note"] = check_range(system, joint, row["lower"], row["upper"])
        out.append(row)
    return out


def _write_servos(system: System, rows: Rows) -> None:
    """Each block's rows into its servos, then each joint verified by reading it back."""
    for m in able(system):
        mine = {r["joint"]: r for r in rows if r["block"] == m.name}
        if not mine:
            continue
        m.driver.write_joint_calibration(mine)
        after = m.driver.joint_calibration()
        for joint, row in mine.items():
            wrong = [k for k in ("homing_offset", "range_min", "range_max")
                     if after.get(joint, {}).get(k) != row[k]]
            row["written"] = "failed" if wrong else "verified"
            if wrong:
                system.notes.append(f"{joint}: {', '.join(wrong)} reads back differently "
                                    "after the write")


def save(system: System, rows: Rows, lerobot: str | None) -> dict[str, str | None]:
    """deltoctl's file of the profile, and with ``lerobot`` (a device id) LeRobot's of each
    block where its tools look for it."""
    from deltoctl.servo import lerobot as lerobot_file

    path = calibration_file(system.profile.name, _simulated(system))
    blocks: dict[str, dict[str, Any]] = {}
    for r in rows:
        blocks.setdefault(r["block"], {})[r["joint"]] = {
            k: r[k] for k in ("id", "drive_mode", "homing_offset", "range_min", "range_max")}
    document = {"format": FORMAT, "profile": system.profile.name,
                "time": datetime.now(timezone.utc).isoformat(timespec="seconds"),
                "blocks": blocks}
    files: dict[str, str | None] = {"file": str(_write(path, json.dumps(document, indent=2))),
                                    "lerobot_file": None}
    if lerobot is not None:
        from deltoctl.app.calibrate import check_device_name

        check_device_name(lerobot)
        for m in able(system):
            types = m.driver.lerobot_types
            if types is None or m.name not in blocks:
                continue
            leader = not any(j.command_interfaces for j in m.hw.joints)
            name = lerobot if len(blocks) == 1 else f"{lerobot}-{m.name}"
            there = lerobot_file.path(types[leader], name, leader)
            files["lerobot_file"] = str(_write(there, lerobot_file.dump(blocks[m.name])))
    return files


def _write(path: Path, text: str) -> Path:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text + "\n")
    except OSError as exc:
        raise InvalidInput(f"cannot write {path}: {exc.strerror}") from None
    return path


# -- the check on open ---------------------------------------------------------------------------

def load(path: Path) -> dict[str, dict[str, dict[str, int]]]:
    """A calibration file's blocks → joints → entries; anything else is an InvalidInput."""
    import stat

    try:
        if not stat.S_ISREG(path.stat().st_mode):
            raise InvalidInput(f"{path}: a calibration file must be a regular file")
        with path.open("rb") as file:
            data = json.loads(file.read(MAX_BYTES + 1).decode())
    except OSError as exc:
        raise InvalidInput(f"{path}: cannot read the calibration ({exc.strerror})") from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise InvalidInput(f"{path}: not a calibration file ({exc})") from None
    if not _shaped(data):
        raise InvalidInput(f"{path}: not a {FORMAT} file (blocks → joints → integers)")
    return dict(data["blocks"])


def _integers(entry: Any) -> bool:
    return isinstance(entry, dict) and all(
        isinstance(v, int) and not isinstance(v, bool) for v in entry.values())


def _shaped(data: Any) -> bool:
    """A document of deltoctl's calibration: its format, and blocks → joints → integers."""
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        return False
    blocks = data.get("blocks")
    return isinstance(blocks, dict) and all(
        isinstance(joints, dict) and all(_integers(e) for e in joints.values())
        for joints in blocks.values())


def compare_on_open(system: System) -> list[str]:
    """The differences between the servos and the profile's calibration file, one warning
    each naming the joint and the register (none without a file, or on simulators started
    for the command); they go to the System's notes too."""
    members = [m for m in system.able(CAPABILITY) if m.simulated is None]
    path = calibration_file(system.profile.name)
    if not members or not path.is_file():
        return []
    try:
        saved = load(path)
    except InvalidInput as exc:
        system.notes.append(f"calibration not checked: {exc.message}")
        return [system.notes[-1]]
    found = []
    for m in members:
        if saved.get(m.name):
            found += _differences(m, saved[m.name], path)
    system.notes.extend(found)
    return found


def _differences(m: Member, wanted: dict[str, dict[str, int]], path: Path) -> list[str]:
    """Where a block's servos differ from its joints' entries in the file, by register."""
    try:
        live = m.driver.joint_calibration()
    except DeltoctlError as exc:
        return [f"{m.name}: calibration not checked ({exc.message})"]
    return [f"{joint}: {register} is {live[joint].get(key)}, its calibration ({path}) says "
            f"{entry[key]}; calibrate again (deltoctl calibrate joints)"
            for joint, entry in wanted.items() if joint in live
            for key, register in m.driver.calibration_registers.items()
            if key in entry and live[joint].get(key) != entry[key]]
