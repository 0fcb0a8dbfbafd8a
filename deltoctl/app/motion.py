"""Motion procedures: the homing plan and its run, moves with their report, jogs. The System
holds the envelope (every target checked before a byte is sent); these decide what to move
and report what happened. Confirmation is the caller's."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from deltoctl.errors import DeviceError, InvalidInput

if TYPE_CHECKING:
    from deltoctl.core.system import System
    from deltoctl.profile.model import Component, Profile
    from deltoctl.units import Quantity

Progress = Callable[[float], None]
# a homing joint's progress: its name, what it does now, how far (0 to 1)
HomeProgress = Callable[[str, str, float], None]


def _near(name: str, names: list[str]) -> str:
    from deltoctl.suggest import did_you_mean

    return did_you_mean(name, names)


def moving_joints(profile: Profile, names: Sequence[str]) -> dict[str, Component]:
    """The joints a jog names, each once and each with a command interface that moves it."""
    comps: dict[str, Component] = {}
    for name in names:
        comp = profile.component(name)
        if comp is None or comp.kind != "joint":
            raise InvalidInput(f"{profile.name} has no joint {name!r}"
                               + _near(name, [j.name for j in profile.joints()]))
        if comp.command("effort") is None and comp.command("position") is None:
            raise InvalidInput(f"{name} has no effort or position command interface to move "
                               "it")
        if name in comps:
            raise InvalidInput(f"{name} is given twice")
        comps[name] = comp
    return comps


def ready_to_jog(system: System, joints: Sequence[str]) -> None:
    """Every block holding one of ``joints`` can move them now (homed first …)."""
    for names in system.by_block(list(joints)).values():
        m = system.member(names[0])
        if not m.can("jog"):
            raise InvalidInput(f"{m.name} cannot move its joints")
        m.driver.check_motion(names)


def present_positions(system: System, joints: Sequence[str]) -> dict[str, float]:
    """Where each joint is now (one read); a joint whose position is unknown (its servo does
    not answer) refuses the move that would start from it."""
    values = system.read()
    unknown = [j for j in joints if values.get(f"{j}/position") is None]
    if unknown:
        raise DeviceError(f"the position of {', '.join(unknown)} is not known: nothing moved",
                          hint="check that the joint answers (deltoctl detect)")
    return {j: values[f"{j}/position"] for j in joints}


def jog_pairs(profile: Profile, joint: str, delta: str | None, more: Sequence[str] | None,
              to: str | None) -> list[tuple[str, str | None]]:
    """(joint, its DELTA) of each joint a jog moves — one joint by DELTA or to POS, and more
    JOINT DELTA pairs (not with POS) — each a joint of ``profile`` that can move, once."""
    if (delta is None) == (to is None):
        raise InvalidInput("give either DELTA or --to POS")
    pairs = [(joint, delta)]
    if more:
        if to is not None or len(more) % 2:
            raise InvalidInput("more joints come as JOINT DELTA pairs (and not with --to)")
        pairs += list(zip(more[0::2], more[1::2]))
    moving_joints(profile, [name for name, _ in pairs])
    return pairs


def jog_targets(system: System, steps: Sequence[tuple[str, str | float | None]],
                to: str | float | None = None) -> tuple[dict[str, float], list[str]]:
    """Each joint's target — its step (``5deg``, ``0.1``) from where it is now, or ``to`` —
    once every block holding one can move (homed first …); and each move described, for
    the confirmation, in the unit typed (else degrees or millimetres). A unit that is not
    the joint's (``5mm`` on a revolute joint) is refused before anything is read."""
    from deltoctl.units import joint_dimension, shown

    typed = {name: _joint_step(system.profile, name, step, to) for name, step in steps}
    names = list(typed)
    ready_to_jog(system, names)
    present = present_positions(system, names)
    targets, moves = {}, []
    for name, given in typed.items():
        start = present[name]
        target = given.value if to is not None else start + given.value
        if not math.isfinite(target):
            raise InvalidInput(f"the target of {name} must be finite")
        targets[name] = target
        dim = joint_dimension(_joint(system.profile, name).joint_type)
        moves.append(f"{name} ({system.member(name).name}) from "
                     f"{shown(start, dim, given.unit)} to {shown(target, dim, given.unit)} "
                     f"({shown(target - start, dim, given.unit, signed=True)})")
    return targets, moves


