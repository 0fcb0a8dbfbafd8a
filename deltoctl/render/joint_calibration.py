"""``calibrate joints`` as a person reads it: the live table of each joint's present, lowest
and highest position while the arm is moved by hand, and the calibration made."""

from __future__ import annotations

import math
import time
from typing import Any

RANGE_COLUMNS = ("joint", "min", "present", "max")
LIVE_PERIOD = 0.05  # s: redrawn at most 20 times a second


class RangeLive:
    """The live range table on the terminal (stderr) while it is sampled, when ``shown``; a
    context that ends it."""

    def __init__(self, shown: bool = True) -> None:
        self.shown = shown
        self.live: Any = None
        self.drawn = 0.0

    def __enter__(self) -> RangeLive:
        return self

    def __exit__(self, *_: Any) -> None:
        if self.live is not None:
            self.live.stop()

    def show(self, rows: list[dict[str, Any]]) -> None:
        """Draw this sample's rows (at most 20 times a second)."""
        if not self.shown or time.monotonic() - self.drawn < LIVE_PERIOD:
            return
        from rich.console import Console
        from rich.live import Live
        from rich.table import Table

        if self.live is None:
            self.live = Live(console=Console(stderr=True), auto_refresh=False)
            self.live.start()
        table = Table(title="the range moved by hand (steps): Enter once every joint has "
                            "been through its range", header_style="bold")
        for column in RANGE_COLUMNS:
            table.add_column(column, justify="left" if column == "joint" else "right")
        for r in rows:
            table.add_row(r["joint"], *(str(r[k]) for k in RANGE_COLUMNS[1:]))
        self.live.update(table, refresh=True)
        self.drawn = time.monotonic()


def calibration_table(result: dict[str, Any]) -> tuple[str, list[str], list[list[Any]]]:
    """The calibration made: per joint its offset, limits, range in degrees and verdicts."""
    rows = []
    for r in result["joints"]:
        moved = ("" if r["full_turn"] else
                 f"{math.degrees(r['lower']):.1f}..{math.degrees(r['upper']):.1f}")
        rows.append([r["joint"], r["id"], r["homing_offset"], r["range_min"], r["range_max"],
                     moved, r["check"], r["written"]])
    return (f"{result['profile']}: joint calibration",
            ["joint", "id", "homing offset", "min", "max", "range (°)", "limits", "servo"], rows)
