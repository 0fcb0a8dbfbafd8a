"""Calibrating a servo arm's joints, LeRobot's procedure with the robot's profile: the arm put in
the middle of its range gives each joint's homing offset (that pose reads the middle of the turn,
the profile's zero); the torque off, each joint moved by hand through its range while its
present, lowest and highest positions are sampled; the range checked against the profile's
joint limits; then the homing offsets and position limits written into the servos (only with
the permissions ``config restore --allow`` asks for the same registers) and saved: deltoctl's
file, one per profile (and per arm's ``--id``) in the user's data directory, and LeRobot's on
request. A file saved without the writes says so (``"written": false``): a record, and the
source of LeRobot's file, never compared.

On every later open of a profile that has a file the servos were given, each servo's registers
are compared with it (with several arms' files, with the one they match or else the closest):
a difference is a warning naming the joint and the register, as LeRobot's check at connect."""

from __future__ import annotations

import json
import math
import re
import string
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
PERIOD = 0.05  # s between samples of the range
Rows = list[dict[str, Any]]


PLAIN = re.compile(r"[A-Za-z0-9_-][A-Za-z0-9_.-]*")
_KEPT = frozenset(string.ascii_letters + string.digits + "-_")


def file_name(name: str) -> str:
    """A profile's or block's name as one file name: a plain name (letters, digits, ``-_.``,
    not starting with a dot) as it is; else each byte but a letter, digit, ``-`` or ``_`` as
    ``%XX`` (a dot too: no ``..``)."""
    if PLAIN.fullmatch(name):
        return name
    return "".join(chr(b) if chr(b) in _KEPT else f"%{b:02X}" for b in name.encode()) or "%"


def check_id(name: str | None) -> None:
    """An arm's ``--id`` names files: a plain name only."""
    if name is not None and not PLAIN.fullmatch(name):
        raise InvalidInput(f"--id {name!r} must be a plain name: letters, digits, '-', '_' "
                           "and '.', not starting with a dot")


def calibration_file(profile_name: str, simulated: bool = False,
                     name: str | None = None) -> Path:
    """deltoctl's calibration of a profile: $XDG_DATA_HOME/deltoctl/calibration/PROFILE.json,
    or PROFILE/ID.json for the arm ``name`` (``--id``); one made on simulators goes under sim/,
    never compared with a robot's servos (nor with a simulator's: it starts afresh)."""
    from deltoctl.data_paths import user_data_dir

    folder = user_data_dir("calibration", *(("sim",) if simulated else ()))
    profile = file_name(profile_name)
    return folder / (f"{profile}.json" if name is None else f"{profile}/{file_name(name)}.json")


def _simulated(system: System) -> bool:
    return any(m.simulated is not None for m in system.able(CAPABILITY))


def _unable(m: Member) -> str:
    """Why a block cannot be calibrated ("" when it can): a driver without a calibration,
    or a servo without a homing offset register."""
    if not m.driver.calibration_registers:
        return f"{m.name}: its servos have no homing offset register"
    joints = m.driver.uncalibrated_joints()
    if joints:
        return f"{m.name}: {', '.join(joints)} has no homing offset register (its servo's model)"
    return ""


def able(system: System) -> list[Member]:
    """The blocks calibrated: an InvalidInput naming each block or joint that cannot be, when
    one cannot (before anything is written)."""
    found = system.able(CAPABILITY)
    if not found:
        raise InvalidInput(f"{system.profile.name} has no servo joints deltoctl calibrates "
                           "(Dynamixel Protocol 2.0 and Feetech buses)")
    cannot = [why for why in map(_unable, found) if why]
    if cannot:
        raise InvalidInput(f"nothing done: cannot calibrate {'; '.join(cannot)}",
                           hint="calibrate the other blocks alone (--hardware)"
                           if len(cannot) < len(found) else None)
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


