"""``deltoctl calibrate ft``: tare the fingertip F/T sensors and check what is left."""

from pathlib import Path
from typing import Annotated

import typer

from deltoctl.cli.context import options
from deltoctl.cli.device_cmd import AllowMismatch, finish, open_robot
from deltoctl.cli.output import emit_json, info, table
from deltoctl.errors import DeviceError

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
    allow_model_mismatch: AllowMismatch = False,
) -> None:
    """Tare the F/T sensors of every block that has them (SET_FT_SENSOR_OFFSET), then check
    the residual over N samples; exit 1 when over tolerance. One report per block, saved as
    calibration-<model>-<address>-<time>.json."""
    from deltoctl.app.calibrate import check_tare

    opts = options(ctx)
    check_tare(samples, force_tolerance, torque_tolerance, output_dir)
    with open_robot(opts, allow_model_mismatch) as robot:
        result = robot.calibrate_ft(samples, force_tolerance, torque_tolerance, output_dir)
    reports = result["blocks"]
    if opts.json:
        emit_json(result)
    else:
        table(None, ["block", "sensor", "residual force N", "residual torque N·m", "pass"],
              [[r["block"], s, v["residual_force_n"], v["residual_torque_nm"],
                "yes" if v["pass"] else "NO"]
               for r in reports for s, v in r["sensors"].items()])
        for r in reports:
            info(f"report: {r['report_file']}")
    bad = [s for r in reports for s, v in r["sensors"].items() if not v["pass"]]
    if bad:
        raise DeviceError(f"residual over tolerance after the tare on: {', '.join(bad)}",
                          hint="check the firmware (OFFSET needs v2.3 or later) and that "
                               "nothing touches the fingertips")
    finish(robot.system)


def register(root: typer.Typer) -> None:
    root.add_typer(app, name="calibrate")
