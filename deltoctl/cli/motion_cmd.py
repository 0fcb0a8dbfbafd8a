"""Motion verbs: home and jog. Confirmed as the verb table says (deltoctl.cli.confirm);
refused (exit 5) outside limits or without confirmation; duty 0 on the way out, Ctrl-C
included."""

import contextlib
from pathlib import Path
from typing import Annotated, Any

import typer

from deltoctl.cli.completions import complete_part as complete_joint
from deltoctl.cli.confirm import confirm
from deltoctl.cli.context import Options, options
from deltoctl.cli.device_cmd import AllowMismatch, finish, open_robot
from deltoctl.cli.output import emit_json, info, progress, say
from deltoctl.render.progress import advancing
from deltoctl.verb_help import DESCRIPTIONS, OPTION_HELP

VelocityOpt = Annotated[str | None, typer.Option(
    "--velocity", help="Setpoint speed: 20deg/s, 10mm/s, or a bare number in rad/s "
                       "(revolute) / m/s (prismatic).")]


def register(app: typer.Typer) -> None:
    app.command("home", help=DESCRIPTIONS["home"])(home)
    # negative deltas (`jog J -5deg`) are arguments, not unknown options
    app.command("jog", help=DESCRIPTIONS["jog"],
                context_settings={"ignore_unknown_options": True})(jog)


def _said(label: str, report: dict[str, Any]) -> None:
    say(f"{label}: {'settled' if report['settled'] else 'did not settle'} in "
        f"{report['seconds']:.2f} s")


def home(
    ctx: typer.Context,
    velocity: VelocityOpt = None,
    joint: Annotated[list[str] | None, typer.Option(
        "--joint", "-j", autocompletion=complete_joint,
        help="Home only this joint (repeatable; default: all).")] = None,
    force: Annotated[bool, typer.Option(
        help="Home again joints that are homed already (homing joints only).")] = False,
    allow_model_mismatch: AllowMismatch = False,
) -> None:
    from deltoctl.app.motion import fail_unsettled, joint_speed, plan_home
    from deltoctl.render.progress import HomingBars

    opts = options(ctx)
    profile = opts.load_profile()
    plan = plan_home(profile, opts.hardware, joint or [])
    speed = joint_speed(profile, list(plan.targets), velocity)
    confirm(ctx, plan.describe())
    bars = HomingBars(lambda transient: progress(opts, transient), plan.routine,
                      None if opts.json else info)
    with open_robot(opts, allow_model_mismatch, profile) as robot:
        try:
            report = robot.home(force=force, velocity=speed, plan=plan, progress=bars.move,
                                show=bars.show)
        finally:
            bars.stop()
    if opts.json:
        emit_json(report)
    elif plan.targets:
        _said("home", report)
    if plan.targets:
        fail_unsettled(report, profile)
    finish(robot)


JogRecordOpt = Annotated[Path | None, typer.Option(
    "--record", metavar="FILE.mcap", help=OPTION_HELP["jog --record"])]
JogForceOpt = Annotated[bool, typer.Option(
    "--force", help="Overwrite --record's file when it exists (without: exit 2).")]


def jog(
    ctx: typer.Context,
    joint: Annotated[str, typer.Argument(autocompletion=complete_joint,
                                         help="The joint to move.")],
    delta: Annotated[str | None, typer.Argument(
        help="Relative move: 5deg, 2mm, or a bare number in rad (revolute) / m "
             "(prismatic).")] = None,
    more: Annotated[list[str] | None, typer.Argument(
        metavar="[JOINT DELTA]...", show_default=False,
        help="More joints to move at the same time, each with its delta.")] = None,
    to: Annotated[str | None, typer.Option(
        "--to", help="Absolute target instead: 30deg, 12mm, or a bare number in rad / m.")]
        = None,
    velocity: VelocityOpt = None,
    record: JogRecordOpt = None,
    allow_model_mismatch: AllowMismatch = False,
    force: JogForceOpt = False,
) -> None:
    from deltoctl.app.motion import fail_unsettled, jog_pairs, joint_speed
    from deltoctl.app.recording import planned_output

    opts = options(ctx)
    profile = opts.load_profile()
    pairs = jog_pairs(profile, joint, delta, more, to)
    speed = joint_speed(profile, [name for name, _ in pairs], velocity)

    # a file that cannot be written, or exists, is refused (exit 2) before anything opens
    record = planned_output(record, force) if record else None
    with open_robot(opts, allow_model_mismatch, profile) as robot, \
            robot.new_recording(record, force) if record else \
            contextlib.nullcontext() as record:
        # e.g. not homed, or outside the System's envelope: before anyone is asked
        targets, moves = robot.plan_jog(pairs, to, speed)
        confirm(ctx, "jog " + "; ".join(moves))
        report = _jog(opts, robot, targets, speed, record)
    if opts.json:
        emit_json(report)
    fail_unsettled(report, profile)
    finish(robot)


def _jog(opts: Options, robot: Any, targets: dict[str, float], speed: float | None,
         record: Path | None) -> dict[str, Any]:
    """The move with a progress bar, recorded to ``record`` when given; its outcome said."""
    label = f"jog {', '.join(targets)}"

    def moving() -> dict[str, Any]:
        bar = progress(opts)
        try:
            report = robot.move(targets, speed, advancing(bar, label))
        finally:
            if bar is not None:
                bar.stop()
        if not opts.json:
            _said(label, report)
        return report

    if record is None:
        return moving()
    report = robot.recorded(record, moving)
    if not opts.json:
        info(f"wrote {record}: {report['recording']['cycles']} cycles of states and commands")
    return report