def description(system: System, write: bool, posed: bool = False) -> str:
    """What calibrating does, in order; ``posed``: the limp arm is put in its middle pose
    first (else the pose it stands in is read as its middle, before the torque goes off)."""
    names = ", ".join(m.name for m in able(system))
    where = ("written into the servos (Homing Offset, position limits) and saved" if write
             else "saved to the calibration file only (no --allow: the servos are not written)")
    limp = f"switch the torque off on {names}: the arm goes limp, support it"
    if posed:
        return f"{limp}; then each joint's middle and range, {where}"
    return (f"read the arm's pose as the middle of each joint's range, then {limp}; then each "
            f"joint's range, {where}")


def check_seconds(seconds: float | None) -> None:
    if seconds is not None and not (math.isfinite(seconds) and 0 < seconds <= 3600):
        raise InvalidInput(f"--range-seconds must be above 0 and at most 3600, got {seconds:g}")


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
        check_seconds(self.seconds)
        if self.done is None and self.seconds is None:
            raise InvalidInput("the range needs an end: done, or seconds")


def calibrate(system: System, control: Callable[[str], str], steps: Steps,
              allow: Sequence[str] = (), lerobot: str | None = None,
              full_turn: Sequence[str] = (),
              confirm: Callable[[str], None] | None = None,
              name: str | None = None) -> dict[str, Any]:
    """The whole procedure (``Robot.calibrate_joints``); ``control`` runs a hand's line."""
    steps.check()
    check_id(name)
    check_id(lerobot)
    write = check_allow(allow)
    system.check_allowed("calibrating joints")
    members = able(system)
    joints = [j.name for m in members for j in m.hw.joints]
    unknown = sorted(set(full_turn) - set(joints))
    if unknown:
        raise InvalidInput(f"--full-turn {unknown[0]}: not a calibrated joint (joints: "
                           f"{', '.join(joints)})")
    if confirm is not None:
        confirm(description(system, write, steps.middle is not None))
    if steps.middle is not None:  # limp, the arm is put in its middle pose and held there
        _torque_off(members)
        steps.middle()
    held, offsets = start(system)  # the middle pose read before the arm goes limp
    if steps.middle is None:
        _torque_off(members)
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
    return {"profile": system.profile.name, **save(system, rows, lerobot, name, write),
            "written": write, "torque": "off", "joints": rows}


def _torque_off(members: Sequence[Member]) -> None:
    for m in members:
        m.driver.set_torque([j.name for j in m.hw.joints], False)


def start(system: System) -> tuple[dict[str, dict[str, Any]], dict[str, int]]:
    """With the arm in its middle pose: what each servo holds and the homing offset that makes
    the pose read the middle of the turn, per joint."""
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
    """Each block's rows into its servos, then each joint verified by reading it back: a
    register that reads back otherwise is a DeviceError naming joint and register (the file
    is not saved)."""
    wrong = []
    for m in able(system):
        mine = {r["joint"]: r for r in rows if r["block"] == m.name}
        if not mine:
            continue
        m.driver.write_joint_calibration(mine)
        after = m.driver.joint_calibration()
        for joint, row in mine.items():
            back = after.get(joint, {})
            wrong += [f"{joint}: {m.driver.calibration_registers[k]} reads {back.get(k)} after "
                      f"{row[k]} was written" for k in ("homing_offset", "range_min",
                                                        "range_max") if back.get(k) != row[k]]
            row["written"] = "verified"
    if wrong:
        raise DeviceError(f"the calibration did not hold: {'; '.join(wrong)}; not saved",
                          hint="check the servos' power and wiring (deltoctl identify), then "
                               "calibrate again")


