"""Numbers with units, as technicians type them (``5deg``, ``-0.1``, ``12mm``), and times as
people read them."""

from __future__ import annotations

import math
import re

from deltoctl.errors import InvalidInput

_QUANTITY = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([a-zA-Z°]*)\s*$")
_SCALE = {"": 1.0, "rad": 1.0, "deg": math.pi / 180, "°": math.pi / 180, "m": 1.0, "mm": 1e-3}


def parse_quantity(text: str | float | int) -> float:
    """Parse a number with an optional unit into SI (rad or m). Raises ValueError."""
    if isinstance(text, bool):
        raise ValueError(f"expected a number, got {text!r}")
    if isinstance(text, (int, float)):
        return float(text)
    match = _QUANTITY.match(str(text))
    if not match or match.group(2) not in _SCALE:
        raise ValueError(
            f"expected a number with an optional unit (rad, deg, m, mm), got {text!r}"
        )
    return float(match.group(1)) * _SCALE[match.group(2)]


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
