"""A stream for people: the live table on a terminal (a table per set of interfaces, the
links' states, each tactile grid as a heat map), redrawn as the values come."""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from typing import Any

from deltoctl.core.runner import Sink
from deltoctl.record.cdr import stream_grids

LIVE_PERIOD = 0.05  # s between redraws of the live table: people read at most 20 a second

# a column: its unit (None: unknown or none), the factor from SI to it, and its decimals,
# fixed so that a column does not jitter as its values change
Column = tuple[str | None, float, int]
_JOINT_COLUMNS: dict[str, dict[str, Column]] = {
    "angle": {"position": ("deg", 180 / math.pi, 2), "velocity": ("deg/s", 180 / math.pi, 1)},
    "length": {"position": ("mm", 1e3, 2), "velocity": ("mm/s", 1e3, 1)},
}
_COLUMNS: dict[str, Column] = {
    "position": (None, 1.0, 4), "velocity": (None, 1.0, 4), "effort": (None, 1.0, 3),
    "temperature": ("°C", 1.0, 1), "force": ("N", 1.0, 2), "torque": ("N·m", 1.0, 3),
    "linear_acceleration": ("m/s²", 1.0, 2), "angular_velocity": ("rad/s", 1.0, 3),
    "orientation": (None, 1.0, 4),
}
_OTHER: Column = (None, 1.0, 3)  # whole numbers (a flag, a digital input) without decimals


def column(interface: str, dimension: str | None = None) -> Column:
    """How a column of ``interface`` is shown: a joint's position and velocity in degrees
    (revolute) or millimetres (prismatic), a force in N and a torque in N·m (``force.x``)."""
    joint = _JOINT_COLUMNS.get(dimension or "", {})
    base = interface.split(".")[0]
    return joint.get(interface) or _COLUMNS.get(base, _OTHER)


def _header(interface: str, col: Column) -> str:
    return interface if col[0] is None else f"{interface}\n({col[0]})"


def _cell(value: Any, col: Column) -> str:
    if value is None:
        return "—"
    if not isinstance(value, int | float):
        return str(value)
    if col is _OTHER and float(value).is_integer():
        return f"{value:.0f}"
    text = f"{value * col[1]:.{col[2]}f}"
    return text[1:] if text.startswith("-") and not float(text) else text  # no -0.00


class LiveSink(Sink):
    """The live table on a terminal, redrawn at most 20 times a second."""

    def __init__(self, names: list[str], rate: float,
                 joint_types: Mapping[str, str] | None = None) -> None:
        from rich.live import Live

        self.names = names
        self.rate = rate
        self.joint_types = joint_types
        self.samples = 0
        self.shown = 0.0
        self.live = Live(auto_refresh=False)
        self.live.start()

    def frame(self, t_ns: int, values: dict[str, float]) -> None:
        self.samples += 1
        if time.monotonic() - self.shown >= LIVE_PERIOD:
            sample = {n: values.get(n) for n in self.names}
            title = f"{self.samples} samples at {self.rate:g} Hz"
            self.live.update(live_tables(sample, title, self.joint_types), refresh=True)
            self.shown = time.monotonic()

    def close(self, _: Any) -> None:
        self.live.stop()