def save(system: System, rows: Rows, lerobot: str | None, name: str | None = None,
         written: bool = True) -> dict[str, str | None]:
    """deltoctl's file of the profile (of the arm ``name`` when given; ``written``: whether
    the servos hold it), and with ``lerobot`` (a device id) LeRobot's of each block where its
    tools look for it."""
    from deltoctl.servo import lerobot as lerobot_file

    path = calibration_file(system.profile.name, _simulated(system), name)
    blocks: dict[str, dict[str, Any]] = {}
    for r in rows:
        blocks.setdefault(r["block"], {})[r["joint"]] = {
            k: r[k] for k in ("id", "drive_mode", "homing_offset", "range_min", "range_max")}
    document = {"format": FORMAT, "profile": system.profile.name, "id": name,
                "time": datetime.now(timezone.utc).isoformat(timespec="seconds"),
                "written": written, "blocks": blocks}
    files: dict[str, str | None] = {"file": str(_write(path, json.dumps(document, indent=2))),
                                    "lerobot_file": None}
    if lerobot is not None:
        for m in able(system):
            types = m.driver.lerobot_types
            if types is None or m.name not in blocks:
                continue
            leader = not any(j.command_interfaces for j in m.hw.joints)
            device = lerobot if len(blocks) == 1 else f"{lerobot}-{file_name(m.name)}"
            there = lerobot_file.path(types[leader], device, leader)
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

def load(path: Path) -> dict[str, Any]:
    """A calibration file's document (its blocks → joints → entries, whether the servos were
    written); anything else is an InvalidInput."""
    from deltoctl.servo.lerobot import read_json

    data = read_json(path)
    if not _shaped(data):
        raise InvalidInput(f"{path}: not a {FORMAT} file (blocks → joints → integers)")
    return data


def _integers(entry: Any) -> bool:
    return isinstance(entry, dict) and all(
        isinstance(v, int) and not isinstance(v, bool) for v in entry.values())


def _shaped(data: Any) -> bool:
    """A document of deltoctl's calibration: its format, whether written (a bool, true when
    left out), and blocks → joints → integers."""
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        return False
    blocks = data.get("blocks")
    return isinstance(data.get("written", True), bool) and isinstance(blocks, dict) and all(
        isinstance(joints, dict) and all(_integers(e) for e in joints.values())
        for joints in blocks.values())


def _files(profile_name: str) -> list[Path]:
    """The profile's calibration files: its own, then each arm's (``--id``)."""
    path = calibration_file(profile_name)
    arms = path.with_suffix("")
    return [p for p in (path, *(sorted(arms.glob("*.json")) if arms.is_dir() else ()))
            if p.is_file()]


def compare_on_open(system: System) -> list[str]:
    """The differences between the servos and the profile's calibration files the servos were
    given (none without one, or on simulators started for the command): with several arms'
    files, none when the servos match one, else those of the closest, one warning each naming
    the joint and the register. They go to the System's notes too."""
    members = [m for m in system.able(CAPABILITY) if m.simulated is None]
    paths = _files(system.profile.name) if members else []
    found: list[str] = []
    best: list[str] | None = None
    live: dict[str, dict[str, dict[str, int]] | str] = {}
    for path in paths:
        try:
            document = load(path)
        except InvalidInput as exc:
            found.append(f"calibration not checked: {exc.message}")
            continue
        saved = document["blocks"]
        ours = [m for m in members if saved.get(m.name)]
        if not document.get("written", True) or not ours:
            continue  # a record the servos were not given, or another arm's blocks
        differences = [d for m in ours for d in _differences(m, saved[m.name], path, live)]
        if best is None or len(differences) < len(best):
            best = differences
    found += best or []
    system.notes.extend(found)
    return found


def _differences(m: Member, wanted: dict[str, dict[str, int]], path: Path,
                 live: dict[str, Any]) -> list[str]:
    """Where a block's servos differ from its joints' entries in the file, by register (the
    servos read once, into ``live``)."""
    if m.name not in live:
        try:
            live[m.name] = m.driver.joint_calibration()
        except DeltoctlError as exc:
            live[m.name] = exc.message
    held = live[m.name]
    if isinstance(held, str):
        return [f"{m.name}: calibration not checked ({held})"]
    return [f"{joint}: {register} is {held[joint].get(key)}, its calibration ({path}) says "
            f"{entry[key]}; calibrate again (deltoctl calibrate joints)"
            for joint, entry in wanted.items() if joint in held
            for key, register in m.driver.calibration_registers.items()
            if key in entry and held[joint].get(key) != entry[key]]
