"""The safety checks before any move, and the defaults every family's motion shares."""

from __future__ import annotations

import math

from deltoctl.errors import Refused
from deltoctl.profile.model import Component, Profile

DEFAULT_TOLERANCE = math.radians(2)
DEFAULT_VELOCITY = 0.5  # rad/s


def _bound(value: float | None, none: str) -> str:
    return none if value is None else f"{value:.4f}"


def check_target(profile: Profile, joint: Component, target: float, start: float | None) -> None:
    """Refuse (exit 5) a target outside the joint's limits or its soft limits (a URDF
    ``<safety_controller>``), or a jog larger than allowed."""
    lim = joint.limits
    if lim is not None and not lim.contains(target):
        raise Refused(f"{joint.name} target {target:.4f} is outside its limits "
                      f"[{_bound(lim.lower, '-inf')}, {_bound(lim.upper, 'inf')}]")
    soft = joint.soft_limits
    if soft is not None and not soft.contains(target):
        raise Refused(f"{joint.name} target {target:.4f} is outside its soft limits "
                      f"[{soft.lower:.4f}, {soft.upper:.4f}] (<safety_controller>)")
    step = profile.safety.max_jog_step
    if start is not None and step is not None and abs(target - start) > step + 1e-9:
        raise Refused(f"{joint.name}: a move of {abs(target - start):.4f} is larger than the "
                      f"profile's max_jog_step {step:.4f}",
                      hint="jog in smaller steps, or raise safety.max_jog_step in the profile")
