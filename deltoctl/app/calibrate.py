"""The F/T tare: sample every F/T sensor, tare them, sample again, and judge what is left;
one report per block, saved as ``calibration-<model>-<address>-<time>.json``."""

from __future__ import annotations

import json
import math
import statistics
import time
from collections.abc import Callable
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any

from deltoctl.errors import DeviceError, InvalidInput

if TYPE_CHECKING:
    from deltoctl.core.system import System

AXES = ("force.x", "force.y", "force.z", "torque.x", "torque.y", "torque.z")
DRIFT_AXES = ("fx", "fy", "fz", "tx", "ty", "tz")  # AXES as the drift checks name them
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


def tare_description(system: System) -> str:
    """What a tare is about to do, for the caller's confirmation."""
    blocks = ft_blocks(system)
    return (f"tare the F/T sensors {', '.join(s for names in blocks.values() for s in names)} "
            f"of {', '.join(blocks)}: each one's zero becomes what it reads now, so nothing "
            "may touch them")


def tare_ft(system: System, samples: int = 50, force_tolerance: float = 0.3,
            torque_tolerance: float = 0.03, output_dir: Path | None = None) -> dict[str, Any]:
    """Tare every F/T sensor and check the residual over ``samples``; with ``output_dir``,
    each block's report is saved there (``report_file``). ``pass`` is false when a residual
    is over its tolerance; the caller decides what that means."""
    system.check_allowed("taring the F/T sensors")
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


# -- after the tare: the residual, a known mass, the drift -------------------------------------

G = 9.80665
SETTLE_STD = 0.1  # N of spread on a force axis: more, and the load is still moving
SETTLE_WINDOW = 40  # samples (0.2 s) a load must hold before it is read
MASS_TOLERANCE = 0.02  # of the expected weight, on top of the force tolerance


def _force(values: dict[str, float], sensor: str) -> tuple[float, float, float]:
    return (values[f"{sensor}/force.x"], values[f"{sensor}/force.y"],
            values[f"{sensor}/force.z"])


def _mean_force(system: System, sensor: str, count: int) -> tuple[float, ...]:
    samples = _collect(system, [sensor], count)[sensor]
    return tuple(statistics.fmean(samples[a]) for a in AXES[:3])


def _means(system: System, sensors: list[str], count: int) -> dict[str, tuple[float, ...]]:
    """Each sensor's mean on every axis (AXES) over ``count`` samples."""
    samples = _collect(system, sensors, count)
    return {s: tuple(statistics.fmean(samples[s][a]) for a in AXES) for s in sensors}


def drift_limits(force: float, torque: float, given: dict[str, float] | None = None
                 ) -> dict[str, float]:
    """The largest drift allowed per axis (DRIFT_AXES): the force tolerance (N) on fx, fy,
    fz, the torque tolerance (N·m) on tx, ty, tz, and the ones ``given``."""
    limits = {a: force if a.startswith("f") else torque for a in DRIFT_AXES}
    for axis, value in (given or {}).items():
        if axis not in limits:
            raise InvalidInput(f"--drift-limit {axis}: the axes are {', '.join(DRIFT_AXES)}")
        if not (math.isfinite(value) and value > 0):
            raise InvalidInput(f"--drift-limit {axis}={value:g}: a positive number")
        limits[axis] = value
    return limits


def drift_checks(system: System, sensors: list[str], watch: float, limits: dict[str, float],
                 samples: int) -> list[dict[str, Any]]:
    """How far each sensor's reading moves in ``watch`` seconds, axis by axis: a check each
    (``SENSOR.drift.fz``), the change against ± its limit, the rate in its note."""
    from deltoctl.app.checks import check

    start = _means(system, sensors, samples)
    time.sleep(watch)
    end = _means(system, sensors, samples)
    checks = []
    for s in sensors:
        for axis, name, before, after in zip(DRIFT_AXES, AXES, start[s], end[s]):
            unit = "N" if axis.startswith("f") else "N·m"
            drift, limit = after - before, limits[axis]
            checks.append(check(f"{s}.drift.{axis}", f"{name} drift over {watch:g} s",
                                round(drift, 5), unit, -limit, limit,
                                note=f"{drift / watch:+.4f} {unit}/s"))
    return checks


def _settled_load(system: System, sensor: str, least: float,
                  timeout: float) -> tuple[float, ...]:
    """The mean force once a load of at least ``least`` N holds still for SETTLE_WINDOW."""
    from collections import deque

    window: deque[tuple[float, float, float]] = deque(maxlen=SETTLE_WINDOW)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        values = system.read()
        if not system.connected:
            raise DeviceError("the link was lost during the check")
        window.append(_force(values, sensor))
        time.sleep(1.0 / RATE)
        if len(window) == SETTLE_WINDOW:
            columns = list(zip(*window))
            mean = tuple(statistics.fmean(c) for c in columns)
            if max(statistics.pstdev(c) for c in columns) <= SETTLE_STD and \
                    math.sqrt(sum(v * v for v in mean)) >= least:
                return mean
    raise DeviceError(f"no steady load on {sensor} within {timeout:g} s",
                      hint="put the mass on the fingertip and let it rest; --timeout gives "
                           "more time")


def check_verify(mass: float | None, watch: float | None, timeout: float,
                 drift_limit: dict[str, float] | None = None) -> None:
    if mass is not None and not (math.isfinite(mass) and 0.01 <= mass <= 50):
        raise InvalidInput(f"--mass must be 0.01 to 50 kg, got {mass:g}")
    if watch is not None and not (math.isfinite(watch) and 0 < watch <= 3600):
        raise InvalidInput(f"--watch must be a positive number of seconds up to 3600, "
                           f"got {watch:g}")
    if not (math.isfinite(timeout) and 0 < timeout <= 3600):
        raise InvalidInput(f"--timeout must be a positive number of seconds up to 3600, "
                           f"got {timeout:g}")
    drift_limits(1.0, 1.0, drift_limit)


