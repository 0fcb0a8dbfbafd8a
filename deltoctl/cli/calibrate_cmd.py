"""``deltoctl calibrate ft``: tare the fingertip F/T sensors and check what is left;
``deltoctl calibrate imu``: the IMU's self-test, gravity check and six-position tumble;
``deltoctl calibrate servos``: the servos' calibration in their family's file format;
``deltoctl calibrate joints``: LeRobot's joint calibration with the robot's profile."""

from pathlib import Path
from typing import Annotated, Any

import typer

from deltoctl.cli.confirm import confirm
from deltoctl.cli.context import Options, options, parse_pairs
from deltoctl.cli.device_cmd import AllowMismatch, finish, open_robot
from deltoctl.cli.output import emit_json, info, table
from deltoctl.errors import InvalidInput

app = typer.Typer(help="Calibration routines that write a report.", no_args_is_help=True)


@app.command("ft")
def calibrate_ft(
    ctx: typer.Context,
    samples: Annotated[int, typer.Option("--samples", "-n", min=2, max=100000,
                                         help="Samples per check.")] = 50,
    force_tolerance: Annotated[float, typer.Option(
        help="Largest residual force after the tare, N (norm of the mean).")] = 0.3,
    torque_tolerance: Annotated[float, typer.Option(
        help="Largest residual torque after the tare, N·m (norm of the mean).")] = 0.03,
    output_dir: Annotated[Path, typer.Option(
        "--output-dir", "-o", help="Where the JSON reports go.")] = Path("."),
    verify: Annotated[bool, typer.Option(
        "--verify", help="After the tare, judge each residual as a check (implied by --mass "
                         "and --watch).")] = False,
    mass: Annotated[float | None, typer.Option(
        help="A known mass, kg: the terminal asks for it on --sensor and checks its weight "
             "once the reading settles.")] = None,
    sensor: Annotated[str | None, typer.Option(
        help="The fingertip the mass goes on (the first F/T sensor by default).")] = None,
    watch: Annotated[float | None, typer.Option(
        help="Seconds to watch the drift of each axis (Fx, Fy, Fz within the force "
             "tolerance, Tx, Ty, Tz within the torque tolerance, or --drift-limit).")] = None,
    drift_limit: Annotated[list[str] | None, typer.Option(
        "--drift-limit", metavar="AXIS=LIMIT",
        help="The drift allowed on one axis (fx, fy, fz in N; tx, ty, tz in N·m), e.g. "
             "fz=0.1 (repeatable).")] = None,
    timeout: Annotated[float, typer.Option(
        help="Seconds to wait for the mass to settle.")] = 60.0,
    allow_model_mismatch: AllowMismatch = False,
) -> None:
    """Tare the F/T sensors of every block that has them (SET_FT_SENSOR_OFFSET), then check
    the residual over N samples; exit 1 when over tolerance. One report per block, saved as
    calibration-<model>-<address>-<time>.json. --verify reports each check (id, value,
    limit, verdict); --watch S the drift of each axis over S seconds; --mass KG a known
    mass's weight."""
    from deltoctl.app.calibrate import check_tare, check_verify, fail_ft

    opts = options(ctx)
    drift = _drift_limits(drift_limit or [])
    check_tare(samples, force_tolerance, torque_tolerance, output_dir)
    check_verify(mass, watch, timeout, drift)
    verify = verify or mass is not None or watch is not None
    checks = {"mass": mass, "sensor": sensor, "watch": watch, "ask": _ask, "timeout": timeout,
              "drift_limit": drift} if verify else None
    with open_robot(opts, allow_model_mismatch) as robot:
        result = robot.calibrate_ft(samples, force_tolerance, torque_tolerance, output_dir,
                                    lambda what: confirm(ctx, what), checks)
    _show_ft(opts, result, verify)
    fail_ft(result)
    finish(robot)


def _drift_limits(items: list[str]) -> dict[str, float]:
    """``--drift-limit fz=0.1`` … as {axis: limit}; the axes and values are checked by
    check_verify."""
    from deltoctl.units import quantity

    pairs = parse_pairs(items, "=", "--drift-limit", "AXIS=LIMIT (fz=0.1)")
    return {axis.lower(): quantity(value, f"--drift-limit {axis}")
            for axis, value in pairs.items()}


def _ask(text: str) -> None:
    """What the operator is to do now, on stderr."""
    typer.echo(f"{text} …", err=True)


def _show_ft(opts: Options, result: dict[str, Any], verify: bool) -> None:
    from deltoctl.render.checks import ft_table

    if opts.json:
        emit_json(result)
        return
    table(*ft_table(result, verify))
    for r in result["blocks"]:
        info(f"report: {r['report_file']}")


@app.command("imu")
def calibrate_imu(
    ctx: typer.Context,
    samples: Annotated[int, typer.Option("--samples", "-n", min=10, max=100000,
                                         help="Samples of the gravity check.")] = 100,
    tumble: Annotated[bool, typer.Option(
        "--tumble", help="Then the six-position tumble: the terminal says which face to put "
                         "down and waits until the readings settle; saves the calibration.")
    ] = False,
    timeout: Annotated[float, typer.Option(help="Seconds to wait for each position.")] = 120.0,
    output_dir: Annotated[Path, typer.Option(
        "--output-dir", "-o", help="Where the calibration file goes.")] = Path("."),
    allow_model_mismatch: AllowMismatch = False,
) -> None:
    """Verify every IMU: the chip's built-in self-test against its datasheet's limits and a
    gravity check at rest (|a| = 9.81 m/s², gyro at its zero-rate level); with --tumble, each
    axis's bias and scale from six positions, saved as
    calibration-<chip>-<address>-<time>.json — name it in the sensor's `calibration` param
    and stream and record apply it. Exit 1 when a check fails."""
    from deltoctl.app.imu_calibration import check_options, fail_imu
    from deltoctl.render.checks import calibration_files, imu_table

    opts = options(ctx)
    check_options(samples, timeout, output_dir)
    with open_robot(opts, allow_model_mismatch) as robot:
        result = robot.calibrate_imu(samples, _ask if tumble else None, timeout, output_dir,
                                     lambda what: confirm(ctx, what))
    if opts.json:
        emit_json(result)
    else:
        table(*imu_table(result))
        for line in calibration_files(result):
            info(line)
    fail_imu(result)
    finish(robot)


