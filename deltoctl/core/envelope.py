"""The safety envelope: the checks before any command reaches a joint (a move's targets and
speed, a position, velocity or effort command, a replayed setpoint), and the defaults every
family's motion shares. The System calls them for every caller; they send nothing."""

from __future__ import annotations

import math

from deltoctl.errors import InvalidInput, OutsideEnvelope, Refused
from deltoctl.profile.model import Component, Profile

DEFAULT_TOLERANCE = math.radians(2)
DEFAULT_VELOCITY = 0.5  # rad/s


def _bound(value: float | None, none: str) -> str:
    return none if value is None else f"{value:.4f}"


def _people(joint: Component, value: float, low: float | None = None,
            high: float | None = None, *, bound: float | None = None) -> str:
    """The SI unit of a position of ``joint`` and the values in degrees or millimetres:
    `` rad (-17.19° outside [0.00°, 115.00°])``, `` rad (40.00° > 30.00°)``."""
    from deltoctl.units import joint_dimension, shown

    dim = joint_dimension(joint.joint_type)
    if dim is None:
        return ""
    si = "rad" if dim == "angle" else "m"

    def text(v: float | None) -> str:
        return "none" if v is None else shown(v, dim)

    if bound is not None:
        return f" {si} ({text(value)} > {text(bound)})"
    return f" {si} ({text(value)} outside [{text(low)}, {text(high)}])"


def _limit(joint: Component, name: str) -> float | None:
    """The joint's ``velocity`` or ``effort`` limit (None: it has none)."""
    return None if joint.limits is None else getattr(joint.limits, name)


def check_finite(joint: Component, what: str, value: float) -> None:
    """A NaN or infinite command is bad input (exit 2): no limit can judge it."""
    if not math.isfinite(value):
        raise InvalidInput(f"{joint.name} {what} must be a finite number, got {value!r}")


def check_target(profile: Profile, joint: Component, target: float, start: float | None) -> None:
    """Refuse (OutsideEnvelope, exit 5) a target outside the joint's limits or its soft limits
    (a URDF ``<safety_controller>``), or a jog larger than allowed."""
    check_finite(joint, "target", target)
    lim = joint.limits
    if lim is not None and not lim.contains(target):
        raise OutsideEnvelope(
            f"{joint.name} target {target:.4f} is outside its limits "
            f"[{_bound(lim.lower, '-inf')}, {_bound(lim.upper, 'inf')}]"
            + _people(joint, target, lim.lower, lim.upper))
    soft = joint.soft_limits
    if soft is not None and not soft.contains(target):
        raise OutsideEnvelope(
            f"{joint.name} target {target:.4f} is outside its soft limits "
            f"[{soft.lower:.4f}, {soft.upper:.4f}]"
            + _people(joint, target, soft.lower, soft.upper) + " (<safety_controller>)")
    step = profile.safety.max_jog_step
    if start is not None and step is not None and abs(target - start) > step + 1e-9:
        raise OutsideEnvelope(
            f"{joint.name}: a move of {abs(target - start):.4f} is larger than the "
            f"profile's max_jog_step {step:.4f}" + _people(joint, abs(target - start), bound=step),
            hint="jog in smaller steps, or raise safety.max_jog_step in the profile")


def check_magnitude(joint: Component, what: str, value: float, limit: float | None,
                    cap: float | None = None) -> None:
    """Refuse (OutsideEnvelope, exit 5) a velocity or effort beyond the joint's limit, or beyond
    the cap its family derives from the profile's safety section (an effort from
    ``current_cap``)."""
    check_finite(joint, what, value)
    for bound, whose in ((limit, "its limit"), (cap, "the profile's safety cap")):
        if bound is not None and abs(value) > bound + 1e-9:
            raise OutsideEnvelope(
                f"{joint.name} {what} {value:.4f} is beyond {whose} {bound:.4f}")


def check_move(profile: Profile, joint: Component, target: float, start: float | None,
               velocity: float | None, jog: bool = True) -> None:
    """A move of one joint to ``target`` from ``start`` (its present position) at
    ``velocity`` (None: the family's default). ``jog`` False: a move to a known pose (the
    home pose, a replay's start pose), which ``max_jog_step`` does not bound."""
    if not jog:
        start = None
    elif start is None and profile.safety.max_jog_step is not None:
        raise Refused(f"{joint.name}: its position is unknown, so the move cannot be bounded "
                      "by the profile's max_jog_step; nothing moved",
                      hint="check that the joint answers (deltoctl detect)")
    check_target(profile, joint, target, start)
    if velocity is not None:
        if not velocity > 0:  # NaN too
            raise InvalidInput(f"the velocity of a move must be positive, got {velocity!r}")
        check_magnitude(joint, "velocity", velocity, _limit(joint, "velocity"))


def check_command(profile: Profile, joint: Component, interface: str, value: float,
                  present: float | None, effort_cap: float | None = None) -> None:
    """A command to one of the joint's interfaces: a position is a move from ``present``
    (bounded by ``max_jog_step``), a velocity or an effort is bounded by the joint's limit
    (and an effort by ``effort_cap``). Other interfaces (``home``, a custom one) pass."""
    if interface == "position":
        check_move(profile, joint, value, present, None)
    elif interface in ("velocity", "effort"):
        check_magnitude(joint, f"{interface} command", value, _limit(joint, interface),
                        effort_cap if interface == "effort" else None)


def check_setpoint(profile: Profile, joint: Component, setpoint: tuple[float, float, float],
                   previous: float | None) -> None:
    """One cycle's recorded setpoint (position, velocity, effort; NaN: not commanded), its
    position a step from ``previous`` (the setpoint before, else the present position). An
    effort is bounded by the joint's limit; the family clamps it to its cap, as its moves do."""
    position, velocity, effort = setpoint
    if position == position:
        check_move(profile, joint, position, previous, None)
    if velocity == velocity:
        check_command(profile, joint, "velocity", velocity, None)
    if effort == effort:
        check_command(profile, joint, "effort", effort, None)
