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
from typing import Annotated, Any

import typer

from deltoctl.cli.context import Options, options
from deltoctl.cli.device_cmd import AllowMismatch, finish, open_system
from deltoctl.cli.output import emit_json, info, progress, say, table, warn
from deltoctl.errors import WARNINGS, DeviceError, InvalidInput, Refused

MAX_DEVIATION = 0.2  # rad or m: a replayed joint further than this from its recording stops


def register(app: typer.Typer) -> None:
    app.command("replay")(replay)


def _tolerance(text: str | None, option: str = "--tolerance") -> float | None:
    if text is None:
        return None
    import math

    from deltoctl.units import parse_quantity

    try:
        value = parse_quantity(text)
    except ValueError as exc:
        raise InvalidInput(f"{option}: {exc}") from None
    if not math.isfinite(value) or value < 0:
        raise InvalidInput(f"{option} must be a finite number ≥ 0, got {text!r}")
    return value


def _where(opts: Options, device: bool, profile: Any, blocks: list[str]) -> Options:
    """The options the System opens with: only the blocks the recording commands, on the
    simulators unless --device; on a device, only the one -t names (or --sim's): neither
    the recording's bus URLs nor a profile's choose a device."""
    import copy

    if opts.target and not device:
        raise InvalidInput("-t/--target names a device: add --device to replay on it "
                           "(replay runs on the simulators unless told otherwise)")
    run = copy.copy(opts)
    run.hardware = opts.hardware or blocks
    if not device:
        run.sim = True
    elif not opts.sim:
        _check_targets(opts, profile, run.hardware)
    return run


def _check_targets(opts: Options, profile: Any, blocks: list[str]) -> None:
    """Every bus a replay on a device drives is named by -t (a simulated block aside)."""
    from deltoctl import registry
    from deltoctl.core.system import mock_blocks, parse_targets

    mock = mock_blocks(profile, blocks)
    buses = {hw.bus or hw.name for hw in profile.hardware if hw.name in blocks
             and hw.name not in mock and (f := registry.of_block(profile.family_of(hw),
                                                                 hw.plugin)) and f.schemes}
    named, bare = parse_targets(profile, opts.target)
    missing = sorted(buses - set(named)) if not bare else []
    if missing:
        raise InvalidInput(f"replay --device: name the device of {', '.join(missing)} with "
                           f"-t {missing[0]}=URL (or rehearse with --sim); a replay never "
                           "takes a device from the recording or from a profile's bus URLs")


def _targets(opts: Options) -> str:
    """Where --device sends the commands, for the confirmation."""
    return ", ".join(opts.target) or "the simulators"


def _home_simulated(system: Any, joints: list[str]) -> None:
    """A simulator starts unhomed: joints with a homing routine run it first, so that
    positions mean what they meant on the robot (a device is refused instead)."""
    for block, names in system.by_block(joints).items():
        m = system.member(names[0])
        routine = [j for j in names if system.component(j).command("home")]
        if not routine or not m.can("home"):
            continue
        try:
            m.driver.check_motion(routine)
        except Refused:
            info(f"{block}: homing {', '.join(routine)} on the simulator first")
            m.driver.home(routine)


