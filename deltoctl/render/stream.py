"""A stream for people: the live table on a terminal (a table per set of interfaces, the
links' states, each tactile grid as a heat map), redrawn as the values come."""

from __future__ import annotations

import contextlib
import math
import sys
import time
from collections.abc import Callable, Iterator, Mapping
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
                 joint_types: Mapping[str, str] | None = None, source: str | None = None) -> None:
        from rich.live import Live

        self.names = names
        self.rate = rate
        self.joint_types = joint_types
        self.source = source or f"at {rate:g} Hz"  # after "N samples" in the title
        self.samples = 0
        self.shown = 0.0
        self.live = Live(auto_refresh=False)
        self.live.start()

    def frame(self, t_ns: int, values: dict[str, float]) -> None:
        self.samples += 1
        if time.monotonic() - self.shown >= LIVE_PERIOD:
            sample = {n: values.get(n) for n in self.names}
            title = f"{self.samples} samples {self.source}"
            self.live.update(live_tables(sample, title, self.joint_types, live=True),
                             refresh=True)
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
                joint_types: Mapping[str, str] | None = None, live: bool = False) -> Any:
    """One row per part and a column per interface: a table for each set of interfaces
    (joints, F/T sensors, GPIO), so a hand of 20 joints fits on a screen; the links' states in
    the title; each tactile grid as a heat map below. Each column's unit under its name
    (``joint_types``, a joint's ros2_control type, says a revolute joint's position is
    shown in degrees, a prismatic one's in mm), its values with fixed decimals. Laid out for
    the console it is drawn on: columns that do not fit its width go to a table of their
    own below (the part's name repeated), so no value is ever cut. ``live`` (the live view):
    fitted to the console's height too — a long table's rows in groups side by side when the
    width allows, else the rows that do not fit left out and counted on a line that says how
    to pick fewer (every set keeps a row per group, so sensors and GPIOs stay in view) — and
    a line saying how to stop."""
    from rich import box
    from rich.table import Table
    from rich.text import Text

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

    def widths(columns: tuple[str, ...], rows: list) -> int:
        """A table's width at most, as ``chunks`` counts it."""
        return max(len(p) for p, _ in rows) + 4 + sum(
            max([len(line) for line in c.splitlines()] + [len(r[i]) for _, r in rows]) + 3
            for i, c in enumerate(columns))

    class Tables:
        def __rich_console__(self, console: Any, options: Any) -> Any:
            width = options.max_width
            heading = Text.from_markup(title, overflow="ellipsis")
            heading.no_wrap = True
            yield heading
            heat = heat_maps(sample, grids) if grids else None
            plan = [(1, len(rows)) for rows in sets.values()]
            if live:
                spans = [(len(rows), len(chunks(cols, rows, width)),
                          _side_by_side(widths(cols, rows), width),
                          1 + max(len(c.splitlines()) for c in cols))
                         for cols, rows in sets.items()]
                fixed = 2 + (len(console.render_lines(heat, options)) if heat else 0)
                plan = fit_rows(spans, options.size.height - fixed)
            for (columns, rows), (groups, shown) in zip(sets.items(), plan, strict=True):
                for chunk in chunks(columns, rows, width) if shown else ():
                    tables = []
                    for group in _split(rows[:shown], groups):
                        t = Table(box=box.SIMPLE_HEAD, show_edge=False)
                        t.add_column(no_wrap=True)
                        for i in chunk:
                            t.add_column(columns[i], justify="right", overflow="fold")
                        for part, cells in group:
                            t.add_row(part, *(cells[i] for i in chunk))
                        tables.append(t)
                    yield _beside(tables)
                if shown < len(rows):
                    yield _hidden([part for part, _ in rows[shown:]], not shown)
            if heat is not None:
                yield heat
            if live:
                yield Text("Ctrl-C to stop", style="dim")

    return Tables()


GAP = 3  # columns between tables side by side


