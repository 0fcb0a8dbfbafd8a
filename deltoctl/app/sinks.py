"""Cycle sinks every front end shares: the lost-link policy of a stream or a recording, and a
stream's NDJSON frames (with its tactile grids)."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from deltoctl.core.runner import Sink
from deltoctl.errors import Unreachable

if TYPE_CHECKING:
    from deltoctl.core.system import System


class LinkWatch(Sink):
    """Counts link losses per block; at the end, a block whose link is still down is
    unreachable (exit 4), and one that came back is a warning."""

    def __init__(self, system: System) -> None:
        self.system = system
        self.keys = {m.status_key: m for m in system}
        self.up = dict.fromkeys(self.keys, True)
        self.losses: dict[str, int] = {}

    def frame(self, t_ns: int, values: dict[str, float]) -> None:
        if values.get("system/connection_status") == 1.0 and all(self.up.values()):
            return
        for key, m in self.keys.items():
            up = values.get(key) == 1.0
            if self.up[key] and not up:
                self.losses[m.name] = self.losses.get(m.name, 0) + 1
            self.up[key] = up

    def finish(self) -> None:
        down = [self.keys[k].name for k, up in self.up.items() if not up]
        if down:
            raise Unreachable(f"the link to {', '.join(down)} was lost and did not come back")
        for name, n in self.losses.items():
            self.system.notes.append(f"{name}: the link was lost {n} time(s) and came back")


def _cell(value: float | None) -> float | int | None:
    """A cell as JSON: an integer reading as an integer."""
    return int(value) if isinstance(value, float) and value.is_integer() else value


class LinesSink(Sink):
    """NDJSON frames, each given to ``write``: ``{"t": ns, "values": {...}}``, and with
    tactile sensors ``"grids": {sensor: [[cell, ...], ...]}``, each grid as its rows (row 0
    first)."""

    def __init__(self, names: list[str], write: Callable[[dict[str, Any]], None]) -> None:
        self.names = names
        self.write = write
        self.samples = 0
        from deltoctl.record.cdr import stream_grids

        self.grids = stream_grids(names)

    def frame(self, t_ns: int, values: dict[str, float]) -> None:
        self.samples += 1
        line: dict[str, Any] = {"t": t_ns, "values": {n: values.get(n) for n in self.names}}
        if self.grids:
            line["grids"] = {part: [[_cell(values.get(n)) for n in row] for row in rows]
                             for part, rows in self.grids.items()}
        self.write(line)
