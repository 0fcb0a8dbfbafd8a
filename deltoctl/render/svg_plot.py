"""A line chart as inline SVG, drawn with the standard library: one path per series (a gap
where a value is not finite), axes with round ticks and their labels, the unit, and a legend.
The commissioning report draws a recording's figures with it, so every install has them."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from xml.sax.saxutils import escape, quoteattr

WIDTH, HEIGHT = 640, 260
LEFT, RIGHT, TOP, BOTTOM = 64, 12, 12, 40  # px of margin around the plot area
LEGEND_ROW = 16  # px per legend line, below the plot
TICKS = 6  # about this many ticks per axis
Scale = Callable[[float], float]  # a value → its pixel


def colour(i: int) -> str:
    """The ``i``-th series' colour: hues far apart."""
    return f"hsl({(i * 47) % 360}, 65%, 40%)"


def nice_ticks(low: float, high: float, count: int = TICKS) -> list[float]:
    """Round tick values (1, 2 or 5 times a power of ten apart) covering low … high."""
    if not (math.isfinite(low) and math.isfinite(high)):
        return []
    if high <= low:
        return [low]
    raw = (high - low) / max(count - 1, 1)
    power = 10.0 ** math.floor(math.log10(raw))
    step = next(m * power for m in (1, 2, 5, 10) if m * power >= raw)
    first = math.ceil(low / step - 1e-9)
    ticks = []
    k = first
    while k * step <= high + step * 1e-9:
        ticks.append(0.0 if abs(k * step) < step * 1e-9 else k * step)
        k += 1
    return ticks


def _label(value: float) -> str:
    return f"{value:.4g}"


def _finite(values: Sequence[float | None]) -> list[float]:
    return [v for v in values if v is not None and math.isfinite(v)]


def _range(series: Sequence[tuple[str, Sequence[float], Sequence[float | None]]]
           ) -> tuple[float, float, float, float] | None:
    """(t0, t1, low, high) of the finite points, widened where a span is empty."""
    ts = [t for _, times, values in series for t, v in zip(times, values)
          if v is not None and math.isfinite(v) and math.isfinite(t)]
    vs = [v for _, _, values in series for v in _finite(values)]
    if not ts or not vs:
        return None
    t0, t1, low, high = min(ts), max(ts), min(vs), max(vs)
    if t1 <= t0:
        t1 = t0 + 1.0
    if high <= low:
        pad = abs(low) * 0.05 or 1.0
        low, high = low - pad, high + pad
    return t0, t1, low, high


def _path(times: Sequence[float], values: Sequence[float | None], x: Scale, y: Scale) -> str:
    """Path data of one series: a new subpath after each value that is not finite."""
    parts: list[str] = []
    pen_down = False
    for t, v in zip(times, values):
        if v is None or not (math.isfinite(v) and math.isfinite(t)):
            pen_down = False
            continue
        parts.append(f"{'L' if pen_down else 'M'}{x(t):.1f} {y(v):.1f}")
        pen_down = True
    return " ".join(parts)


def figure(title: str, unit: str, series: Sequence[tuple[str, Sequence[float],
                                                          Sequence[float | None]]],
           time_unit: str = "s") -> str:
    """An ``<svg>`` element: each series (name, times, values; None or NaN for a gap) as a
    path, the time axis below, the value axis in ``unit`` at the left, the legend under
    them. Text is escaped; with no finite value, the axes frame says so."""
    height = HEIGHT + LEGEND_ROW * len(series)
    plot_w, plot_h = WIDTH - LEFT - RIGHT, HEIGHT - TOP - BOTTOM
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{height}" '
           f'viewBox="0 0 {WIDTH} {height}" role="img" font-family="sans-serif" '
           f'font-size="11">', f"<title>{escape(title)}</title>",
           f'<rect x="{LEFT}" y="{TOP}" width="{plot_w}" height="{plot_h}" fill="none" '
           'stroke="#999"/>']
    span = _range(series)
    if span is None:
        out.append(f'<text x="{LEFT + plot_w / 2:.1f}" y="{TOP + plot_h / 2:.1f}" '
                   'text-anchor="middle" fill="#666">no finite values recorded</text>')
    else:
        t0, t1, low, high = span

        def x(t: float) -> float:
            return LEFT + (t - t0) / (t1 - t0) * plot_w

        def y(v: float) -> float:
            return TOP + plot_h - (v - low) / (high - low) * plot_h

        out += _axes(t0, t1, low, high, x, y)
        for i, (name, times, values) in enumerate(series):
            d = _path(times, values, x, y)
            out.append(f'<path class="series" data-name={quoteattr(name)} fill="none" '
                       f'stroke="{colour(i)}" stroke-width="1.2" d="{d}">'
                       f"<title>{escape(name)}</title></path>")
    out += _axis_titles(unit, time_unit, plot_w, plot_h)
    out += _legend(series)
    out.append("</svg>")
    return "\n".join(out)


def _axes(t0: float, t1: float, low: float, high: float, x: Scale, y: Scale) -> list[str]:
    """Tick marks, grid lines and tick labels of both axes."""
    out: list[str] = []
    bottom = HEIGHT - BOTTOM
    for t in nice_ticks(t0, t1):
        px = x(t)
        out.append(f'<line x1="{px:.1f}" y1="{bottom}" x2="{px:.1f}" y2="{bottom + 4}" '
                   'stroke="#555"/>')
        out.append(f'<text x="{px:.1f}" y="{bottom + 15}" text-anchor="middle">'
                   f"{escape(_label(t))}</text>")
    for v in nice_ticks(low, high):
        py = y(v)
        out.append(f'<line x1="{LEFT}" y1="{py:.1f}" x2="{WIDTH - RIGHT}" y2="{py:.1f}" '
                   'stroke="#e4e4e4"/>')
        out.append(f'<text x="{LEFT - 6}" y="{py + 4:.1f}" text-anchor="end">'
                   f"{escape(_label(v))}</text>")
    return out


def _axis_titles(unit: str, time_unit: str, plot_w: int, plot_h: int) -> list[str]:
    mid_y = TOP + plot_h / 2
    return [f'<text x="{LEFT + plot_w / 2:.1f}" y="{HEIGHT - 6}" text-anchor="middle">'
            f"time [{escape(time_unit)}]</text>",
            f'<text x="14" y="{mid_y:.1f}" text-anchor="middle" '
            f'transform="rotate(-90 14 {mid_y:.1f})">{escape(unit or "value")}</text>']


def _legend(series: Sequence[tuple[str, Sequence[float], Sequence[float | None]]]
            ) -> list[str]:
    out = []
    for i, (name, _, values) in enumerate(series):
        row = HEIGHT + LEGEND_ROW * i + 4
        empty = "" if _finite(values) else " (no finite values)"
        out.append(f'<g class="legend"><rect x="{LEFT}" y="{row}" width="12" height="8" '
                   f'fill="{colour(i)}"/><text x="{LEFT + 18}" y="{row + 8}">'
                   f"{escape(name + empty)}</text></g>")
    return out
