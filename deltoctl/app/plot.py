"""A recording's interfaces over time: the series record/reader.py reads (drawn by
render/plot.py), and each interface's statistics; the extra ``deltoctl[plot]`` brings numpy,
plotext and matplotlib."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from deltoctl.errors import InvalidInput, need_plot

DEFAULT_PLOT = ["*/position"]


@dataclasses.dataclass
class Plot:
    """The series of a recording's interfaces: time (ns) and values of each, the recording's
    start, and the topic each interface was read from (in the recording's order)."""

    data: dict[str, tuple[Any, Any]]
    origin: int
    topics: dict[str, str]

    def stats(self) -> list[dict[str, Any]]:
        """Each interface's count, times, min, max, mean and missing values."""
        return [stats(name, topic, *self.data[name]) for name, topic in self.topics.items()]


def read_plot(file: Path, globs: list[str], start: float | None = None,
              end: float | None = None) -> Plot:
    """The interfaces of ``file`` that ``globs`` match, from ``start`` to ``end`` seconds
    after the recording's start (reads only the topics that carry them); none matching is
    invalid input naming the nearest."""
    need_plot("numpy")
    from deltoctl.record.reader import (
        interfaces,
        keep_freed_memory,
        read_recording,
        select,
        series,
    )

    rec = read_recording(file, keep=None)
    available = interfaces(rec)
    wanted = select(available, globs)
    if not wanted:
        raise InvalidInput(f"no interface in {file} matches {' '.join(globs)}",
                           nearest(globs[0], available))
    origin = rec.start_ns
    window = [None if s is None else origin + int(s * 1e9) for s in (start, end)]
    keep_freed_memory()
    data = series(rec, wanted, *window)
    topic = {cid: ch.topic for cid, ch in rec.channels.items()}
    return Plot(data, origin, {n: topic[available[n]] for n in wanted})


def nearest(typed: str, available: dict[str, int]) -> str:
    """The hint for an interface glob that matches nothing: the closest names, else some."""
    from deltoctl.suggest import close_matches

    close = close_matches(typed, available)
    some = close or list(available)[:6]
    return ("interfaces here: " if not close else "did you mean: ") + ", ".join(some) + \
        (" …" if not close and len(available) > 6 else "")



def stats(name: str, topic: str, t: Any, v: Any) -> dict[str, Any]:
    """One interface's statistics (NaN, a link lost, counts as missing)."""
    import numpy as np

    real = v[~np.isnan(v)]
    return {"interface": name, "topic": topic, "count": len(v),
            "first_ns": int(t[0]) if len(t) else None, "last_ns": int(t[-1]) if len(t) else None,
            "min": float(real.min()) if len(real) else None,
            "max": float(real.max()) if len(real) else None,
            "mean": float(real.mean()) if len(real) else None,
            "missing": int(len(v) - len(real))}
