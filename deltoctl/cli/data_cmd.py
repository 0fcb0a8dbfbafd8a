"""``deltoctl info FILE.mcap`` and ``deltoctl plot FILE.mcap [INTERFACE-GLOB…]``: what a
recording holds, and its interfaces over time (the reading is record/reader.py's, the plot
render/plot.py's)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from deltoctl.cli.context import options
from deltoctl.cli.output import emit_json, info, show, stdout_is_terminal
from deltoctl.verb_help import DESCRIPTIONS

FileArg = Annotated[Path, typer.Argument(metavar="FILE.mcap", help="A recording (MCAP).")]


def info_verb(ctx: typer.Context, file: FileArg) -> None:
    from deltoctl.record.reader import describe
    from deltoctl.render.recording import summary

    report = describe(file)
    if not report["indexed"]:
        info(f"note: {file} has no index (its recording was stopped before it finished); "
             "it was read whole")
    if options(ctx).json:
        emit_json(report)
        return
    show(summary(report))


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
    from deltoctl.app.plot import DEFAULT_PLOT, read_plot
    from deltoctl.render.plot import png_plot, terminal_plot

    opts = options(ctx)
    globs = list(patterns or DEFAULT_PLOT)
    plotted = read_plot(file, globs, start, end)
    title = f"{file.name} — {' '.join(globs)}"
    if out is not None:
        png_plot(plotted, title, out)
        info(f"wrote {out}")
    elif not opts.json:
        typer.echo(terminal_plot(plotted, title, colour=stdout_is_terminal()))
    if opts.json:
        emit_json({"file": str(file), "out": str(out) if out else None,
                   "interfaces": plotted.stats()})


def register(root: typer.Typer) -> None:
    root.command("info", help=DESCRIPTIONS["info"])(info_verb)
    root.command("plot", help=DESCRIPTIONS["plot"])(plot)
