"""``deltoctl bench loop|dynamixel|feetech|i2c|scan``: options, then the figures of
deltoctl/benchmarks/ for people (or as JSON)."""

from collections.abc import Callable
from typing import Annotated, Any

import typer

from deltoctl.cli.context import options
from deltoctl.cli.output import emit_json, say
from deltoctl.errors import InvalidInput
from deltoctl.render.bench import (
    dynamixel_lines,
    feetech_lines,
    i2c_lines,
    loop_lines,
    scan_lines,
)
from deltoctl.verb_help import DESCRIPTIONS

app = typer.Typer(help="Benchmarks that ship with deltoctl.", no_args_is_help=True)


@app.command("loop", help=DESCRIPTIONS["bench loop"])
def bench_loop(
    ctx: typer.Context,
    rate: Annotated[float, typer.Option("--rate", help="Requested cycle rate, Hz.")] = 1000.0,
    duration: Annotated[float, typer.Option("--duration", help="Seconds per run.")] = 10.0,
    unpaced: Annotated[float, typer.Option(
        "--unpaced", help="Seconds of the unpaced run (0: skip).")] = 5.0,
    hands: Annotated[str, typer.Option(
        "--hands", help="Numbers of simulated hands to run, e.g. 1,2,4 (each hand served by "
                        "its own process).")] = "1",
    foxglove: Annotated[bool, typer.Option(
        "--foxglove", help="Also the paced run with the live view (record --foxglove) serving "
                           "every topic to a subscribed Foxglove client.")] = False,
    hands_per_process: Annotated[int | None, typer.Option(
        "--hands-per-process", help="Hands each sim serve process serves, one thread "
                                    "answering them (default: all; 1: a process per hand).")
    ] = None,
) -> None:
    from deltoctl.benchmarks.loop import loop_options, measure

    opts = options(ctx)
    counts = loop_options(rate, duration, unpaced, hands, hands_per_process)
    prof = opts.load_profile(opts.profile or "dg-5f-right")
    results = measure(prof, rate, duration, unpaced, counts, foxglove, hands_per_process)
    _report(opts.json, results, loop_lines, counts, rate)


@app.command("dynamixel", help=DESCRIPTIONS["bench dynamixel"])
def bench_dynamixel(
    ctx: typer.Context,
    servos: Annotated[int, typer.Option(help="Servos on the bus.")] = 11,
    duration: Annotated[float, typer.Option(help="Seconds per measurement.")] = 3.0,
) -> None:
    from deltoctl.benchmarks.dynamixel import measure

    if not 1 <= servos <= 252 or duration <= 0:
        raise InvalidInput("--servos must be 1-252 and --duration positive")
    _report(options(ctx).json, measure(servos, duration), dynamixel_lines, servos)


@app.command("feetech", help=DESCRIPTIONS["bench feetech"])
def bench_feetech(
    ctx: typer.Context,
    servos: Annotated[int, typer.Option(help="Servos on the bus.")] = 6,
    duration: Annotated[float, typer.Option(help="Seconds per measurement.")] = 3.0,
) -> None:
    from deltoctl.benchmarks.feetech import measure

    if not 1 <= servos <= 253 or duration <= 0:
        raise InvalidInput("--servos must be 1-253 and --duration positive")
    _report(options(ctx).json, measure(servos, duration), feetech_lines)


@app.command("i2c", help=DESCRIPTIONS["bench i2c"])
def bench_i2c(
    ctx: typer.Context,
    cycles: Annotated[int, typer.Option(help="Read cycles per client.")] = 3000,
    clock: Annotated[int, typer.Option(help="I2C clock in Hz for the wire time.")] = 400_000,
) -> None:
    from deltoctl.benchmarks.i2c import measure

    if cycles < 1 or clock <= 0:
        raise InvalidInput("--cycles and --clock must be positive")
    _report(options(ctx).json, measure(cycles, clock), i2c_lines, cycles, clock)


@app.command("scan")
def bench_scan(ctx: typer.Context,
               runs: Annotated[int, typer.Option(min=1, help="deltoctl's scans a case.")] = 3,
               sdk_runs: Annotated[int, typer.Option(min=0, help="Each SDK way's.")] = 3,
               case: Annotated[str, typer.Option(help="Cases, comma-separated.")] = "") -> None:
    """How long scan takes to find one servo, per link kind, against the SDKs' own scans."""
    from deltoctl.benchmarks.scan import case_names, measure
    _report(options(ctx).json, measure(case_names(case), runs, sdk_runs), scan_lines)


def _report(as_json: bool, results: dict, lines: Callable[..., list[str]], *args: Any) -> None:
    """A benchmark's results as JSON, or their lines for people (deltoctl.render.bench)."""
    if as_json:
        emit_json(results)
        return
    for line in lines(results, *args):
        say(line)


def register(root: typer.Typer) -> None:
    root.add_typer(app, name="bench")
