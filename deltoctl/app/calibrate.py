"""The F/T tare: sample every F/T sensor, tare them, sample again, and judge what is left;
one report per block, saved as ``calibration-<model>-<address>-<time>.json``."""

from __future__ import annotations

import json
import math
import statistics
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any

from deltoctl.errors import DeviceError, InvalidInput

if TYPE_CHECKING:
    from deltoctl.core.system import System

AXES = ("force.x", "force.y", "force.z", "torque.x", "torque.y", "torque.z")
RATE = 200.0  # Hz between two samples of a check


def _collect(system: System, sensors: list[str], count: int) -> dict[str, dict[str, list]]:
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
        time.sleep(1.0 / RATE)
    return samples


def _residuals(before: dict, after: dict, force_tol: float, torque_tol: float) -> dict:
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


def ft_blocks(system: System) -> dict[str, list[str]]:
    """Each driven block that can tare, with its F/T sensors; the blocks with F/T sensors
    that cannot are a warning."""
    blocks = {m.name: [s.name for s in m.hw.sensors if s.state("force.x")]
              for m in system.able("calibrate_ft")}
    blocks = {name: sensors for name, sensors in blocks.items() if sensors}
    if not blocks:
        raise InvalidInput(f"{system.profile.name} has no F/T sensors to calibrate")
    unable = [m.name for m in system if m.name not in blocks
              and any(s.state("force.x") for s in m.hw.sensors)]
    if unable:
        system.notes.append(f"{', '.join(unable)}: cannot calibrate F/T")
    for names in blocks.values():  # what a driver knows the device has, before sampling
        reason = getattr(system.member(names[0]).driver, "no_ft_reason", lambda: None)()
        if reason:
            raise DeviceError(reason, hint="deltoctl detect shows the device's sensors; "
                              "use a profile that declares them")
    return blocks


def check_tare(samples: int, force_tolerance: float, torque_tolerance: float,
               output_dir: Path | None) -> None:
    """The tare's options, checked before any device is opened."""
    if not all(math.isfinite(t) and t > 0 for t in (force_tolerance, torque_tolerance)):
        raise InvalidInput("the tolerances must be positive numbers")
    if not 2 <= samples <= 100_000:
        raise InvalidInput(f"samples must be 2 to 100000, got {samples}")
    if output_dir is not None and not output_dir.is_dir():
        raise InvalidInput(f"--output-dir {output_dir} is not a directory")


def tare_ft(system: System, samples: int = 50, force_tolerance: float = 0.3,
            torque_tolerance: float = 0.03, output_dir: Path | None = None) -> dict[str, Any]:
    """Tare every F/T sensor and check the residual over ``samples``; with ``output_dir``,
    each block's report is saved there (``report_file``). ``pass`` is false when a residual
    is over its tolerance; the caller decides what that means."""
    check_tare(samples, force_tolerance, torque_tolerance, output_dir)
    blocks = ft_blocks(system)
    sensors = [s for names in blocks.values() for s in names]
    before = _collect(system, sensors, samples)
    for names in blocks.values():
        system.member(names[0]).driver.tare_ft()
    time.sleep(0.05)
    system.read()
    after = _collect(system, sensors, samples)
    now = datetime.now(timezone.utc)
    reports = []
    for name, names in blocks.items():
        m = system.member(names[0])
        ident = m.driver.identify()
        per_sensor = _residuals({s: before[s] for s in names}, {s: after[s] for s in names},
                                force_tolerance, torque_tolerance)
        report = {
            "kind": "ft_tare", "profile": system.profile.name, "block": name,
            "model": ident.get("reported_model"), "firmware": ident.get("firmware"),
            "target": m.url, "time": now.isoformat(timespec="seconds"),
            "time_ns": time.time_ns(), "samples": samples,
            "tolerance": {"force_n": force_tolerance, "torque_nm": torque_tolerance},
            "pass": all(r["pass"] for r in per_sensor.values()), "sensors": per_sensor,
        }
        if output_dir is not None:
            model = str(ident.get("reported_model", name)).split(" ")[0]
            address = m.url.split("://", 1)[-1].replace(":", "_").replace("/", "_")
            path = output_dir / (f"calibration-{model}-{address}-"
                                 f"{now.strftime('%Y%m%dT%H%M%SZ')}.json")
            path.write_text(json.dumps(report, indent=2) + "\n")
            report["report_file"] = str(path)
        reports.append(report)
    return {"pass": all(r["pass"] for r in reports), "blocks": reports}
