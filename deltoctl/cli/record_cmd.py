"""``deltoctl record OUT.mcap``: interface values to MCAP (ROS 2 encoding)."""

from pathlib import Path
from typing import Annotated

import typer

from deltoctl.cli.context import options
from deltoctl.cli.device_cmd import (
    AllowMismatch,
    DurationOpt,
    FoxgloveHostOpt,
    FoxgloveOpt,
    FoxgloveOriginOpt,
    FoxglovePortOpt,
    RateOpt,
    finish,
    open_robot,
)
from deltoctl.cli.output import emit_json, info, progress, warn
from deltoctl.verb_help import DESCRIPTIONS, OPTION_HELP

ForceOpt = Annotated[bool, typer.Option(
    "--force", help="Overwrite the file when it exists (without: exit 2).")]
OutputArg = Annotated[Path, typer.Argument(help=OPTION_HELP["record OUTPUT"])]
GpioTypeOpt = Annotated[str, typer.Option(
    "--gpio-type", metavar="TYPE", help=OPTION_HELP["record --gpio-type"])]


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
    from deltoctl.app.live import foxglove_live, start_foxglove
    from deltoctl.app.recording import check_record, planned_output
    from deltoctl.core.runner import interrupted_by_signals
    from deltoctl.render.progress import recording_task
    from deltoctl.render.recording import recorded_lines

    opts = options(ctx)
    check_record(output, rate, duration, gpio_type)
    output = planned_output(output, force)  # an existing file is refused before anything opens
    bar = progress(opts, elapsed=True)
    show = None if bar is None else recording_task(bar, output, duration)

    # the file is created once the devices answer: an unreachable one leaves no empty file;
    # SIGTERM and SIGHUP before the loop interrupt like Ctrl-C, so the file is finished too
    try:
        with interrupted_by_signals(), \
                foxglove_live(foxglove, foxglove_host, foxglove_port, foxglove_origin, warn,
                              info) as live, open_robot(opts, allow_model_mismatch) as robot:
            sinks = start_foxglove(live, robot, info, gpio_type)
            result, links = robot.record_to(output, rate, duration, gpio_type, sinks, show,
                                            force)
    finally:
        if bar is not None:
            bar.stop()
    if live is not None:
        result["foxglove"] = live.summary()
    if opts.json:
        emit_json(result)
    for line in recorded_lines(result)[1 if opts.json else 0:]:
        info(line)
    links.finish()
    # exit 3 on warnings (a servo that never answered, a link lost, a loop an adapter slowed)
    finish(robot, robot.loop_warnings(rate, result["loop"]))


def register(root: typer.Typer) -> None:
    root.command("record", help=DESCRIPTIONS["record"])(record)
