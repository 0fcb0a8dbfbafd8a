"""A recording's interfaces over time: the values record/reader.py reads, drawn as a terminal
plot's text (plotext) or a figure (matplotlib), and each interface's statistics; the extra
``deltoctl[plot]`` brings numpy, plotext and matplotlib."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from deltoctl.errors import DeltoctlError, InvalidInput

PLOT_EXTRA = "pip install 'deltoctl[plot]'"
PNG_POINTS = 4000  # per interface: more than a figure's pixels across
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
    need("numpy")
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


def envelope(times: Any, values: Any, points: int) -> tuple[Any, Any]:
    """At most ``points`` points that keep every spike: the min and max of each stretch."""
    import numpy as np

    if len(values) <= points:
        return times, values
    per = -(-len(values) // (points // 2))
    cut = len(values) // per * per
    shaped = values[:cut].reshape(-1, per)
    with np.errstate(all="ignore"):
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # a stretch of NaN (link lost)
            low, high = np.nanmin(shaped, axis=1), np.nanmax(shaped, axis=1)
    starts = times[:cut:per]
    middles = times[per // 2:cut:per]
    t = np.empty(2 * len(low), times.dtype)
    v = np.empty(2 * len(low))
    t[0::2], t[1::2] = starts, middles
    v[0::2], v[1::2] = low, high
    return t, v


def need(module: str) -> Any:
    """A module of the plot extra, or one clear message naming the extra."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise DeltoctlError(f"plot needs {module.split('.')[0]}, which is not installed",
                            f"{PLOT_EXTRA} (plotext for the terminal, matplotlib for --out)") \
            from None


def terminal_plot(plot: Plot, title: str, colour: bool = True) -> str:
    """The plot's text, as wide as the terminal (in braille dots); ``colour``: with its
    terminal colours."""
    import shutil

    plt = need("plotext")
    width, height = shutil.get_terminal_size((100, 30))
    plt.clear_figure()
    plt.plotsize(width, max(height - 3, 15))
    for name, (t, v) in plot.data.items():
        t, v = envelope(t, v, 2 * width)
        plt.plot(((t - plot.origin) / 1e9).tolist(), v.tolist(), label=name, marker="braille")
    plt.title(title)
    plt.xlabel("s")
    text = plt.build()
    return text if colour else plt.uncolorize(text)


def png_plot(plot: Plot, title: str, out: Path) -> None:
    """The plot as a figure in ``out`` (PNG, SVG or PDF, by its name)."""
    from deltoctl.units import utc_time

    matplotlib = need("matplotlib")
    matplotlib.use("Agg")
    pyplot = need("matplotlib.pyplot")
    fig, ax = pyplot.subplots(figsize=(12, 6), layout="constrained")
    for name, (t, v) in plot.data.items():
        t, v = envelope(t, v, PNG_POINTS)
        ax.plot((t - plot.origin) / 1e9, v, linewidth=0.8, label=name)
    ax.set_title(title)
    ax.set_xlabel(f"s from {utc_time(plot.origin)}")
    ax.grid(True, alpha=0.3)
    if len(plot.data) <= 24:
        ax.legend(fontsize="small", loc="upper left", bbox_to_anchor=(1.0, 1.0))
    try:
        fig.savefig(out, dpi=120)
    except (OSError, ValueError) as exc:
        raise InvalidInput(f"cannot write {out}: {exc}") from None
    finally:
        pyplot.close(fig)


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
