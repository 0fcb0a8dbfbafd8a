"""A stream for people: the live table on a terminal (a table per set of interfaces, the
links' states, each tactile grid as a heat map), redrawn as the values come."""

from __future__ import annotations

import time
from typing import Any

from deltoctl.core.runner import Sink
from deltoctl.record.cdr import stream_grids

LIVE_PERIOD = 0.05  # s between redraws of the live table: people read at most 20 a second


class LiveSink(Sink):
    """The live table on a terminal, redrawn at most 20 times a second."""

    def __init__(self, names: list[str], rate: float) -> None:
        from rich.live import Live

        self.names = names
        self.rate = rate
        self.samples = 0
        self.shown = 0.0
        self.live = Live(auto_refresh=False)
        self.live.start()

    def frame(self, t_ns: int, values: dict[str, float]) -> None:
        self.samples += 1
        if time.monotonic() - self.shown >= LIVE_PERIOD:
            sample = {n: values.get(n) for n in self.names}
            self.live.update(live_tables(sample, f"{self.samples} samples at {self.rate:g} Hz"),
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


def live_tables(sample: dict[str, Any], title: str) -> Any:
    """One row per part and a column per interface: a table for each set of interfaces
    (joints, F/T sensors, GPIO), so a hand of 20 joints fits on a screen; the links' states in
    the title; each tactile grid as a heat map below. Laid out for the console it is drawn
    on: columns that do not fit its width go to a table of their own below (the part's name
    repeated), so no value is ever cut."""
    from rich import box
    from rich.table import Table

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
        sets.setdefault(tuple(values), []).append(
            (part, ["—" if v is None else f"{v:.4g}" for v in values.values()]))

    def chunks(columns: tuple[str, ...], rows: list, width: int) -> list[list[int]]:
        """Column indexes per table: as many as fit ``width`` (a column costs its text + 3,
        a table 1 more)."""
        start = used = max(len(p) for p, _ in rows) + 4
        out: list[list[int]] = [[]]
        for i, column in enumerate(columns):
            cost = max([len(column)] + [len(r[i]) for _, r in rows]) + 3
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
