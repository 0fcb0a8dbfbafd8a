"""``deltoctl calibrate ft``: tare the fingertip F/T sensors and check what is left."""

import time
from pathlib import Path
from typing import Annotated, Any

import typer

from deltoctl.cli.context import options
from deltoctl.cli.device_cmd import AllowMismatch, finish, open_system
from deltoctl.cli.output import emit_json, info, table
from deltoctl.errors import DeviceError, InvalidInput

app = typer.Typer(help="Calibration routines that write a report.", no_args_is_help=True)

AXES = ("force.x", "force.y", "force.z", "torque.x", "torque.y", "torque.z")


def _collect(system: Any, sensors: list[str], count: int,
             rate: float) -> dict[str, dict[str, list]]:
    samples: dict[str, dict[str, list]] = {s: {a: [] for a in AXES} for s in sensors}
    for _ in range(count):
        values = system.read()
        if not system.connected:
            raise DeviceError("the link was lost during calibration; nothing was saved")
        for s in sensors:
            for a in AXES:
                value = values.get(f"{s}/{a}")
                if value is None:  # e.g. the gripper reports tactile, not F/T, sensors
                    raise DeviceError(f"{s} sends no {a}: the device reports no F/T values "
                                      "for it", hint="deltoctl detect shows its sensor type")
                samples[s][a].append(value)
        time.sleep(1.0 / rate)
    return samples


def _residuals(before: dict, after: dict, force_tol: float, torque_tol: float) -> dict:
    import math
    import statistics

    per_sensor = {}
    for s in after:
        mean_b = {a: statistics.fmean(before[s][a]) for a in AXES}
        mean_a = {a: statistics.fmean(after[s][a]) for a in AXES}
        std_a = {a: statistics.stdev(after[s][a]) for a in AXES}
        force = math.sqrt(sum(mean_a[a] ** 2 for a in AXES[:3]))
        torque = math.sqrt(sum(mean_a[a] ** 2 for a in AXES[3:]))
        per_sensor[s] = {"offset_removed": {a: round(mean_b[a] - mean_a[a], 5) for a in AXES},
                         "residual_mean": {a: round(mean_a[a], 5) for a in AXES},
                         "residual_std": {a: round(std_a[a], 5) for a in AXES},
                         "residual_force_n": round(force, 5),
                         "residual_torque_nm": round(torque, 5),
                         "pass": force <= force_tol and torque <= torque_tol}
    return per_sensor


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
    import json
    import math
    from datetime import datetime, timezone

    opts = options(ctx)
    if not all(math.isfinite(t) and t > 0 for t in (force_tolerance, torque_tolerance)):
        raise InvalidInput("the tolerances must be positive numbers")
    if not output_dir.is_dir():
        raise InvalidInput(f"--output-dir {output_dir} is not a directory")
    reports = []
    with open_system(opts, allow_model_mismatch) as system:
        blocks = {m.name: [s.name for s in m.hw.sensors if s.state("force.x")]
                  for m in system.able("calibrate_ft")}
        blocks = {name: sensors for name, sensors in blocks.items() if sensors}
        if not blocks:
            raise InvalidInput(f"{system.profile.name} has no F/T sensors to calibrate")
        unable = [m.name for m in system if m.name not in blocks
                  and any(s.state("force.x") for s in m.hw.sensors)]
        for names in blocks.values():  # what a driver knows the device has, before sampling
            driver = system.member(names[0]).driver
            reason = getattr(driver, "no_ft_reason", lambda: None)()
            if reason:
                raise DeviceError(reason, hint="deltoctl detect shows the device's sensors; "
                                  "use a profile that declares them")
        sensors = [s for names in blocks.values() for s in names]
        before = _collect(system, sensors, samples, 200.0)
        for name in blocks:
            system.member(blocks[name][0]).driver.tare_ft()
        time.sleep(0.05)
        system.read()
        after = _collect(system, sensors, samples, 200.0)
        identities = {name: system.member(names[0]).driver.identify()
                      for name, names in blocks.items()}
        urls = {name: system.member(names[0]).url for name, names in blocks.items()}
    now = datetime.now(timezone.utc)
    for name, names in blocks.items():
        ident = identities[name]
        per_sensor = _residuals({s: before[s] for s in names}, {s: after[s] for s in names},
                                force_tolerance, torque_tolerance)
        model = str(ident.get("reported_model", name)).split(" ")[0]
        address = urls[name].split("://", 1)[-1].replace(":", "_").replace("/", "_")
        report = {
            "kind": "ft_tare", "profile": system.profile.name, "block": name,
            "model": ident.get("reported_model"), "firmware": ident.get("firmware"),
            "target": urls[name], "time": now.isoformat(timespec="seconds"),
            "time_ns": time.time_ns(), "samples": samples,
            "tolerance": {"force_n": force_tolerance, "torque_nm": torque_tolerance},
            "pass": all(r["pass"] for r in per_sensor.values()), "sensors": per_sensor,
        }
        path = output_dir / (f"calibration-{model}-{address}-"
                             f"{now.strftime('%Y%m%dT%H%M%SZ')}.json")
        path.write_text(json.dumps(report, indent=2) + "\n")
        report["report_file"] = str(path)
        reports.append(report)
    if opts.json:
        emit_json({"pass": all(r["pass"] for r in reports), "blocks": reports})
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
    finish(system, [f"{', '.join(unable)}: cannot calibrate F/T"] if unable else None)


def register(root: typer.Typer) -> None:
    root.add_typer(app, name="calibrate")
