"""``deltoctl replay FILE.mcap``: play a recording's commands back at their recorded timing.

On the profile's simulators unless --device says otherwise (then confirmed as any motion, on
the device -t names, under the limits of -p or of the catalog's profile: a recording is
untrusted, its profile never relaxes a limit and its bus URLs never choose a device);
every command is checked against the profile's limits before anything moves (exit 5); a safe
move to the recorded start pose first; Ctrl-C, SIGTERM or SIGHUP stop every block, and so
does a joint outside its limits or beyond --max-deviation from the recording (exit 5). The
report: per joint, RMS and max of replayed against recorded position; --tolerance makes a
larger difference exit 3.
"""

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from deltoctl.cli.context import Options, options
from deltoctl.cli.device_cmd import AllowMismatch, finish, open_robot
from deltoctl.cli.output import advancing, emit_json, info, progress, say, table, warn
from deltoctl.errors import WARNINGS

if TYPE_CHECKING:
    from deltoctl.app.replay import Deviated, ReplayPlan, ReplayResult
    from deltoctl.app.robot import Robot
    from deltoctl.profile.model import Profile

MAX_DEVIATION = 0.2  # rad or m: a replayed joint further than this from its recording stops


def register(app: typer.Typer) -> None:
    app.command("replay")(replay)


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
    """Play a recording's commands back at their recorded timing, then report per joint the
    difference between recorded and replayed position (RMS, max).

    The profile is the recording's own (its metadata), or -p PROFILE. Every command is
    checked against the profile's limits and jog step before anything moves; then the
    joints go to the recorded start pose; then the commands follow, and a joint that leaves
    its limits or strays beyond --max-deviation from the recording stops every block
    (exit 5). Runs on the profile's simulators unless --device (with --yes, or confirmed on
    a terminal): then on the device -t names, under the limits of -p PROFILE or of the
    catalog's profile of the recorded name; a recorded profile looser than that is refused
    (exit 5)."""
    import copy

    from deltoctl.app.replay import plan_replay, replay_report, where_to_replay
    from deltoctl.cli.motion_cmd import confirm_motion
    from deltoctl.units import nonnegative

    opts = options(ctx)
    nonnegative(tolerance, "--tolerance")
    nonnegative(max_deviation, "--max-deviation")
    named = opts.load_profile() if opts.profile else None
    plan = plan_replay(recording, named, device, opts.hardware)
    limit = _per_joint(plan, tolerance, "--tolerance")
    deviation = _per_joint(plan, max_deviation, "--max-deviation")
    deviation = MAX_DEVIATION if deviation is None else deviation
    run_opts = copy.copy(opts)  # only the blocks it commands, on the simulators unless --device
    run_opts.hardware, run_opts.sim = where_to_replay(plan, device, opts.hardware, opts.target,
                                                      opts.sim)
    for note in plan.notes:
        warn(note)
    on_device = device and not opts.sim
    if on_device:
        confirm_motion(opts, plan.describe(recording, opts.target))
    robot, result, stopped = _run(opts, run_opts, allow_model_mismatch, plan, recording,
                                  deviation)
    report = replay_report(recording, robot.system, plan.recorded, result, limit, on_device,
                           deviation, stopped)
    if stopped is not None:
        if opts.json:
            emit_json(report)  # the replay until it was stopped
        raise stopped
    _show(opts, report, plan.profile, tolerance)
    if report["exceeded"]:
        warn(f"{', '.join(report['exceeded'])}: replayed more than {tolerance} from the "
             "recording")
    finish(robot.system)
    if report["exceeded"] or plan.notes:  # the notes: shown before the replay
        raise typer.Exit(WARNINGS)


def _per_joint(plan: "ReplayPlan", text: str | None, what: str) -> float | None:
    """A tolerance in SI, its unit that of every replayed joint (exit 2 otherwise)."""
    from deltoctl.app.motion import joints_quantity

    return joints_quantity(plan.profile, plan.recorded.joints, text, what)


def _run(opts: Options, run_opts: Options, allow_model_mismatch: bool, plan: "ReplayPlan",
         recording: Path, deviation: float) -> "tuple[Robot, ReplayResult, Deviated | None]":
    """The replay with a progress bar: (the robot, its result, what stopped it or None)."""
    from deltoctl.app.replay import run_replay

    bar = progress(opts)
    try:
        with open_robot(run_opts, allow_model_mismatch, plan.profile) as robot:
            result, stopped = run_replay(robot.system, plan.recorded, deviation, run_opts.sim,
                                         advancing(bar, f"replay {recording.name}"), info)
    finally:
        if bar is not None:
            bar.stop()
    return robot, result, stopped


def _show(opts: Options, report: dict[str, Any], profile: "Profile",
          tolerance: str | None) -> None:
    """The report; each joint's differences in the unit of --tolerance (else degrees or
    millimetres)."""
    from deltoctl.units import joint_dimension, parse_unit, shown

    if opts.json:
        emit_json(report)
        return
    say(f"replayed {report['commands']} commands of {Path(report['file']).name} on the "
        f"{report['on']} in {report['seconds']:.2f} s (recorded: "
        f"{report['recorded_seconds']:.2f} s; latest command {report['late_max_ms']:.1f} ms "
        "late)")
    unit = parse_unit(tolerance).unit if tolerance else ""
    rows = []
    for j, d in report["joints"].items():
        comp = profile.component(j)
        dim = joint_dimension(comp.joint_type) if comp is not None else None
        rows.append([j, d["block"], d["samples"], shown(d["rms"], dim, unit),
                     shown(d["max"], dim, unit)])
    table("recorded vs replayed position", ["joint", "block", "samples", "RMS", "max"], rows)