def heat_maps(sample: dict[str, Any], grids: dict[str, list[list[str]]]) -> Any:
    """Each tactile grid as a small heat map (its cells' values on a dark → red → yellow
    scale, the hottest cell of the sample at the top), side by side; the grids' common name
    above them, each titled by the rest of its name."""
    import os

    from rich.columns import Columns
    from rich.style import Style
    from rich.table import Table
    from rich.text import Text

    top = max([1.0] + [v for rows in grids.values() for row in rows for n in row
                       if isinstance(v := sample.get(n), int | float) and v == v])
    # the names' common start as strings (not as paths), cut after its last _
    common = os.path.commonprefix(list(grids)) if len(grids) > 1 else ""  # noqa: RUF071
    common = common[:common.rfind("_") + 1]
    maps = []
    for part, rows in grids.items():
        t = Table(title=part[len(common):] or part, show_header=False, box=None, padding=0,
                  title_justify="left")
        for _ in rows[0]:
            t.add_column(justify="right", width=6, no_wrap=True)
        for row in rows:
            cells = []
            for name in row:
                v = sample.get(name)
                if not isinstance(v, int | float) or v != v:
                    cells.append(Text("     —"))
                    continue
                f = max(0.0, min(1.0, v / top))
                red, green = min(255, 40 + int(430 * f)), max(0, min(255, int(510 * f) - 255))
                style = Style(bgcolor=f"rgb({red},{green},{int(40 * (1 - f))})",
                              color="black" if f > 0.6 else "white")
                cells.append(Text(f"{v:6.0f}", style=style))
            t.add_row(*cells)
        maps.append(t)
    return Columns(maps, padding=(1, 2), title=common.rstrip("_") or None)


def live_tables(sample: dict[str, Any], title: str,
                joint_types: Mapping[str, str] | None = None) -> Any:
    """One row per part and a column per interface: a table for each set of interfaces
    (joints, F/T sensors, GPIO), so a hand of 20 joints fits on a screen; the links' states in
    the title; each tactile grid as a heat map below. Each column's unit under its name
    (``joint_types``, a joint's ros2_control type, says a revolute joint's position is
    shown in degrees, a prismatic one's in mm), its values with fixed decimals. Laid out for
    the console it is drawn on: columns that do not fit its width go to a table of their
    own below (the part's name repeated), so no value is ever cut."""
    from rich import box
    from rich.table import Table

    from deltoctl.units import joint_dimension

    types = joint_types or {}

    grids = stream_grids(list(sample))
    parts: dict[str, dict[str, Any]] = {}
    links: dict[str, Any] = {}
    for name, value in sample.items():
        part, _, interface = name.rpartition("/")
        if interface == "connection_status":
            links[part] = value
        elif part not in grids:
            parts.setdefault(part, {})[interface] = value
    overall = links.pop("system", None)
    if overall is not None:
        down = [p for p, v in links.items() if not v]
        title += (" · links up" if overall else
                  f" · [bold red]link lost: {', '.join(down) or 'reconnecting'}[/]")
    sets: dict[tuple[str, ...], list[tuple[str, list[str]]]] = {}
    for part, values in parts.items():
        dimension = joint_dimension(types[part]) if part in types else None
        cols = [column(interface, dimension) for interface in values]
        headers = [_header(i, c) for i, c in zip(values, cols)]
        if any("\n" in h for h in headers):  # every name on the first line, units below
            headers = [h if "\n" in h else h + "\n" for h in headers]
        sets.setdefault(tuple(headers), []).append(
            (part, [_cell(v, c) for v, c in zip(values.values(), cols)]))

    def chunks(columns: tuple[str, ...], rows: list, width: int) -> list[list[int]]:
        """Column indexes per table: as many as fit ``width`` (a column costs its text + 3,
        a table 1 more)."""
        start = used = max(len(p) for p, _ in rows) + 4
        out: list[list[int]] = [[]]
        for i, column in enumerate(columns):
            cost = max([len(line) for line in column.splitlines()]
                       + [len(r[i]) for _, r in rows]) + 3
            if out[-1] and used + cost > width:
                out.append([])
                used = start
            out[-1].append(i)
            used += cost
        return out

    class Tables:
        def __rich_console__(self, console: Any, options: Any) -> Any:
            first = True
            for columns, rows in sets.items():
                for chunk in chunks(columns, rows, options.max_width):
                    t = Table(title=title if first else None, title_justify="left",
                              box=box.SIMPLE_HEAD)
                    first = False
                    t.add_column(no_wrap=True)
                    for i in chunk:
                        t.add_column(columns[i], justify="right", overflow="fold")
                    for part, cells in rows:
                        t.add_row(part, *(cells[i] for i in chunk))
                    yield t
            if grids:
                yield heat_maps(sample, grids)

    return Tables()
