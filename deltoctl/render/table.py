"""A table for people: rich's on a terminal (its borders dropped when they do not fit, a value
wrapped, never cut), plain aligned columns when piped."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any


def cells(rows: Sequence[Sequence[Any]]) -> list[list[str]]:
    """Every value as its text (None as empty)."""
    return [["" if c is None else str(c) for c in row] for row in rows]


def plain_lines(title: str | None, columns: Sequence[str], rows: list[list[str]]) -> list[str]:
    """The title, the upper-cased header and the rows, each column as wide as its widest."""
    widths = [max([len(c)] + [len(r[i]) for r in rows]) for i, c in enumerate(columns)]
    lines = [title] if title else []
    lines.append("  ".join(c.upper().ljust(w) for c, w in zip(columns, widths)).rstrip())
    lines += ["  ".join(v.ljust(w) for v, w in zip(row, widths)).rstrip() for row in rows]
    return lines


def print_rich(title: str | None, columns: Sequence[str], rows: list[list[str]]) -> None:
    """The table drawn by rich on the terminal."""
    from rich.console import Console
    from rich.table import Table

    t = Table(title=title, header_style="bold")
    for column in columns:  # too narrow a terminal wraps a value, never cuts it
        t.add_column(column, overflow="fold")
    for row in rows:
        t.add_row(*row)
    console = Console()
    if _natural_width(console, t) > console.width:  # no room for the borders
        from rich import box

        t.box, t.pad_edge, t.show_edge = box.SIMPLE_HEAD, False, False
    console.print(t)


def _natural_width(console: Any, renderable: Any) -> int:
    """The width ``renderable`` takes with all the room it wants."""
    from rich.measure import Measurement

    return Measurement.get(console, console.options.update_width(1 << 16), renderable).maximum
