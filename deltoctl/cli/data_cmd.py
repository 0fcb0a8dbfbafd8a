"""``deltoctl info FILE.mcap`` and ``deltoctl plot FILE.mcap [INTERFACE-GLOB…]``: what a
recording holds, and its interfaces over time (the reading is record/reader.py's)."""

from __future__ import annotations

from datetime import datetime, timezone
from pathlib import Path
from typing import Annotated, Any

import typer

from deltoctl.cli.context import options
from deltoctl.cli.output import emit_json, info, say, stdout_is_terminal, table
from deltoctl.errors import DeltoctlError, InvalidInput

FileArg = Annotated[Path, typer.Argument(metavar="FILE.mcap", help="A recording (MCAP).")]
PLOT_EXTRA = "pip install 'deltoctl[plot]'"
PNG_POINTS = 4000  # per interface: more than a figure's pixels across
DEFAULT_PLOT = ["*/position"]


def _time(t_ns: int | None) -> str:
    if t_ns is None:
        return "-"
    stamp = datetime.fromtimestamp(t_ns / 1e9, timezone.utc)
    return stamp.isoformat(timespec="milliseconds").replace("+00:00", "Z")


def _size(n: int) -> str:
    for unit in ("B", "kB", "MB", "GB"):
        if n < 1000 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000
    return str(n)


def _identity_text(identity: Any) -> str:
    """The scalar facts of an identify result, one line."""
    if not isinstance(identity, dict):
        return "" if identity is None else str(identity)
    return "; ".join(f"{k}={v}" for k, v in identity.items()
                     if isinstance(v, (str, int, float, bool)))


def info_verb(ctx: typer.Context, file: FileArg) -> None:
    """What a recording holds: its times, blocks and their identities, topics with counts and
    rates, link losses and gaps with their times, the loop's lateness and jitter. Reads the
    file's summary and index, not every message."""
    from deltoctl.record.reader import describe

    report = describe(file)
    if not report["indexed"]:
        info(f"note: {file} has no index (its recording was stopped before it finished); "
             "it was read whole")
    if options(ctx).json:
        emit_json(report)
        return
    _show(report)


def _show(r: dict[str, Any]) -> None:
    say(f"{r['file']}: {r['duration_s']:.3f} s from {_time(r['start_ns'])} to "
        f"{_time(r['end_ns'])}, {r['messages']} messages, {_size(r['bytes'])} "
        f"({', '.join(r['compression']) or 'no chunks'}, {r['chunks']} chunks)")
    profile = r["profile"] or {}
    facts = [f"profile {profile.get('name') or '?'}"]
    if profile.get("model"):
        facts.append(f"model {profile['model']}")
    if r["deltoctl"]:
        facts.append(f"recorded by deltoctl {r['deltoctl']}")
    if r["rosbag2"]:
        facts.append(f"rosbag2 metadata v{r['rosbag2']['version']}")
    say(", ".join(facts))
    if r["blocks"]:
        table("blocks", ["block", "family", "target", "identity"],
              [[b["name"], b.get("family"), b.get("target"), _identity_text(b.get("identity"))]
               for b in r["blocks"]])
    table("topics", ["topic", "type", "messages", "rate (Hz)"],
          [[t["topic"], t["type"], t["messages"],
            "-" if t["rate_hz"] is None else f"{t['rate_hz']:.2f}"] for t in r["topics"]])
    if r["link_losses"]:
        table("link losses", ["lost", "restored", "seconds", "blocks down"],
              [[_time(x["lost_ns"]), _time(x["restored_ns"]) if x["restored_ns"] else
                "not restored", f"{x['seconds']:.3f}", ", ".join(x["blocks"])]
               for x in r["link_losses"]])
    else:
        say("link losses: none")
    if r["gaps"]:
        table("gaps (no cycle)", ["from", "to", "seconds"],
              [[_time(g["start_ns"]), _time(g["end_ns"]), f"{g['seconds']:.3f}"]
               for g in r["gaps"]])
    else:
        say("gaps: none")
    loop = r["loop"]
    if loop:
        say(f"loop: {loop.get('real_rate')} Hz of {loop.get('requested_rate')} asked, "
            f"{loop.get('cycles')} cycles, {loop.get('deadline_misses')} deadline misses; "
            f"lateness p50 {loop.get('lateness_p50_ms')} ms, p99 {loop.get('lateness_p99_ms')} "
            f"ms; period jitter p50 {loop.get('period_jitter_p50_ms')} ms, p99 "
            f"{loop.get('period_jitter_p99_ms')} ms")
    for name, bus in r["buses"].items():
        say(f"bus loop {name}: " + ", ".join(f"{k} {v}" for k, v in bus.items()))


# -- plot ----------------------------------------------------------------------------------------

def _envelope(times: Any, values: Any, points: int) -> tuple[Any, Any]:
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