def _joint(profile: Profile, name: str) -> Component:
    comp = profile.component(name)
    if comp is None or comp.kind != "joint":
        raise InvalidInput(f"{profile.name} has no joint {name!r}"
                           + _near(name, [j.name for j in profile.joints()]))
    return comp


def _joint_step(profile: Profile, name: str, step: str | float | None,
                to: str | float | None) -> Quantity:
    """A jog's DELTA (or --to POS) for ``name``, in the joint's unit."""
    from deltoctl.units import joint_quantity

    what, text = ("--to", to) if to is not None else ("DELTA", "" if step is None else step)
    return joint_quantity(text, _joint(profile, name).joint_type, what, name)


def joints_quantity(profile: Profile, joints: Sequence[str], text: str | float | None,
                    what: str, speed: bool = False) -> float | None:
    """One quantity for every joint in ``joints`` (a speed, a tolerance) in SI, its unit
    that of each of them (a bare number is SI for each); None when none is given."""
    from deltoctl.units import joint_quantity, quantity

    if text is None or text == "":
        return None
    value = quantity(text, what)
    for name in joints:
        joint_quantity(text, _joint(profile, name).joint_type, what, name, speed=speed)
    return value


def joint_speed(profile: Profile, joints: Sequence[str], velocity: str | float | None,
                what: str = "--velocity") -> float | None:
    """A move's speed (``20deg/s``, ``10mm/s``, a bare number in rad/s or m/s) in SI, its
    unit that of every joint in ``joints``; None when none is given. Not positive: exit 2."""
    speed = joints_quantity(profile, joints, velocity, what, speed=True)
    if speed is not None and not speed > 0:
        raise InvalidInput(f"{what} must be positive")
    return speed


def joint_positions(profile: Profile, targets: Mapping[str, str | float],
                    what: str = "target") -> dict[str, float]:
    """Absolute targets (``30deg``, ``12mm``, a bare number in rad or m) in SI, each in its
    joint's unit."""
    from deltoctl.units import joint_quantity

    return {name: joint_quantity(value, _joint(profile, name).joint_type, what, name).value
            for name, value in targets.items()}


def move(system: System, targets: Mapping[str, float], velocity: float | None = None,
         progress: Progress | None = None, *, jog: bool = True) -> dict[str, Any]:
    """Move joints to ``targets``, the blocks on several links at once, and stop the blocks
    that moved on the way out; the report a ``jog --json`` prints. A move the envelope or a
    block's motion rules refuse has no effect on any block: checked before anything is sent,
    it stops nothing either."""
    from deltoctl.core.runner import interrupted_by_signals

    targets = dict(targets)
    system.check_move(targets, velocity, jog=jog)
    system.check_ready(targets)
    try:
        with interrupted_by_signals():
            result = system.move(targets, velocity, progress, jog=jog)
    finally:
        system.stop(system.by_block(targets))
    values = system.read()
    return {
        "settled": result.settled,
        "seconds": round(result.seconds, 3),
        "blocks": [{"name": name, "joints": {
            j: {"target": targets[j], "position": values.get(f"{j}/position"),
                "settled": j not in result.unsettled} for j in joints}}
            for name, joints in system.by_block(targets).items()],
        "unsettled": result.unsettled,
    }


def fail_unsettled(report: Mapping[str, Any], profile: Profile | None = None) -> None:
    """A move whose joints did not all settle failed (exit 1), naming each with where it
    ended and its target (in degrees or millimetres when ``profile`` says which)."""
    unsettled = report.get("unsettled")
    if not unsettled:
        return
    from deltoctl.units import joint_dimension, shown

    ended = {j: e for b in report.get("blocks", ()) for j, e in b["joints"].items()}

    def where(name: str) -> str:
        entry = ended.get(name, {})
        position, target = entry.get("position"), entry.get("target")
        if position is None or target is None:
            return name
        dim = joint_dimension(_joint(profile, name).joint_type) if profile else None
        return f"{name} at {shown(position, dim)}, its target {shown(target, dim)}"

    raise DeviceError(f"{len(unsettled)} joint(s) did not settle: "
                      f"{'; '.join(where(j) for j in unsettled)}")


