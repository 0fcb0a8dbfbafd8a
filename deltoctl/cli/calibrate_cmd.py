"""``deltoctl calibrate ft``: tare the fingertip F/T sensors and check what is left."""

import time
from pathlib import Path
from typing import Annotated

import typer

from deltoctl.cli.context import options
from deltoctl.cli.device_cmd import AllowMismatch, open_session
from deltoctl.cli.output import emit_json, info, table
from deltoctl.errors import DeviceError, InvalidInput

app = typer.Typer(help="Calibration routines that write a report.", no_args_is_help=True)

AXES = ("force.x", "force.y", "force.z", "torque.x", "torque.y", "torque.z")


def _collect(driver, sensors: list[str], count: int, rate: float) -> dict[str, dict[str, list]]:  # type: ignore[no-untyped-def]
    samples = {s: {a: [] for a in AXES} for s in sensors}
    for _ in range(count):
        values = driver.read()
        if not driver.connected:
            raise DeviceError("the link was lost during calibration; nothing was saved")
        for s in sensors:
            for a in AXES:
                samples[s][a].append(values[f"{s}/{a}"])
        time.sleep(1.0 / rate)
    return samples


@app.command("ft")
def calibrate_ft(
    ctx: typer.Context,
    samples: Annotated[int, typer.Option("--samples", "-n", help="Samples per check.")] = 50,
    force_tolerance: Annotated[float, typer.Option(
        help="Largest residual force after the tare, N (norm of the mean).")] = 0.3,
    torque_tolerance: Annotated[float, typer.Option(
        help="Largest residual torque after the tare, N·m (norm of the mean).")] = 0.03,
    output_dir: Annotated[Path, typer.Option(
        "--output-dir", "-o", help="Where the JSON report goes.")] = Path("."),
    allow_model_mismatch: AllowMismatch = False,
) -> None:
    """Tare (SET_FT_SENSOR_OFFSET), then check the residual over N samples; exit 1 when over
    tolerance. The report is saved as calibration-<model>-<address>-<time>.json."""
    import json
    import math
    import statistics
    from datetime import datetime, timezone

    opts = options(ctx)
    if samples < 2:
        raise InvalidInput("--samples must be at least 2")
    if not output_dir.is_dir():
        raise InvalidInput(f"--output-dir {output_dir} is not a directory")
    with open_session(opts, allow_model_mismatch) as session:
        driver = session.driver
        sensors = [s.name for s in session.hw.sensors if s.state("force.x")]
        if not sensors:
            raise InvalidInput(f"{session.profile.name} has no F/T sensors")
        before = _collect(driver, sensors, samples, 200.0)
        driver.tare_ft()
        time.sleep(0.05)
        driver.read()
        after = _collect(driver, sensors, samples, 200.0)
        ident = driver.identity.as_dict()
    per_sensor = {}
    passed = True
    for s in sensors:
        mean_b = {a: statistics.fmean(before[s][a]) for a in AXES}
        mean_a = {a: statistics.fmean(after[s][a]) for a in AXES}
        std_a = {a: statistics.stdev(after[s][a]) for a in AXES}
        force = math.sqrt(sum(mean_a[a] ** 2 for a in AXES[:3]))
        torque = math.sqrt(sum(mean_a[a] ** 2 for a in AXES[3:]))
        ok = force <= force_tolerance and torque <= torque_tolerance
        passed &= ok
        per_sensor[s] = {"offset_removed": {a: round(mean_b[a] - mean_a[a], 5) for a in AXES},
                         "residual_mean": {a: round(mean_a[a], 5) for a in AXES},
                         "residual_std": {a: round(std_a[a], 5) for a in AXES},
                         "residual_force_n": round(force, 5),
                         "residual_torque_nm": round(torque, 5), "pass": ok}
    now = datetime.now(timezone.utc)
    model = ident["reported_model"].split(" ")[0]
    address = session.url.split("://", 1)[1].replace(":", "_").replace("/", "_")
    report = {
        "kind": "ft_tare", "profile": session.profile.name, "model": ident["reported_model"],
        "firmware": ident["firmware"], "target": session.url,
        "time": now.isoformat(timespec="seconds"), "time_ns": time.time_ns(),
        "samples": samples, "tolerance": {"force_n": force_tolerance,
                                          "torque_nm": torque_tolerance},
        "pass": passed, "sensors": per_sensor,
    }
    path = output_dir / f"calibration-{model}-{address}-{now.strftime('%Y%m%dT%H%M%SZ')}.json"
    path.write_text(json.dumps(report, indent=2) + "\n")
    report["report_file"] = str(path)
    if opts.json:
        emit_json(report)
    else:
        table(None, ["sensor", "residual force N", "residual torque N·m", "pass"],
              [[s, r["residual_force_n"], r["residual_torque_nm"], "yes" if r["pass"] else "NO"]
               for s, r in per_sensor.items()])
        info(f"report: {path}")
    if not passed:
        bad = [s for s, r in per_sensor.items() if not r["pass"]]
        raise DeviceError(f"residual over tolerance after the tare on: {', '.join(bad)}",
                          hint="check the firmware (OFFSET needs v2.3 or later) and that "
                               "nothing touches the fingertips")


def register(root: typer.Typer) -> None:
    root.add_typer(app, name="calibrate")
