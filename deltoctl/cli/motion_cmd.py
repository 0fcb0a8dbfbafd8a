"""Motion verbs: home and jog. Confirmation on a terminal unless --yes; refused (exit 5)
outside limits or without confirmation; duty 0 on the way out, Ctrl-C included."""

import sys
from typing import Annotated

import typer

from deltoctl.cli.context import Options, options
from deltoctl.cli.device_cmd import AllowMismatch, finish, open_session
from deltoctl.cli.output import emit_json, info, progress, say
from deltoctl.errors import DeviceError, InvalidInput, Refused
from deltoctl.units import parse_quantity

VelocityOpt = Annotated[str | None, typer.Option(
    "--velocity", help="Setpoint speed, e.g. 0.5 or 20deg (per second).")]


def register(app: typer.Typer) -> None:
    app.command("home")(home)
    # negative deltas (`jog J -5deg`) are arguments, not unknown options
    app.command("jog", context_settings={"ignore_unknown_options": True})(jog)


def confirm_motion(opts: Options, what: str) -> None:
    if opts.yes:
        return
    if not sys.stdin.isatty():
        raise Refused(f"{what}: motion needs confirmation; pass --yes to move without asking")
    if not typer.confirm(f"{what}. Move?", default=False, err=True):
        raise Refused("not confirmed; nothing moved")


def _quantity(text: str, what: str) -> float:
    try:
        return parse_quantity(text)
    except ValueError as exc:
        raise InvalidInput(f"{what}: {exc}") from None


def _speed(velocity: str | None) -> float | None:
    speed = _quantity(velocity, "--velocity") if velocity else None
    if speed is not None and speed <= 0:
        raise InvalidInput("--velocity must be positive")
    return speed


def _complete_joint(ctx: typer.Context, incomplete: str) -> list[str]:
    from deltoctl.cli.profile_cmd import complete_part

    return complete_part(ctx, incomplete)


def _move(opts: Options, session, targets: dict[str, float], velocity, label: str):  # type: ignore[no-untyped-def]
    import signal

    signal.signal(signal.SIGTERM, signal.default_int_handler)
    bar = progress(opts)
    task = bar.add_task(label, total=1.0) if bar else None
    try:
        result = session.driver.move(
            targets, session.profile, velocity,
            None if bar is None else lambda fraction: bar.update(task, completed=fraction))
    finally:
        session.driver.stop()
        if bar is not None:
            bar.stop()
    values = session.driver.read()
    report = {
        "settled": result.settled,
        "seconds": round(result.seconds, 3),
        "targets": targets,
        "positions": {j: values[f"{j}/position"] for j in targets},
        "unsettled": result.unsettled,
    }
    if opts.json:
        emit_json(report)
    elif not opts.quiet:
        say(f"{label}: {'settled' if result.settled else 'did not settle'} in "
             f"{result.seconds:.2f} s")
    if not result.settled:
        raise DeviceError(f"{len(result.unsettled)} joint(s) did not settle: "
                          f"{', '.join(result.unsettled)}")


def home(
    ctx: typer.Context,
    velocity: VelocityOpt = None,
    joint: Annotated[list[str] | None, typer.Option(
        "--joint", "-j", autocompletion=_complete_joint,
        help="Home only this joint (repeatable; default: all).")] = None,
    force: Annotated[bool, typer.Option(
        help="Home again joints that are homed already (homing joints only).")] = False,
    allow_model_mismatch: AllowMismatch = False,
) -> None:
    """Drive every joint home: to the profile's home pose, or by its homing routine.

    Joints with a `home` command interface (the Bioscara arm) run into their hard stops one at
    a time, in the profile's homing order; the others go to safety.home_pose (zero unless the
    profile says otherwise)."""
    from deltoctl.core.motion import check_target

    opts = options(ctx)
    profile = opts.load_profile()
    homing = [j.name for j in profile.joints() if j.command("home")]
    if homing:
        _home_routine(opts, profile, homing, joint or [], force)
        return
    joints = [j for j in profile.joints() if j.command("effort") or j.command("position")]
    if joint:
        joints = [j for j in joints if j.name in _known(profile, joint)]
    targets = {j.name: profile.safety.home_pose.get(j.name, 0.0) for j in joints}
    for comp in joints:
        check_target(profile, comp, targets[comp.name], None)
    speed = _speed(velocity)
    confirm_motion(opts, f"home {len(targets)} joints of {profile.name}")
    with open_session(opts, allow_model_mismatch, profile) as session:
        _move(opts, session, targets, speed, "home")
    finish(session)