@dataclass
class HomePlan:
    """What ``home`` will do: joints with a homing routine (into a hard stop, or a drive's own
    homing mode; one at a time), and the others' home poses."""

    profile: str
    routine: list[str] = field(default_factory=list)
    targets: dict[str, float] = field(default_factory=dict)

    def describe(self) -> str:
        what = []
        if self.routine:
            what.append(f"home {', '.join(self.routine)} one at a time, each by its own "
                        "routine (into its hard stop, or the drive's homing mode)")
        if self.targets:
            what.append(f"move {len(self.targets)} joints to the home pose")
        return f"{self.profile}: " + "; then ".join(what)


def plan_home(profile: Profile, hardware: Sequence[str] = (),
              joints: Sequence[str] = ()) -> HomePlan:
    """The homing plan of the selected blocks (or of ``joints`` only), each home pose within
    the envelope — checked before anyone is asked."""
    from deltoctl import registry
    from deltoctl.core import envelope
    from deltoctl.core.system import select_blocks

    known = [j.name for j in profile.joints()]
    for name in joints:
        if name not in known:
            raise InvalidInput(f"{profile.name} has no joint {name!r}" + _near(name, known))
    blocks = select_blocks(profile, hardware)
    chosen = [j for hw in blocks for j in hw.joints if not joints or j.name in joints]
    # a routine: a home interface, or the family says the device homes the joint itself
    homing = set().union(*(registry.homing_joints(profile, hw) for hw in blocks))
    plan = HomePlan(profile.name, [j.name for j in chosen if j.command("home") or j.name in homing])
    for j in chosen:
        if j.name not in plan.routine and (j.command("effort") or j.command("position")) \
                and j.mimic is None:
            plan.targets[j.name] = profile.safety.home_pose.get(j.name, 0.0)
            envelope.check_move(profile, j, plan.targets[j.name], None, None, jog=False)
    if not plan.routine and not plan.targets:
        raise InvalidInput(f"nothing to home in {profile.name}: no joint with a home, effort "
                           "or position command interface")
    return plan


def _home_routine(system: System, homing: list[str], force: bool,
                  show: HomeProgress | None) -> list[dict[str, Any]]:
    """Each joint runs into its hard stop, one at a time, in the profile's homing order,
    block by block."""
    from deltoctl.core.runner import interrupted_by_signals

    order = [j for j in system.profile.safety.homing_order if j in homing]
    order += [j for j in homing if j not in order]
    blocks = []
    with interrupted_by_signals():
        for name, joints in system.by_block(order).items():
            outcome = system.member(joints[0]).driver.home(joints, force,
                                                           show or (lambda *_: None))
            values = system.read()
            blocks.append({"name": name, "joints": {
                j: {"outcome": outcome.get(j), "position": values.get(f"{j}/position")}
                for j in joints}})
    return blocks


def home(system: System, plan: HomePlan, force: bool = False, velocity: float | None = None,
         progress: Progress | None = None, show: HomeProgress | None = None) -> dict[str, Any]:
    """Run a homing plan: the routines first (``show`` follows each joint), then the home
    pose (``progress``); a block that cannot home is a warning (``cannot_home``)."""
    unable = [m.name for m in system if not m.can("home")
              and any(j.name in plan.targets or j.name in plan.routine for j in m.hw.joints)]
    if unable:
        system.notes.append(f"{', '.join(unable)}: cannot home")
    targets = {j: t for j, t in plan.targets.items() if system.member(j).can("home")}
    if targets:  # the home pose at this speed, before any routine runs
        system.check_move(targets, velocity, jog=False)
    started = time.monotonic()
    report: dict[str, Any] = {"blocks": []}
    if plan.routine:
        report["blocks"] += _home_routine(system, plan.routine, force, show)
    if targets:
        moved = move(system, targets, velocity, progress, jog=False)
        report["blocks"] += moved["blocks"]
        report["settled"], report["unsettled"] = moved["settled"], moved["unsettled"]
        report["seconds"] = moved["seconds"]
    # one shape whatever the family: a homing routine ends at its stop, settled
    report.setdefault("settled", True)
    report.setdefault("unsettled", [])
    report.setdefault("seconds", round(time.monotonic() - started, 3))
    report["cannot_home"] = unable
    return report
