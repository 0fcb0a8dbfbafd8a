"""``deltoctl record OUT.mcap``: interface values to MCAP (ROS 2 encoding)."""

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from deltoctl.cli.context import Options, options
from deltoctl.cli.device_cmd import (
    AllowMismatch,
    DurationOpt,
    FoxgloveHostOpt,
    FoxgloveOpt,
    FoxgloveOriginOpt,
    FoxglovePortOpt,
    RateOpt,
    finish,
    foxglove_live,
    open_robot,
    start_foxglove,
)
from deltoctl.cli.output import emit_json, info, progress

if TYPE_CHECKING:
    from rich.progress import Progress


def _status(output: Path, cycles: int, link: float | None) -> str:
    """The status line people watch (the time so far is the bar's, against --duration)."""
    size = output.stat().st_size if output.exists() else 0
    state = "" if link is None else " · link up" if link else " · [red]link lost[/]"
    return f"recording {output.name}: {cycles} cycles, {size / 1e6:.1f} MB{state}"


ForceOpt = Annotated[bool, typer.Option(
    "--force", help="Overwrite the file when it exists (without: exit 2).")]
OutputArg = Annotated[Path, typer.Argument(
    help="The .mcap file to write; {time} in its name becomes the start time (UTC, "
         "20261125T211400Z), {serial} each block's device serial, or its target's "
         "address where the device reports none (joined by +).")]
GpioTypeOpt = Annotated[str, typer.Option(
    "--gpio-type", metavar="TYPE",
    help="/gpio's type: group-values (control_msgs/DynamicInterfaceGroupValues, control_msgs "
         "4.7+ on Humble, 5.3+ on Jazzy) or joint-state (control_msgs/DynamicJointState, "
         "every control_msgs).")]


def record(
    ctx: typer.Context,
    output: OutputArg,
    rate: RateOpt = 100.0,
    duration: DurationOpt = None,
    allow_model_mismatch: AllowMismatch = False,
    gpio_type: GpioTypeOpt = "group-values",
    foxglove: FoxgloveOpt = False,
    foxglove_port: FoxglovePortOpt = 8765,
    foxglove_host: FoxgloveHostOpt = "127.0.0.1",
    foxglove_origin: FoxgloveOriginOpt = None,
    force: ForceOpt = False,
) -> None:
    """Record every block's state interfaces; Ctrl-C, SIGTERM, SIGHUP or --duration end with a
    valid file. Exit 4 when a link is down at the end, 3 when one was lost and came back, 1 when
    the file could not be written to the end (disk full, file too large, removed)."""
    from deltoctl.app.latency import loop_warnings
    from deltoctl.app.recording import check_record, planned_output
    from deltoctl.app.recording import record as record_robot
    from deltoctl.core.runner import interrupted_by_signals

    opts = options(ctx)
    check_record(output, rate, duration, gpio_type)
    output = planned_output(output, force)  # an existing file is refused before anything opens
    bar = progress(opts, elapsed=True)
    show = _shown(bar, output, duration)

    # the file is created once the devices answer: an unreachable one leaves no empty file;
    # SIGTERM and SIGHUP before the loop interrupt like Ctrl-C, so the file is finished too
    try:
        with interrupted_by_signals(), \
                foxglove_live(foxglove, foxglove_host, foxglove_port, foxglove_origin) as live, \
                open_robot(opts, allow_model_mismatch) as robot:
            sinks = start_foxglove(live, robot.system, gpio_type)
            result, links = record_robot(robot.system, output, rate, duration, gpio_type,
                                         sinks, show, force)
            output = Path(result["output"])
    finally:
        if bar is not None:
            bar.stop()
    if live is not None:
        result["foxglove"] = live.summary()
    _show(opts, result, output)
    links.finish()
    # exit 3 on warnings (a servo that never answered, a link lost, a loop an adapter slowed)
    finish(robot.system, loop_warnings([m.url for m in robot.system.members], rate,
                                       result["loop"]["real_rate"]))


def _shown(bar: "Progress | None", output: Path,
           duration: float | None) -> Callable[[float, int, float | None], None] | None:
    """What updates the status line on ``bar`` (None without one)."""
    if bar is None:
        return None
    task = bar.add_task(f"recording {output.name}", total=duration)

    def show(seconds: float, cycles: int, link: float | None) -> None:
        bar.update(task, completed=seconds, description=_status(output, cycles, link))

    return show


def _show(opts: Options, result: dict[str, Any], output: Path) -> None:
    summary, counts = result["loop"], result["messages"]
    if opts.json:
        emit_json(result)
    else:
        info(f"wrote {output}: {sum(counts.values())} messages on {len(counts)} topics, "
             f"{summary['cycles']} cycles at {summary['real_rate']} Hz")
    if result["link_losses"]:
        info("the gaps are marked on /diagnostics")


def register(root: typer.Typer) -> None:
    root.command("record")(record)
