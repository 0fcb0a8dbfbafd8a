"""Motion verbs: home and jog. Confirmed as the verb table says (deltoctl.cli.confirm);
refused (exit 5) outside limits or without confirmation; duty 0 on the way out, Ctrl-C
included."""

import contextlib
from pathlib import Path
from typing import Annotated, Any

import typer

from deltoctl.cli.confirm import confirm
from deltoctl.cli.context import Options, options
from deltoctl.cli.device_cmd import AllowMismatch, finish, open_robot
from deltoctl.cli.output import advancing, emit_json, info, progress, say

VelocityOpt = Annotated[str | None, typer.Option(
    "--velocity", help="Setpoint speed: 20deg/s, 10mm/s, or a bare number in rad/s "
                       "(revolute) / m/s (prismatic).")]


def register(app: typer.Typer) -> None:
    app.command("home")(home)
    # negative deltas (`jog J -5deg`) are arguments, not unknown options
    app.command("jog", context_settings={"ignore_unknown_options": True})(jog)


def complete_joint(ctx: typer.Context, incomplete: str) -> list[str]:
    from deltoctl.cli.profile_cmd import complete_part

    return complete_part(ctx, incomplete)


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
    """Drive every block's joints home: by their homing routine, or to the home pose.

    Joints with a `home` command interface (the Bioscara arm) run into their hard stops one at
    a time, in the profile's homing order; the others go to safety.home_pose (zero unless the
    profile says otherwise). Blocks that cannot home are named."""
    from deltoctl.app.motion import fail_unsettled, home, joint_speed, plan_home

    opts = options(ctx)
    profile = opts.load_profile()
    plan = plan_home(profile, opts.hardware, joint or [])
    speed = joint_speed(profile, list(plan.targets), velocity)
    confirm(ctx, plan.describe())
    bars = _Bars(opts, plan.routine)
    with open_robot(opts, allow_model_mismatch, profile) as robot:
        try:
            report = home(robot.system, plan, force, speed, bars.move, bars.show)
        finally:
            bars.stop()
    if opts.json:
        emit_json(report)
    elif plan.targets:
        _said("home", report)
    if plan.targets:
        fail_unsettled(report, profile)
    finish(robot.system)


class _Bars:
    """Homing on a terminal: a bar per joint that runs its routine (its steps on stderr
    otherwise), then one for the way to the home pose, started when that begins."""

    def __init__(self, opts: Options, joints: list[str]) -> None:
        self.opts = opts
        self.bar = progress(opts, transient=False) if joints else None
        self.tasks = {j: self.bar.add_task(f"{j}: waiting", total=1.0)
                      for j in joints} if self.bar else {}
        self.posing = False

    def show(self, name: str, status: str, fraction: float) -> None:
        if self.bar is not None:
            self.bar.update(self.tasks[name], completed=fraction,
                            description=f"{name}: {status}")
        elif not self.opts.json:
            info(f"{name}: {status}")

    def move(self, fraction: float) -> None:
        if not self.posing:
            self.stop()
            self.posing = True
            self.bar = progress(self.opts)
            self.tasks = {"home": self.bar.add_task("home", total=1.0)} if self.bar else {}
        if self.bar is not None:
            self.bar.update(self.tasks["home"], completed=fraction)

    def stop(self) -> None:
        if self.bar is not None:
            self.bar.stop()
            self.bar = None


JogRecordOpt = Annotated[Path | None, typer.Option(
    "--record", metavar="FILE.mcap",
    help="Record the motion to MCAP: every block's states and each cycle's commands "
         "(/joint_commands), for `deltoctl replay`; {time} and {serial} in its name "
         "are filled as record fills them.")]
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
    """Move one joint by DELTA (or --to POS), within its limits and the profile's jog step;
    more JOINT DELTA pairs move at the same time (blocks on several links at once).

    A bare number is in rad for a revolute joint, m for a prismatic one; 5deg, 2mm say
    their unit, and a unit that is not the joint's (an angle on a prismatic joint) is
    refused (exit 2). The confirmation shows the move in the unit typed (else degrees or
    millimetres)."""
    from deltoctl.app.motion import fail_unsettled, jog_pairs, jog_targets, joint_speed
    from deltoctl.app.recording import new_output, planned_output

    opts = options(ctx)
    profile = opts.load_profile()
    pairs = jog_pairs(profile, joint, delta, more, to)
    speed = joint_speed(profile, [name for name, _ in pairs], velocity)

    # a file that cannot be written, or exists, is refused (exit 2) before anything opens
    record = planned_output(record, force) if record else None
    with open_robot(opts, allow_model_mismatch, profile) as robot, \
            new_output(record, robot.system, force) if record else \
            contextlib.nullcontext() as record:
        system = robot.system
        targets, moves = jog_targets(system, pairs, to)  # e.g. not homed: before asking
        system.check_move(targets, speed)  # the System's envelope, before anyone is asked
        confirm(ctx, "jog " + "; ".join(moves))
        report = _jog(opts, system, targets, speed, record)
    if opts.json:
        emit_json(report)
    fail_unsettled(report, profile)
    finish(robot.system)


def _jog(opts: Options, system: Any, targets: dict[str, float], speed: float | None,
         record: Path | None) -> dict[str, Any]:
    """The move with a progress bar, recorded to ``record`` when given; its outcome said."""
    from deltoctl.app.motion import move
    from deltoctl.app.recording import recorded_moves

    label = f"jog {', '.join(targets)}"

    def moving() -> dict[str, Any]:
        bar = progress(opts)
        try:
            report = move(system, targets, speed, advancing(bar, label))
        finally:
            if bar is not None:
                bar.stop()
        if not opts.json:
            _said(label, report)
        return report

    if record is None:
        return moving()
    report = recorded_moves(system, record, moving)
    if not opts.json:
        info(f"wrote {record}: {report['recording']['cycles']} cycles of states and commands")
    return report
