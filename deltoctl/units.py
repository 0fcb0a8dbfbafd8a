"""Numbers with units, as technicians type them (``5deg``, ``-0.1``, ``12mm``), and times as
people read them."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from deltoctl.errors import InvalidInput

_QUANTITY = re.compile(
    r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([a-zA-Z°]*(?:/s)?)\s*$")
ANGLE, LENGTH = "angle", "length"
_DEG = math.pi / 180
# a unit as typed: (its scale to SI, its dimension: angle, length, or either per second)
_UNITS: dict[str, tuple[float, str]] = {
    "rad": (1.0, ANGLE), "deg": (_DEG, ANGLE), "°": (_DEG, ANGLE),
    "m": (1.0, LENGTH), "mm": (1e-3, LENGTH),
}
_UNITS.update({f"{u}/s": (scale, f"{dim}/s") for u, (scale, dim) in list(_UNITS.items())})
# what a joint's position is in: the SI unit, the one typed most
JOINT_DIMENSIONS = {"revolute": ANGLE, "continuous": ANGLE, "prismatic": LENGTH}
_NAMES = {ANGLE: ("an angle", "rad", "deg"), LENGTH: ("a length", "m", "mm")}


@dataclass(frozen=True)
class Quantity:
    """A number as typed: its value in SI, its unit as typed ("" for a bare number) and the
    unit's dimension (None for a bare number)."""

    value: float
    unit: str = ""
    dimension: str | None = None


def parse_unit(text: str | float | int) -> Quantity:
    """Parse a number with an optional unit (rad, deg, m, mm, or one of them per second).
    Raises ValueError."""
    if isinstance(text, bool):
        raise ValueError(f"expected a number, got {text!r}")
    if isinstance(text, (int, float)):
        return Quantity(float(text))
    match = _QUANTITY.match(str(text))
    if not match or (match.group(2) and match.group(2) not in _UNITS):
        raise ValueError(
            f"expected a number with an optional unit (rad, deg, m, mm), got {text!r}"
        )
    unit = match.group(2)
    scale, dimension = _UNITS[unit] if unit else (1.0, None)
    return Quantity(float(match.group(1)) * scale, unit, dimension)


def parse_quantity(text: str | float | int) -> float:
    """Parse a number with an optional unit into SI (rad or m). Raises ValueError."""
    return parse_unit(text).value


def joint_dimension(joint_type: str) -> str | None:
    """What a joint's position is: an angle (revolute, continuous), a length (prismatic)."""
    return JOINT_DIMENSIONS.get(joint_type)


def mismatch(given: Quantity, dimension: str | None, speed: bool = False) -> str | None:
    """Why ``given`` does not fit a joint whose position is ``dimension`` (None: it fits).
    A bare number fits (SI); a speed may be typed as a position unit, per second."""
    if given.dimension is None or dimension is None:
        return None
    if given.dimension == dimension or (speed and given.dimension == f"{dimension}/s"):
        return None
    name, si, common = _NAMES[dimension]
    if speed:
        return (f"a speed in {si}/s or {common}/s (a bare number is {si}/s), "
                f"not {given.unit}")
    return f"{name} in {si} or {common} (a bare number is {si}), not {given.unit}"


def joint_quantity(text: str | float, joint_type: str, what: str, joint: str,
                   speed: bool = False) -> Quantity:
    """A finite quantity typed for ``what`` of ``joint``, its unit of the joint's dimension;
    InvalidInput (exit 2) naming the joint's unit otherwise."""
    value = quantity(text, what)
    given = parse_unit(text)
    wrong = mismatch(given, joint_dimension(joint_type), speed)
    if wrong:
        raise InvalidInput(f"{what} {text}: {joint} is a {joint_type} joint, so it takes "
                           f"{wrong}")
    return Quantity(value, given.unit, given.dimension)


def shown(value: float, dimension: str | None, unit: str = "", signed: bool = False) -> str:
    """A joint's position (SI) for people: in ``unit`` when an angle or length was typed in
    it, else degrees for an angle and millimetres for a length, with fixed decimals."""
    sign = "+" if signed else ""
    unit = unit.removesuffix("/s")
    if dimension is None or unit not in _UNITS or _UNITS[unit][1] != dimension:
        unit = {ANGLE: "deg", LENGTH: "mm"}.get(dimension or "", "")
    if not unit:
        return f"{value:{sign}.4f}"
    scaled = value / _UNITS[unit][0]
    if unit in ("deg", "°"):
        return f"{scaled:{sign}.2f}°"
    return f"{scaled:{sign}.{2 if unit == 'mm' else 4}f} {unit}"


def _parsed(text: str | float, what: str) -> float:
    try:
        return parse_quantity(text)
    except ValueError as exc:
        raise InvalidInput(f"{what}: {exc}") from None


def quantity(text: str | float, what: str) -> float:
    """A finite quantity typed for ``what`` (an option, an argument), in SI; InvalidInput
    (exit 2) naming ``what`` otherwise."""
    value = _parsed(text, what)
    if not math.isfinite(value):
        raise InvalidInput(f"{what} must be a finite number, got {text!r}")
    return value


def positive(text: str | None, what: str) -> float | None:
    """A quantity > 0 (a speed), or None when none is typed."""
    value = quantity(text, what) if text else None
    if value is not None and value <= 0:
        raise InvalidInput(f"{what} must be positive")
    return value


def nonnegative(text: str | None, what: str) -> float | None:
    """A finite quantity ≥ 0 (a tolerance, a deviation), or None when none is typed."""
    if text is None:
        return None
    value = _parsed(text, what)
    if not math.isfinite(value) or value < 0:
        raise InvalidInput(f"{what} must be a finite number ≥ 0, got {text!r}")
    return value


def format_number(value: float) -> str:
    """Shortest text that reads back as the same float (ints without a dot)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    whole = isinstance(value, float) and value.is_integer() and abs(value) < 1e15
    if isinstance(value, int) or whole:
        return str(int(value))
    return repr(float(value))


def utc_time(t_ns: int | None) -> str:
    """A time of a recording as people read it: ISO 8601, UTC, to the millisecond."""
    if t_ns is None:
        return "-"
    from datetime import datetime, timezone

    stamp = datetime.fromtimestamp(t_ns / 1e9, timezone.utc)
    return stamp.isoformat(timespec="milliseconds").replace("+00:00", "Z")


def shown_value(value: object) -> str:
    """A configuration value as a person reads it."""
    if value is None:
        return "—"
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)