def replay(
    ctx: typer.Context,
    recording: Annotated[Path, typer.Argument(
        metavar="FILE.mcap", help="A recording with commands (jog --record).")],
    device: Annotated[bool, typer.Option(
        "--device", help="Replay on the devices -t/--target names (or, with --sim, on "
                         "simulators) under the limits of -p PROFILE or of the catalog's "
                         "profile, never the recording's; asks for confirmation unless --yes.")
    ] = False,
    tolerance: Annotated[str | None, typer.Option(
        "--tolerance", metavar="X", help="The largest difference allowed between recorded "
                                         "and replayed position (rad or m, e.g. 0.01 or "
                                         "1deg); beyond it, exit 3.")] = None,
    max_deviation: Annotated[str | None, typer.Option(
        "--max-deviation", metavar="X",
        help="While replaying, a joint further than this from its recorded position (rad or "
             f"m) stops every block, exit 5 (default {MAX_DEVIATION:g}).")] = None,
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
    from deltoctl.cli.motion_cmd import confirm_motion
    from deltoctl.core.replay import (
        Deviated,
        Replay,
        check_commands,
        check_recorded_profile,
        commanded_components,
        device_profile,
        read_recording_commands,
        recorded_profile,
    )
    from deltoctl.core.runner import interrupted_by_signals

    opts = options(ctx)
    limit = _tolerance(tolerance)
    deviation = _tolerance(max_deviation, "--max-deviation")
    deviation = MAX_DEVIATION if deviation is None else deviation
    recorded = read_recording_commands(recording)
    named = opts.load_profile() if opts.profile else None
    if device:  # the limits in force are the robot's, never the file's
        profile, theirs = device_profile(recorded, named)
    else:
        profile, theirs = named or recorded_profile(recorded), None
    commanded_components(profile, recorded)  # a joint the profile lacks: exit 2
    notes = check_recorded_profile(profile, theirs, recording)  # looser: exit 5
    check_commands(profile, recorded)  # refused before anything is opened or moves
    joints = recorded.joints
    blocks = [hw.name for hw in profile.hardware
              if any(j.name in joints for j in hw.joints)]
    left_out = [b for b in blocks if opts.hardware and b not in opts.hardware]
    if left_out:
        raise InvalidInput(f"the recording commands block(s) {', '.join(left_out)}, which "
                           "--hardware leaves out")
    run_opts = _where(opts, device, profile, blocks)
    for note in notes:
        warn(note)
    rows = len(recorded.times)
    if device and not opts.sim:
        confirm_motion(opts, f"move {', '.join(joints)} to the recorded start pose, then "
                             f"replay {rows} commands ({recorded.seconds:.2f} s) of "
                             f"{recording.name} on {', '.join(blocks)} at {_targets(opts)}")
    with open_system(run_opts, allow_model_mismatch, profile) as system:
        for block, names in system.by_block(joints).items():
            m = system.member(names[0])
            if not m.can("jog"):
                raise InvalidInput(f"{block} cannot move its joints")
        start = recorded.start_pose()
        player = Replay(system, recorded, deviation)
        stopped: Deviated | None = None
        bar = progress(opts)
        task = bar.add_task(f"replay {recording.name}", total=1.0) if bar else None
        try:
            with interrupted_by_signals():
                if run_opts.sim:
                    _home_simulated(system, joints)
                for names in system.by_block(joints).values():
                    system.member(names[0]).driver.check_motion(names)  # e.g. not homed
                if start:
                    moved = system.move(start, jog=False)  # a known pose, as home's
                    if not moved.settled:
                        raise DeviceError("the recorded start pose was not reached: "
                                          f"{', '.join(moved.unsettled)}; nothing replayed")
                try:
                    result = player.run(None if bar is None else
                                        lambda f: bar.update(task, completed=f))
                except Deviated as exc:  # the finally below stops every block first
                    stopped, result = exc, exc.result
        finally:
            system.stop()
            if bar is not None:
                bar.stop()
    report = _report(recording, system, recorded, result, limit, device and not opts.sim)
    report["max_deviation"] = deviation
    report["stopped"] = stopped.message if stopped else None
    if stopped is not None:
        if opts.json:
            emit_json(report)  # the replay until it was stopped
        raise stopped
    _show(opts, report)
    if report["exceeded"]:
        warn(f"{', '.join(report['exceeded'])}: replayed more than {limit:g} from the "
             "recording")
        finish(system)
        raise typer.Exit(WARNINGS)
    finish(system)
    if notes:  # shown before the replay
        raise typer.Exit(WARNINGS)


def _report(recording: Path, system: Any, recorded: Any, result: Any, limit: float | None,
            device: bool) -> dict[str, Any]:
    joints = {j: {"block": d.block, "samples": d.samples, "rms": round(d.rms, 6),
                  "max": round(d.largest, 6)} for j, d in result.joints.items()}
    exceeded = [j for j, d in result.joints.items() if limit is not None and d.largest > limit]
    return {
        "file": str(recording), "profile": system.profile.name,
        "on": "device" if device else "simulator", "target": system.url,
        "commands": result.rows, "recorded_seconds": round(recorded.seconds, 3),
        "seconds": round(result.seconds, 3), "late_max_ms": round(result.late_max_ms, 3),
        "joints": joints, "tolerance": limit, "exceeded": exceeded,
    }


def _show(opts: Options, report: dict[str, Any]) -> None:
    if opts.json:
        emit_json(report)
        return
    say(f"replayed {report['commands']} commands of {Path(report['file']).name} on the "
        f"{report['on']} in {report['seconds']:.2f} s (recorded: "
        f"{report['recorded_seconds']:.2f} s; latest command {report['late_max_ms']:.1f} ms "
        "late)")
    table("recorded vs replayed position", ["joint", "block", "samples", "RMS", "max"],
          [[j, d["block"], d["samples"], f"{d['rms']:.5f}", f"{d['max']:.5f}"]
           for j, d in report["joints"].items()])
