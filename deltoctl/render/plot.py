"""A recording's interfaces drawn: a terminal plot's text (plotext) or a figure (matplotlib),
each series thinned to the points a drawing can show (deltoctl.app.plot reads them)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from deltoctl.errors import InvalidInput, need_plot

if TYPE_CHECKING:
    from deltoctl.app.plot import Plot

PNG_POINTS = 4000  # per interface: more than a figure's pixels across


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


def terminal_plot(plot: Plot, title: str, colour: bool = True) -> str:
    """The plot's text, as wide as the terminal (in braille dots); ``colour``: with its
    terminal colours."""
    import shutil

    plt = need_plot("plotext")
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

    matplotlib = need_plot("matplotlib")
    matplotlib.use("Agg")
    pyplot = need_plot("matplotlib.pyplot")
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