def verify_ft(system: System, tare: dict[str, Any], mass: float | None = None,
              sensor: str | None = None, watch: float | None = None,
              ask: Callable[[str], None] | None = None, timeout: float = 60.0,
              samples: int = 50, drift_limit: dict[str, float] | None = None
              ) -> list[dict[str, Any]]:
    """Checks after ``tare_ft``: each sensor's residual force and torque against the
    tolerance; with ``watch``, how far each axis drifts in that many seconds (against the
    force or torque tolerance, or its ``drift_limit``: ``{"fz": 0.1}``); with ``mass`` (kg),
    the load read once the operator (``ask``) put it on ``sensor`` (the first F/T sensor by
    default) against its weight."""
    from deltoctl.app.checks import check

    check_verify(mass, watch, timeout, drift_limit)
    tolerance = tare["blocks"][0]["tolerance"]
    sensors = [s for block in tare["blocks"] for s in block["sensors"]]
    checks = []
    for block in tare["blocks"]:
        for name, r in block["sensors"].items():
            checks += [check(f"{name}.residual_force", "residual force after the tare",
                             r["residual_force_n"], "N", None, tolerance["force_n"]),
                       check(f"{name}.residual_torque", "residual torque after the tare",
                             r["residual_torque_nm"], "N·m", None, tolerance["torque_nm"])]
    if watch is not None:
        limits = drift_limits(tolerance["force_n"], tolerance["torque_nm"], drift_limit)
        checks += drift_checks(system, sensors, watch, limits, samples)
    if mass is not None:
        sensor = sensor or sensors[0]
        if sensor not in sensors:
            raise InvalidInput(f"--sensor {sensor}: not an F/T sensor of {system.profile.name} "
                               f"(its sensors: {', '.join(sensors)})")
        weight = mass * G
        before = _mean_force(system, sensor, samples)
        if ask is not None:
            ask(f"put {mass:g} kg on {sensor} and let it rest")
        loaded = _settled_load(system, sensor, weight / 2, timeout)
        change = math.dist(before, loaded)
        margin = tolerance["force_n"] + MASS_TOLERANCE * weight
        checks.append(check(f"{sensor}.known_mass", f"the weight of {mass:g} kg", change, "N",
                            weight - margin, weight + margin))
    return checks


def fail_ft(result: dict[str, Any]) -> None:
    """A tare that left a residual over tolerance, or a failed check beyond the residuals,
    failed (``DeviceError``, exit 1)."""
    bad = [s for r in result["blocks"] for s, v in r["sensors"].items() if not v["pass"]]
    if bad:
        raise DeviceError(f"residual over tolerance after the tare on: {', '.join(bad)}",
                          hint="check the firmware (OFFSET needs v2.3 or later) and that "
                               "nothing touches the fingertips")
    failed = [c["id"] for c in result.get("checks", []) if c["verdict"] == "fail"
              and not c["id"].endswith(("residual_force", "residual_torque"))]
    if failed:
        raise DeviceError(f"F/T checks failed: {', '.join(failed)}",
                          hint="a known mass read wrong is a scale or mounting fault; drift "
                               "wants the sensor warmed up")


def servo_calibration_description(system: System, half_turn: bool) -> str:
    """What ``calibrate servos`` is about to do, for the caller's confirmation."""
    blocks = [m.name for m in system.able("calibrate_servos")]
    if not blocks:
        raise InvalidInput(f"{system.profile.name} has no servos whose calibration deltoctl "
                           "writes")
    if not half_turn:
        return f"read the calibration of the servos of {', '.join(blocks)}"
    return (f"switch torque off on {', '.join(blocks)} and make each servo's present pose the "
            "middle of its turn (its Homing_Offset, written into the servo), its position limits "
            "reset to the whole turn (0..4095 on an STS3215): support the arm and put it in "
            "the middle of its range")


def check_device_name(name: str) -> None:
    """A device name is a file's name: no folder in it."""
    if not name or "/" in name or "\\" in name or name in (".", "..") or "\0" in name:
        raise InvalidInput(f"--id {name!r} must be a plain name (no '/', no '..')")


def _servo_file(output: Path | None, single: bool, device: str, default: str) -> Path:
    if output is None:
        return Path(default)
    return Path(output) if single else Path(output) / f"{device}.json"


def calibrate_servos(system: System, half_turn: bool, name: str,
                     output: Path | None = None, force: bool = False) -> dict[str, Any]:
    """Each able block's servo calibration in its family's file format, saved at ``output``
    or where the format's tools look for it (a block more: ``<name>-<block>``); an existing
    file is overwritten only with ``force``, checked before the servos are touched."""
    check_device_name(name)
    if half_turn:
        system.check_allowed("half-turn homing")
    able = system.able("calibrate_servos")
    devices = {m.name: name if len(able) == 1 else f"{name}-{m.name}" for m in able}
    for m in able if not force else ():
        there = _servo_file(output, len(able) == 1, devices[m.name],
                            m.driver.calibrate_servos(False, devices[m.name])["file"])
        if there.exists():
            raise InvalidInput(f"{there} exists: pass --force to overwrite it")
    blocks = []
    for m in able:
        device = devices[m.name]
        result = m.driver.calibrate_servos(half_turn, device)
        path = _servo_file(output, len(able) == 1, device, result["file"])
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(result["text"])
        except OSError as exc:
            raise InvalidInput(f"cannot write {path}: {exc.strerror}") from None
        blocks.append({"block": m.name, "format": result["format"], "file": str(path),
                       "parts": result["parts"]})
    return {"half_turn": half_turn, "blocks": blocks}
