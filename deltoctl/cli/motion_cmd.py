"""Motion verbs: home and jog. Confirmation on a terminal unless --yes; refused (exit 5)
outside limits or without confirmation; duty 0 on the way out, Ctrl-C included."""

import contextlib
import math
import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from deltoctl.cli.context import Options, options
from deltoctl.cli.device_cmd import AllowMismatch, finish, open_system
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
        value = parse_quantity(text)
    except ValueError as exc:
        raise InvalidInput(f"{what}: {exc}") from None
    if not math.isfinite(value):
        raise InvalidInput(f"{what} must be a finite number, got {text!r}")
    return value


def _speed(velocity: str | None) -> float | None:
    speed = _quantity(velocity, "--velocity") if velocity else None
    if speed is not None and speed <= 0:
        raise InvalidInput("--velocity must be positive")
    return speed


def _complete_joint(ctx: typer.Context, incomplete: str) -> list[str]:
    from deltoctl.cli.profile_cmd import complete_part

    return complete_part(ctx, incomplete)


def _move(opts: Options, system: Any, targets: dict[str, float], velocity: float | None,
          label: str, jog: bool = True) -> dict[str, Any]:
    """Move on every block that holds a target (at the same time), stop them all on the way
    out, and report per block."""
    from deltoctl.core.runner import interrupted_by_signals

    bar = progress(opts)
    task = bar.add_task(label, total=1.0) if bar else None
    try:
        with interrupted_by_signals():
            result = system.move(
                targets, velocity,
                None if bar is None else lambda fraction: bar.update(task, completed=fraction),
                jog=jog)
    finally:
        system.stop()
        if bar is not None:
            bar.stop()
    values = system.read()
    groups = system.by_block(targets)
    report = {
        "settled": result.settled,
        "seconds": round(result.seconds, 3),
        "blocks": [{"name": name, "joints": {
            j: {"target": targets[j], "position": values.get(f"{j}/position"),
                "settled": j not in result.unsettled} for j in joints}}
            for name, joints in groups.items()],
        "unsettled": result.unsettled,
    }
    if not opts.json:
        say(f"{label}: {'settled' if result.settled else 'did not settle'} in "
            f"{result.seconds:.2f} s")
    return report


def _fail_unsettled(report: dict[str, Any]) -> None:
    if report["unsettled"]:
        raise DeviceError(f"{len(report['unsettled'])} joint(s) did not settle: "
                          f"{', '.join(report['unsettled'])}")


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
    """Drive every block's joints home: by their homing routine, or to the home pose.

    Joints with a `home` command interface (the Bioscara arm) run into their hard stops one at
    a time, in the profile's homing order; the others go to safety.home_pose (zero unless the
    profile says otherwise). Blocks that cannot home are named."""
    from deltoctl.core.motion import check_target
    from deltoctl.core.system import select_blocks

    opts = options(ctx)
    profile = opts.load_profile()
    blocks = select_blocks(profile, opts.hardware)
    chosen = _known(profile, joint or [])
    routine = [j.name for hw in blocks for j in hw.joints if j.command("home")
               and (not chosen or j.name in chosen)]
    posed = [j for hw in blocks for j in hw.joints if not j.command("home")
             and (j.command("effort") or j.command("position")) and j.mimic is None
             and (not chosen or j.name in chosen)]
    targets = {j.name: profile.safety.home_pose.get(j.name, 0.0) for j in posed}
    for comp in posed:
        check_target(profile, comp, targets[comp.name], None)
    speed = _speed(velocity)
    what = []
    if routine:
        what.append(f"home {', '.join(routine)} one at a time, each running into its hard stop")
    if targets:
        what.append(f"move {len(targets)} joints to the home pose")
    if not what:
        raise InvalidInput(f"nothing to home in {profile.name}: no joint with a home, effort "
                           "or position command interface")
    confirm_motion(opts, f"{profile.name}: " + "; then ".join(what))
    report: dict[str, Any] = {"blocks": []}
    with open_system(opts, allow_model_mismatch, profile) as system:
        unable = [m.name for m in system if not m.can("home")
                  and any(j.name in targets or j.name in routine for j in m.hw.joints)]
        targets = {j: t for j, t in targets.items() if system.member(j).can("home")}
        if routine:
            report["blocks"] += _home_routine(opts, system, routine, force)
        if targets:
            moved = _move(opts, system, targets, speed, "home", jog=False)
            report["blocks"] += moved["blocks"]
            report["settled"], report["unsettled"] = moved["settled"], moved["unsettled"]
    report["cannot_home"] = unable
    if opts.json:
        emit_json(report)
    if targets:
        _fail_unsettled(report)
    finish(system, [f"{', '.join(unable)}: cannot home"] if unable else None)


def _known(profile: Any, names: list[str]) -> list[str]:
    joints = [j.name for j in profile.joints()]
    for name in names:
        if name not in joints:
            raise InvalidInput(f"{profile.name} has no joint {name!r}" + _near(name, joints))
    return names


def _near(name: str, names: list[str]) -> str:
    from deltoctl.suggest import did_you_mean

    return did_you_mean(name, names)


