"""Turning a limp servo of an emulated bus by hand, as a person moves an arm whose torque is
off: the control lines ``hand JOINT DEGREES`` (the shaft turned to that angle from the middle
of its turn) and ``sweep JOINT FROM TO SECONDS`` (turned from one angle to the other over that
time, as a hand moving it while a recording runs). A servo whose torque is on holds its pose:
the line is refused. Each family's emulated servo offers a ``Shaft``."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Protocol

from deltoctl.errors import InvalidInput

LIMIT_DEGREES = 1800.0  # five turns either way
LIMIT_SECONDS = 3600.0


@dataclass(frozen=True)
class Hand:
    """A hand's move of a shaft: from one step to another over ``seconds`` from ``t0``."""

    start: float
    end: float
    t0: float
    seconds: float

    def now(self) -> tuple[float, bool]:
        """Where the shaft is now (steps), and whether the hand is done."""
        fraction = 1.0 if self.seconds <= 0 else min(1.0, (time.monotonic() - self.t0)
                                                     / self.seconds)
        return self.start + (self.end - self.start) * fraction, fraction >= 1.0


class Shaft(Protocol):
    """What an emulated servo offers a hand: whether its torque is off, where the middle of its
    turn is and how many steps a degree, and the hand that moves it (its ``update`` follows
    ``hand`` while it is set)."""

    hand: Hand | None

    def limp(self) -> bool: ...

    def steps(self, degrees: float) -> float: ...

    def here(self) -> float: ...


def _angle(text: str, what: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and abs(value) <= LIMIT_DEGREES):
        raise InvalidInput(f"{what} must be degrees within ±{LIMIT_DEGREES:g}, got {text!r}")
    return value


def add_controls(control: Callable[[str, str, Callable[[list[str]], str]], None],
                 shafts: Mapping[str, Shaft]) -> None:
    """The ``hand`` and ``sweep`` lines for the servos of ``shafts`` (joint → servo), through
    the serve context's ``control``."""
    if not shafts:
        return

    def limp(name: str) -> Shaft:
        shaft = shafts.get(name)
        if shaft is None:
            raise InvalidInput(f"{name!r} is not a servo joint served here (joints: "
                               f"{', '.join(shafts)})")
        if not shaft.limp():
            raise InvalidInput(f"{name}: its torque is on, the servo holds its pose; switch it "
                               "off first (deltoctl torque off)")
        return shaft

    def hand(words: list[str]) -> str:
        if len(words) != 2:
            raise InvalidInput(f"takes JOINT DEGREES, got {' '.join(words)!r}")
        degrees = _angle(words[1], "DEGREES")
        shaft = limp(words[0])
        shaft.hand = Hand(shaft.here(), shaft.steps(degrees), time.monotonic(), 0.0)
        return f"{words[0]}: turned by hand to {degrees:g}°"

    def sweep(words: list[str]) -> str:
        if len(words) != 4:
            raise InvalidInput(f"takes JOINT FROM TO SECONDS, got {' '.join(words)!r}")
        start, end = _angle(words[1], "FROM"), _angle(words[2], "TO")
        try:
            seconds = float(words[3])
        except ValueError:
            seconds = math.nan
        if not 0 <= seconds <= LIMIT_SECONDS:
            raise InvalidInput(f"SECONDS must be 0 to {LIMIT_SECONDS:g}, got {words[3]!r}")
        shaft = limp(words[0])
        shaft.hand = Hand(shaft.steps(start), shaft.steps(end), time.monotonic(), seconds)
        return f"{words[0]}: swept by hand from {start:g}° to {end:g}° over {seconds:g} s"

    control("hand", "hand JOINT DEGREES: a servo whose torque is off turned by hand to this "
            "angle from the middle of its turn", hand)
    control("sweep", "sweep JOINT FROM TO SECONDS: a servo whose torque is off swept by hand "
            "between these angles over that time", sweep)