def _need(module: str) -> Any:
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise DeltoctlError(f"plot needs {module.split('.')[0]}, which is not installed",
                            f"{PLOT_EXTRA} (plotext for the terminal, matplotlib for --out)") \
            from None


def _terminal_plot(data: dict[str, tuple[Any, Any]], origin: int, title: str) -> None:
    import shutil

    plt = _need("plotext")
    width, height = shutil.get_terminal_size((100, 30))
    plt.clear_figure()
    plt.plotsize(width, max(height - 3, 15))
    for name, (t, v) in data.items():
        t, v = _envelope(t, v, 2 * width)
        plt.plot(((t - origin) / 1e9).tolist(), v.tolist(), label=name, marker="braille")
    plt.title(title)
    plt.xlabel("s")
    text = plt.build()
    typer.echo(text if stdout_is_terminal() else plt.uncolorize(text))


def _png_plot(data: dict[str, tuple[Any, Any]], origin: int, title: str, out: Path) -> None:
    matplotlib = _need("matplotlib")
    matplotlib.use("Agg")
    pyplot = _need("matplotlib.pyplot")
    fig, ax = pyplot.subplots(figsize=(12, 6), layout="constrained")
    for name, (t, v) in data.items():
        t, v = _envelope(t, v, PNG_POINTS)
        ax.plot((t - origin) / 1e9, v, linewidth=0.8, label=name)
    ax.set_title(title)
    ax.set_xlabel(f"s from {_time(origin)}")
    ax.grid(True, alpha=0.3)
    if len(data) <= 24:
        ax.legend(fontsize="small", loc="upper left", bbox_to_anchor=(1.0, 1.0))
    try:
        fig.savefig(out, dpi=120)
    except (OSError, ValueError) as exc:
        raise InvalidInput(f"cannot write {out}: {exc}") from None
    finally:
        pyplot.close(fig)


def _stats(name: str, topic: str, t: Any, v: Any) -> dict[str, Any]:
    import numpy as np

    real = v[~np.isnan(v)]
    return {"interface": name, "topic": topic, "count": len(v),
            "first_ns": int(t[0]) if len(t) else None, "last_ns": int(t[-1]) if len(t) else None,
            "min": float(real.min()) if len(real) else None,
            "max": float(real.max()) if len(real) else None,
            "mean": float(real.mean()) if len(real) else None,
            "missing": int(len(v) - len(real))}


def plot(
    ctx: typer.Context,
    file: FileArg,
    patterns: Annotated[list[str] | None, typer.Argument(
        metavar="[INTERFACE-GLOB]...",
        help="Interfaces to draw, e.g. 'rj_dg_1_*/position' (default: */position).")] = None,
    out: Annotated[Path | None, typer.Option(
        "--out", "-o", metavar="FILE.png",
        help="Write a figure (PNG, SVG or PDF, by its name) instead of drawing in the "
             "terminal.")] = None,
    start: Annotated[float | None, typer.Option(
        "--start", metavar="S", help="From S seconds after the recording's start.")] = None,
    end: Annotated[float | None, typer.Option(
        "--end", metavar="S", help="Up to S seconds after the recording's start.")] = None,
) -> None:
    """Interfaces over time: in the terminal (plotext), or as a figure with --out
    (matplotlib). Reads only the topics that carry them. Needs pip install 'deltoctl[plot]'."""
    _need("numpy")
    from deltoctl.record.reader import (
        interfaces,
        keep_freed_memory,
        read_recording,
        select,
        series,
    )

    opts = options(ctx)
    globs = list(patterns or DEFAULT_PLOT)
    rec = read_recording(file, keep=None)
    available = interfaces(rec)
    wanted = select(available, globs)
    if not wanted:
        raise InvalidInput(f"no interface in {file} matches {' '.join(globs)}",
                           _nearest(globs[0], available))
    origin = rec.start_ns
    window = [None if s is None else origin + int(s * 1e9) for s in (start, end)]
    keep_freed_memory()
    data = series(rec, wanted, *window)
    title = f"{file.name} — {' '.join(globs)}"
    if out is not None:
        _png_plot(data, origin, title, out)
        info(f"wrote {out}")
    elif not opts.json:
        _terminal_plot(data, origin, title)
    if opts.json:
        topic = {cid: ch.topic for cid, ch in rec.channels.items()}
        emit_json({"file": str(file), "out": str(out) if out else None,
                   "interfaces": [_stats(n, topic[available[n]], *data[n]) for n in wanted]})


def _nearest(typed: str, available: dict[str, int]) -> str:
    from deltoctl.suggest import close_matches

    close = close_matches(typed, available)
    some = close or list(available)[:6]
    return ("interfaces here: " if not close else "did you mean: ") + ", ".join(some) + \
        (" …" if not close and len(available) > 6 else "")


def register(root: typer.Typer) -> None:
    root.command("info")(info_verb)
    root.command("plot")(plot)