def _home_routine(opts: Options, system: Any, homing: list[str],
                  force: bool) -> list[dict[str, Any]]:
    """Each joint runs into its hard stop, one at a time, in the profile's homing order,
    block by block."""
    from deltoctl.core.runner import interrupted_by_signals

    order = [j for j in system.profile.safety.homing_order if j in homing]
    order += [j for j in homing if j not in order]
    bar = progress(opts, transient=False)
    tasks = {j: bar.add_task(f"{j}: waiting", total=1.0) for j in order} if bar else {}

    def show(name: str, status: str, fraction: float) -> None:
        if bar is not None:
            bar.update(tasks[name], completed=fraction, description=f"{name}: {status}")
        elif not opts.json:
            info(f"{name}: {status}")

    blocks = []
    try:
        with interrupted_by_signals():
            for name, joints in system.by_block(order).items():
                m = system.member(joints[0])
                outcome = m.driver.home(joints, force, show)
                values = system.read()
                blocks.append({"name": name, "joints": {
                    j: {"outcome": outcome.get(j), "position": values.get(f"{j}/position")}
                    for j in joints}})
    finally:
        if bar is not None:
            bar.stop()
    return blocks


def jog(
    ctx: typer.Context,
    joint: Annotated[str, typer.Argument(autocompletion=_complete_joint,
                                         help="The joint to move.")],
    delta: Annotated[str | None, typer.Argument(
        help="Relative move, e.g. 0.1, -5deg.")] = None,
    more: Annotated[list[str] | None, typer.Argument(
        metavar="[JOINT DELTA]...", show_default=False,
        help="More joints to move at the same time, each with its delta.")] = None,
    to: Annotated[str | None, typer.Option("--to", help="Absolute target instead.")] = None,
    velocity: VelocityOpt = None,
    record: Annotated[Path | None, typer.Option(
        "--record", metavar="FILE.mcap",
        help="Record the motion to MCAP: every block's states and each cycle's commands "
             "(/joint_commands), for `deltoctl replay`.")] = None,
    allow_model_mismatch: AllowMismatch = False,
) -> None:
    """Move one joint by DELTA (or --to POS), within its limits and the profile's jog step;
    more JOINT DELTA pairs move at the same time (blocks on several links at once)."""
    opts = options(ctx)
    profile = opts.load_profile()
    if (delta is None) == (to is None):
        raise InvalidInput("give either DELTA or --to POS")
    pairs = [(joint, delta)]
    if more:
        if to is not None or len(more) % 2:
            raise InvalidInput("more joints come as JOINT DELTA pairs (and not with --to)")
        pairs += list(zip(more[0::2], more[1::2]))
    comps = {}
    for name, _ in pairs:
        comp = profile.component(name)
        if comp is None or comp.kind != "joint":
            raise InvalidInput(f"{profile.name} has no joint {name!r}"
                               + _near(name, [j.name for j in profile.joints()]))
        if comp.command("effort") is None and comp.command("position") is None:
            raise InvalidInput(f"{name} has no effort or position command interface to move "
                               "it")
        if name in comps:
            raise InvalidInput(f"{name} is given twice")
        comps[name] = comp
    speed = _speed(velocity)
    from deltoctl.app.recording import new_output

    # a file that cannot be written is refused (exit 2) before anything opens
    with new_output(record) if record else contextlib.nullcontext(), \
            open_system(opts, allow_model_mismatch, profile) as system:
        for joints in system.by_block(list(comps)).values():
            m = system.member(joints[0])
            if not m.can("jog"):
                raise InvalidInput(f"{m.name} cannot move its joints")
            m.driver.check_motion(joints)  # e.g. not homed: refused before asking
        values = system.read()
        targets, moves = {}, []
        for name, step in pairs:
            start = values[f"{name}/position"]
            target = _quantity(to, "--to") if to is not None else \
                start + _quantity(step or "", "DELTA")
            if not math.isfinite(target):
                raise InvalidInput(f"the target of {name} must be finite")
            targets[name] = target
            moves.append(f"{name} ({system.member(name).name}) from {start:.4f} to "
                         f"{target:.4f} ({math.degrees(target - start):+.1f}°)")
        system.check_move(targets, speed)  # the System's envelope, before anyone is asked
        confirm_motion(opts, "jog " + "; ".join(moves))
        label = f"jog {', '.join(targets)}"
        if record is None:
            report = _move(opts, system, targets, speed, label)
        else:
            report = _recorded_move(opts, system, targets, speed, label, record)
    if opts.json:
        emit_json(report)
    _fail_unsettled(report)
    finish(system)


def _recorded_move(opts: Options, system: Any, targets: dict[str, float],
                   velocity: float | None, label: str, output: Path) -> dict[str, Any]:
    """``_move`` while every move loop's cycles (states and setpoints) go to ``output``."""
    from deltoctl.app.recording import recording_metadata
    from deltoctl.core.replay import CommandLog
    from deltoctl.record.recorder_process import RecorderProcess

    profile, metadata = recording_metadata(system)
    with RecorderProcess(output, profile, metadata, tuple(system.extra_states()),
                         commands=True) as recorder:
        with CommandLog(system, recorder) as log:
            report = _move(opts, system, targets, velocity, label)
        recorder.close()  # the move loops have no loop statistics of their own to write
    if recorder.error:  # a write failed or the file was removed: the message says what is left
        raise DeviceError(recorder.error)
    report["recording"] = {"output": str(output), "cycles": log.rows,
                           "messages": recorder.counts}
    if not opts.json:
        info(f"wrote {output}: {log.rows} cycles of states and commands")
    return report