def _side_by_side(table_width: int, width: int) -> int:
    """How many tables of ``table_width`` fit side by side in ``width``."""
    return max(1, (width + GAP) // (table_width + GAP))


def _split(rows: list, groups: int) -> list[list]:
    """``rows`` in ``groups`` runs of (nearly) the same length, the first ones longest."""
    size = -(-len(rows) // groups) if rows else 0
    return [rows[i:i + size] for i in range(0, len(rows), size)] if size else [rows]


def _hidden(parts: list[str], every: bool) -> Any:
    """The line that counts the rows left out and says how to pick fewer."""
    from rich.text import Text

    which = parts[0] if len(parts) == 1 else f"{parts[0]} … {parts[-1]}"
    plural = "s" if len(parts) > 1 else ""
    rows = f"{len(parts)} row{plural} hidden" if every else f"{len(parts)} more row{plural}"
    line = Text(f"{rows} ({which}): narrow with -i 'PATTERN'", style="yellow",
                overflow="ellipsis")
    line.no_wrap = True
    return line


def _beside(tables: list[Any]) -> Any:
    if len(tables) == 1:
        return tables[0]
    from rich.table import Table

    grid = Table.grid(padding=(0, GAP))
    grid.add_row(*tables)
    return grid


def fit_rows(spans: list[tuple[int, int, int, int]], height: int) -> list[tuple[int, int]]:
    """For each set of rows — ``(rows, tables its columns span, tables the width allows side
    by side, lines of a table's head)`` — the groups of its rows side by side and the rows
    shown, so that the tables take ``height`` lines at most (a table takes its rows and its
    head, a set whose rows are cut a line more): the longest tables are put side by side
    first, then the last rows of the set with the most rows (the joints) cut, all of them if
    need be, so that the sensors and GPIOs stay in view; only then the others' last rows, to
    a row per group."""
    plan = [[1, rows] for rows, _, _, _ in spans]

    def lines() -> int:
        return sum(tables * (head + -(-shown // groups)) * (shown > 0) + (shown < rows)
                   for (rows, tables, _, head), (groups, shown) in zip(spans, plan, strict=True))

    def longest(candidates: list[int]) -> int:
        return max(candidates, key=lambda i: (-(-plan[i][1] // plan[i][0]), spans[i][0]))

    while lines() > height:
        wider = [i for i, (rows, tables, room, _) in enumerate(spans)
                 if tables == 1 and plan[i][0] < min(room, rows)]
        if not wider:
            break
        plan[longest(wider)][0] += 1
    most = max(range(len(spans)), key=lambda i: spans[i][0], default=0)
    while lines() > height:  # the set with the most rows may go; the others keep a row
        cut = [i for i, (groups, shown) in enumerate(plan) if shown > (0 if i == most else groups)]
        if not cut:
            break
        i = max(cut, key=lambda i: (i == most, spans[i][0]))
        groups, shown = plan[i]
        plan[i][1] = groups * (-(-shown // groups) - 1)
    return [(groups, shown) for groups, shown in plan]


class LiveLines:
    """A stream's NDJSON frames as another process writes them (``--robot R stream``), drawn
    as the live table; a line that is not a frame goes to ``other`` as it is. The frames are
    untrusted: a value that is not a number is shown as missing."""

    def __init__(self, source: str, other: Callable[[bytes], None]) -> None:
        self.source, self.other = source, other
        self.sink: LiveSink | None = None
        self.pending = b""

    @property
    def samples(self) -> int:
        return self.sink.samples if self.sink else 0

    def feed(self, data: bytes) -> None:
        *lines, self.pending = (self.pending + data).split(b"\n")
        for line in lines:
            self._line(line)

    def close(self) -> None:
        if self.pending:
            self._line(self.pending)
            self.pending = b""
        if self.sink is not None:
            self.sink.close(None)

    def _line(self, line: bytes) -> None:
        import json

        try:
            frame = json.loads(line)
            values, t_ns = frame["values"], int(frame["t"])
        except (ValueError, TypeError, KeyError, IndexError):
            values = None
        if not isinstance(values, dict):
            self.other(line + b"\n")
            return
        numbers = {str(n): v if isinstance(v, int | float) and not isinstance(v, bool) else None
                   for n, v in values.items()}
        if self.sink is None:
            self.sink = LiveSink(list(numbers), 0.0, source=self.source)
        self.sink.frame(t_ns, numbers)


@contextlib.contextmanager
def live_lines(source: str, other: Callable[[bytes], None],
               drawn: bool = True) -> Iterator[Callable[[bytes], None]]:
    """Where another process's stream goes: drawn as the live table (:class:`LiveLines`), or
    as it is to ``other`` unless ``drawn``."""
    if not drawn:
        yield other
        return
    view = LiveLines(source, other)
    try:
        yield view.feed
    finally:
        view.close()


def write_out(data: bytes) -> None:
    """Another process's stdout, as it came (bytes), on ours."""
    buffer = getattr(sys.stdout, "buffer", None)
    if buffer is not None:
        sys.stdout.flush()
        buffer.write(data)
        buffer.flush()
    else:
        sys.stdout.write(data.decode(errors="replace"))
        sys.stdout.flush()


def write_err(text: str) -> None:
    """Text on stderr, at once."""
    sys.stderr.write(text)
    sys.stderr.flush()
