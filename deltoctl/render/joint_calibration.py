"""``calibrate joints`` as a person reads it: the live table of each joint's present, lowest
and highest position while the arm is moved by hand, and the calibration made."""

from __future__ import annotations

import math
import time
from typing import Any

RANGE_COLUMNS = ("joint", "min", "present", "max")
LIVE_PERIOD = 0.05  # s: redrawn at most 20 times a second


class RangeLive:
    """The live range table on the terminal (stderr), until ``close``."""

    def __init__(self) -> None:
        from rich.console import Console
        from rich.live import Live

        self.live = Live(console=Console(stderr=True), auto_refresh=False)
        self.shown = 0.0
        self.live.start()

    def show(self, rows: list[dict[str, Any]]) -> None:
        from rich.table import Table

        if time.monotonic() - self.shown < LIVE_PERIOD:
            return
        table = Table(title="the range moved by hand (steps): Enter when every joint has "
                            "been through its range", header_style="bold")
        for column in RANGE_COLUMNS:
            table.add_column(column, justify="left" if column == "joint" else "right")
        for r in rows:
            table.add_row(r["joint"], *(str(r[k]) for k in RANGE_COLUMNS[1:]))
        self.live.update(table, refresh=True)
        self.shown = time.monotonic()

    def close(self) -> None:
        self.live.stop()


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