@app.command("servos")
def calibrate_servos(
    ctx: typer.Context,
    half_turn: Annotated[bool, typer.Option(
        "--half-turn", help="First make each servo's present pose the middle of its turn "
                            "(torque off; written into the servo).")] = False,
    name: Annotated[str, typer.Option(
        "--id", help="The device's name in the file's default place.")] = "my_arm",
    output: Annotated[Path | None, typer.Option(
        "--output", "-o", help="Where the file goes (default: where the format's tools look "
                               "for it).")] = None,
    force: Annotated[bool, typer.Option("--force", help="Overwrite an existing file.")] = False,
    allow_model_mismatch: AllowMismatch = False,
) -> None:
    """Save the servos' calibration in their family's file format: a Feetech SO arm's as
    LeRobot's calibration JSON (homing offset and position limits per motor), by default at
    LeRobot's place for it ($HF_LEROBOT_CALIBRATION/robots/so_follower/ID.json, a leader's
    under teleoperators/so_leader). With --half-turn, LeRobot's half-turn homing first."""
    from deltoctl.render.checks import servo_files, servo_tables

    opts = options(ctx)
    with open_robot(opts, allow_model_mismatch) as robot:
        result = robot.calibrate_servos(half_turn, name, output, lambda what: confirm(ctx, what),
                                        force)
    if opts.json:
        emit_json(result)
    else:
        for (title, columns, rows), line in zip(servo_tables(result), servo_files(result),
                                                strict=True):
            table(title, columns, rows)
            info(line)
    finish(robot)


@app.command("joints")
def calibrate_joints(
    ctx: typer.Context,
    allow: Annotated[list[str] | None, typer.Option(
        help="Write into the servos (else the file only): --allow homing-offset --allow "
             "min-position-limit --allow max-position-limit.")] = None,
    fmt: Annotated[str, typer.Option("--format", help="deltoctl, or lerobot: LeRobot's file "
                                     "too, at LeRobot's place for --id.")] = "deltoctl",
    name: Annotated[str | None, typer.Option("--id", help=(
        "The arm's name: its own calibration file of the profile, and LeRobot's file's name "
        "(my_arm by default)."))] = None,
    full_turn: Annotated[list[str] | None, typer.Option(
        help="A joint given its whole turn, not recorded (repeatable).")] = None,
    seconds: Annotated[float | None, typer.Option("--range-seconds", help=(
        "Sample the range this long, not until Enter (the arm in its middle pose)."))] = None,
    hand: Annotated[list[str] | None, typer.Option(help=(
        "With --sim: a control line, one a sample as the range starts ('hand wrist_flex 40', "
        "'sweep wrist_flex 0 90 2'; repeatable)."))] = None,
    allow_model_mismatch: AllowMismatch = False,
) -> None:
    """LeRobot's calibration with the profile: torque off, the arm in the middle of its range
    (each joint's homing offset: that pose reads zero), each joint moved by hand through its
    range, checked against the profile's limits; saved (one file per profile, and per --id),
    and checked at every later open when written into the servos."""
    import sys
    import threading

    from deltoctl.app.joint_calibration import check_allow, check_id, check_seconds
    from deltoctl.render.joint_calibration import RangeLive, calibration_table

    opts, pressed, started = options(ctx), threading.Event(), threading.Event()
    if fmt not in ("deltoctl", "lerobot"):
        raise InvalidInput(f"--format is deltoctl or lerobot, got {fmt!r}")
    check_id(name)
    check_allow(allow or [])
    check_seconds(seconds)
    if seconds is None and not sys.stdin.isatty():
        raise InvalidInput("no terminal to press Enter on: pass --range-seconds")
    live = RangeLive(sys.stderr.isatty() and not opts.json)

    def middle() -> None:
        _ask("move the arm to the middle of its range, then press Enter")
        sys.stdin.readline()
        threading.Thread(target=lambda: (sys.stdin.readline(), pressed.set()),
                         daemon=True).start()

    def sampled(rows: list[dict[str, Any]]) -> bool:
        if not started.is_set():  # the middle pose is read, the arm limp: it is moved now
            started.set()
            _ask("the middle pose is read: move each joint by hand through its range, "
                 + (f"within {seconds:g} s" if seconds else "then press Enter"))
        live.show(rows)
        return pressed.is_set()

    with open_robot(opts, allow_model_mismatch) as robot, live:
        result = robot.calibrate_joints(
            None if seconds else middle, sampled,
            seconds, allow or [], (name or "my_arm") if fmt == "lerobot" else None,
            full_turn or [], lambda what: confirm(ctx, what), hand or [], name)
    emit_json(result) if opts.json else table(*calibration_table(result))
    finish(robot)


def register(root: typer.Typer) -> None:
    root.add_typer(app, name="calibrate")
