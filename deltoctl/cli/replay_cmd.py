"""``deltoctl replay FILE.mcap``: play a recording's commands back at their recorded timing,
on the profile's simulators unless --device (then confirmed as any motion); Ctrl-C, SIGTERM or
SIGHUP stop every block. What is checked, before and while it moves: deltoctl.app.replay."""

from pathlib import Path
from typing import Annotated, Any

import typer

from deltoctl.app.replay import MAX_DEVIATION
from deltoctl.cli.confirm import confirm
from deltoctl.cli.context import Options, options
from deltoctl.cli.device_cmd import AllowMismatch, finish, open_robot
from deltoctl.cli.output import emit_json, info, progress, show, warn
from deltoctl.errors import WARNINGS
from deltoctl.render.progress import advancing
from deltoctl.verb_help import DESCRIPTIONS


def register(app: typer.Typer) -> None:
    app.command("replay", help=DESCRIPTIONS["replay"])(replay)


RecordingArg = Annotated[Path, typer.Argument(
    metavar="FILE.mcap", help="A recording with commands (jog --record).")]
DeviceOpt = Annotated[bool, typer.Option(
    "--device", help="Replay on the devices -t/--target names (or, with --sim, on "
                     "simulators) under the limits of -p PROFILE or of the catalog's "
                     "profile, never the recording's; asks for confirmation unless --yes.")]
ToleranceOpt = Annotated[str | None, typer.Option(
    "--tolerance", metavar="X", help="The largest difference allowed between recorded "
                                     "and replayed position: 1deg, 2mm, or a bare number "
                                     "in rad (revolute) / m (prismatic); beyond it, exit 3.")]
MaxDeviationOpt = Annotated[str | None, typer.Option(
    "--max-deviation", metavar="X",
    help="While replaying, a joint further than this from its recorded position (5deg, "
         "10mm, or a bare number in rad (revolute) / m (prismatic)) stops every block, exit 5 "
         f"(default {MAX_DEVIATION:g}).")]


def replay(
    ctx: typer.Context,
    recording: RecordingArg,
    device: DeviceOpt = False,
    tolerance: ToleranceOpt = None,
    max_deviation: MaxDeviationOpt = None,
    allow_model_mismatch: AllowMismatch = False,
) -> None:
    import copy

    from deltoctl.app.replay import Deviated, plan_replay, replay_limits, where_to_replay
    from deltoctl.units import nonnegative

    opts = options(ctx)
    nonnegative(tolerance, "--tolerance")
    nonnegative(max_deviation, "--max-deviation")
    named = opts.load_profile() if opts.profile else None
    plan = plan_replay(recording, named, device, opts.hardware)
    limit, deviation = replay_limits(plan, tolerance, max_deviation)
    run_opts = copy.copy(opts)  # only the blocks it commands, on the simulators unless --device
    run_opts.hardware, run_opts.sim = where_to_replay(plan, device, opts.hardware, opts.target,
                                                      opts.sim)
    for note in plan.notes:
        warn(note)
    confirm(ctx, plan.describe(recording, opts.target or ["the simulators"]))
    bar = progress(opts)
    try:
        with open_robot(run_opts, allow_model_mismatch, plan.profile) as robot:
            report = robot.replay(recording, deviation, limit, plan, run_opts.sim,
                                  device and not opts.sim,
                                  advancing(bar, f"replay {recording.name}"), info)
    except Deviated as stopped:
        if opts.json and stopped.report is not None:
            emit_json(stopped.report)  # the replay until it was stopped
        raise
    finally:
        if bar is not None:
            bar.stop()
    _show(opts, report, robot.joint_types(), tolerance)
    finish(robot)
    if report["exceeded"] or plan.notes:  # the notes: shown before the replay
        raise typer.Exit(WARNINGS)


def _show(opts: Options, report: dict[str, Any], joint_types: dict[str, str],
          tolerance: str | None) -> None:
    """The report, and the joints beyond --tolerance as a warning."""
    from deltoctl.render.replay import replay_parts

    if opts.json:
        emit_json(report)
    else:
        show(replay_parts(report, joint_types, tolerance))
    if report["exceeded"]:
        warn(f"{', '.join(report['exceeded'])}: replayed more than {tolerance} from the "
             "recording")