def _known(profile, names: list[str]) -> list[str]:  # type: ignore[no-untyped-def]
    joints = [j.name for j in profile.joints()]
    for name in names:
        if name not in joints:
            raise InvalidInput(f"{profile.name} has no joint {name!r}")
    return names


def _home_routine(opts: Options, profile, homing: list[str], chosen: list[str],  # type: ignore[no-untyped-def]
                  force: bool) -> None:
    """Each joint runs into its hard stop, one at a time, in the profile's homing order."""
    import signal

    order = [j for j in profile.safety.homing_order if j in homing]
    order += [j for j in homing if j not in order]
    if chosen:
        order = [j for j in order if j in _known(profile, chosen)]
    confirm_motion(opts, f"home {', '.join(order)} of {profile.name} one at a time, each "
                   "running into its hard stop")
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    bar = progress(opts, transient=False)
    tasks = {j: bar.add_task(f"{j}: waiting", total=1.0) for j in order} if bar else {}

    def show(name: str, status: str, fraction: float) -> None:
        if bar is not None:
            bar.update(tasks[name], completed=fraction, description=f"{name}: {status}")
        elif not (opts.json or opts.quiet):
            info(f"{name}: {status}")

    with open_session(opts, profile=profile) as session:
        try:
            outcome = session.driver.home(order, force, show)
        finally:
            if bar is not None:
                bar.stop()
        values = session.driver.read()
    report = {"homed": outcome, "positions": {j: values.get(f"{j}/position") for j in order}}
    if opts.json:
        emit_json(report)
    finish(session)


def jog(
    ctx: typer.Context,
    joint: Annotated[str, typer.Argument(autocompletion=_complete_joint,
                                         help="The joint to move.")],
    delta: Annotated[str | None, typer.Argument(
        help="Relative move, e.g. 0.1, -5deg.")] = None,
    to: Annotated[str | None, typer.Option("--to", help="Absolute target instead.")] = None,
    velocity: VelocityOpt = None,
    allow_model_mismatch: AllowMismatch = False,
) -> None:
    """Move one joint by DELTA (or --to POS), within its limits and the profile's jog step."""
    import math

    from deltoctl.core.motion import check_target

    opts = options(ctx)
    profile = opts.load_profile()
    comp = profile.component(joint)
    if comp is None or comp.kind != "joint":
        raise InvalidInput(f"{profile.name} has no joint {joint!r}")
    if comp.command("effort") is None and comp.command("position") is None:
        raise InvalidInput(f"{joint} has no effort or position command interface to move it")
    if (delta is None) == (to is None):
        raise InvalidInput("give either DELTA or --to POS")
    speed = _speed(velocity)
    with open_session(opts, allow_model_mismatch, profile) as session:
        session.driver.check_motion([joint])  # e.g. not homed: refused before asking
        start = session.driver.read()[f"{joint}/position"]
        target = _quantity(to, "--to") if to is not None else start + _quantity(delta, "DELTA")
        check_target(profile, comp, target, start)
        confirm_motion(opts, f"jog {joint} from {start:.4f} to {target:.4f} "
                       f"({math.degrees(target - start):+.1f}°)")
        _move(opts, session, {joint: target}, speed, f"jog {joint}")
    finish(session)
