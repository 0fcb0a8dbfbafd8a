"""``deltoctl replay FILE.mcap``: play a recording's commands back at their recorded timing.

On the profile's simulators unless --device says otherwise (then confirmed as any motion);
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


def _where(opts: Options, device: bool) -> Options:
    """The options the System opens with: the simulators unless --device."""
    if opts.target and not device:
        raise InvalidInput("-t/--target names a device: add --device to replay on it "
                           "(replay runs on the simulators unless told otherwise)")
    if device and opts.sim:
        raise InvalidInput("--sim and --device: choose one (replay runs on the simulators "
                           "unless --device says otherwise)")
    if device:
        return opts
    import copy

    sim = copy.copy(opts)
    sim.sim = True
    return sim


def _targets(opts: Options, profile: Any, blocks: list[str]) -> str:
    """Where --device sends the commands, for the confirmation."""
    if opts.target:
        return ", ".join(opts.target)
    urls = {hw.bus: profile.buses.get(hw.bus or "", "?") for hw in profile.hardware
            if hw.name in blocks and hw.bus}
    return ", ".join(f"{bus} {url}" for bus, url in urls.items()) or "the profile's devices"


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
        "--device", help="Replay on the real devices (the profile's buses, or -t/--target) "
                         "instead of the simulators; asks for confirmation unless --yes.")
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
    a terminal)."""
    from deltoctl.cli.motion_cmd import confirm_motion
    from deltoctl.core.replay import (
        Deviated,
        Replay,
        check_commands,
        read_recording_commands,
        recorded_profile,
    )
    from deltoctl.core.runner import interrupted_by_signals

    opts = options(ctx)
    limit = _tolerance(tolerance)
    deviation = _tolerance(max_deviation, "--max-deviation")
    deviation = MAX_DEVIATION if deviation is None else deviation
    recorded = read_recording_commands(recording)
    profile = opts.load_profile() if opts.profile else recorded_profile(recorded)
    run_opts = _where(opts, device)
    check_commands(profile, recorded)  # refused before anything is opened or moves
    joints = recorded.joints
    blocks = [hw.name for hw in profile.hardware
              if any(j.name in joints for j in hw.joints)]
    left_out = [b for b in blocks if opts.hardware and b not in opts.hardware]
    if left_out:
        raise InvalidInput(f"the recording commands block(s) {', '.join(left_out)}, which "
                           "--hardware leaves out")
    rows = len(recorded.times)
    if device:
        confirm_motion(opts, f"move {', '.join(joints)} to the recorded start pose, then "
                             f"replay {rows} commands ({recorded.seconds:.2f} s) of "
                             f"{recording.name} on {', '.join(blocks)} at "
                             f"{_targets(opts, profile, blocks)}")
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
                if not device:
                    _home_simulated(system, joints)
                for names in system.by_block(joints).values():
                    system.member(names[0]).driver.check_motion(names)  # e.g. not homed
                if start:
                    moved = system.move(start)
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
    report = _report(recording, system, recorded, result, limit, device)
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
