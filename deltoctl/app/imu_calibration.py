"""The IMU verified, not only read: the chip's built-in self-test against its datasheet's
limits, a gravity check gated on the IMU being at rest, and a guided six-position tumble that
gives each axis's bias and scale, saved as a calibration file that a sensor's ``calibration``
param names (``stream`` and ``record`` then apply it; a recording's identify metadata says so).
"""

from __future__ import annotations

import math
import statistics
import time
from collections import deque
from collections.abc import Callable
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any

from deltoctl.app.checks import FAIL, SKIP, check, failed
from deltoctl.errors import DeviceError, InvalidInput

if TYPE_CHECKING:
    from deltoctl.core.system import Member, System

G = 9.80665
RATE = 100.0  # Hz between two samples
REST_ACCEL_STD = 0.1  # m/s² of spread on an axis: more, and the IMU moves or shakes
GRAVITY_TOLERANCE = 0.3  # m/s² (3 %) between |a| at rest and g
BIAS_LIMIT = 1.0  # m/s² (0.1 g) of accelerometer bias a tumble accepts
SCALE_LIMITS = (0.95, 1.05)
WINDOW = 20  # samples a face must hold still before it is taken
# the tumble's six positions: the axis up, its index, its sign
FACES = (("+z", 2, 1), ("-z", 2, -1), ("+x", 0, 1), ("-x", 0, -1), ("+y", 1, 1), ("-y", 1, -1))
AXES = ("x", "y", "z")

Ask = Callable[[str], None]


def imu_members(system: System) -> list[Member]:
    members = system.able("calibrate_imu")
    if not members:
        raise InvalidInput(f"{system.profile.name} has no IMU to calibrate")
    return members


def self_test_description(system: System, tumble: bool) -> str:
    """What the calibration is about to do, for the caller's confirmation."""
    sensors = ", ".join(f"{m.driver.sensor.name} of {m.name}" for m in imu_members(system))
    return (f"run the built-in self-test of {sensors}: the chip drives its own test "
            "excitation, then its settings are restored"
            + ("; then the six-position tumble, by hand" if tumble else ""))


def _mean_std(samples: list[tuple]) -> tuple[list[float], list[float]]:
    columns = list(zip(*samples))
    return ([statistics.fmean(c) for c in columns],
            [statistics.pstdev(c) for c in columns])


def _collect(driver: Any, count: int, calibrated: bool) -> list[tuple[tuple, tuple]]:
    samples = []
    for _ in range(count):
        samples.append(driver.sample(calibrated))
        time.sleep(1.0 / RATE)
    return samples


def self_test_checks(driver: Any) -> list[dict[str, Any]]:
    """The chip's self-test, one check per sensor and axis (the chip's own axes)."""
    result = driver.self_test()
    sensor, note = result["sensor"], "; ".join(f"unverified: {u}" for u in result["unverified"])
    checks = []
    for kind, unit, what in (("accel_mg", "mg", "accelerometer"), ("gyro_dps", "dps",
                                                                    "gyroscope")):
        low, high = result["limits"][kind]
        for axis, value in result[kind].items():
            checks.append(check(f"{sensor}.self_test.{kind.split('_')[0]}.{axis}",
                                f"{what} self-test, chip {axis} axis", value, unit, low, high,
                                note=note))
    return checks


def gravity_checks(driver: Any, samples: int) -> list[dict[str, Any]]:
    """At rest, |a| is g and the gyroscope reads its zero-rate level at most; an IMU that
    moves or shakes fails the rest check and the two others are skipped."""
    sensor = driver.sensor.name
    data = _collect(driver, samples, calibrated=True)
    (gyro, _), (accel, accel_std) = (_mean_std([g for g, _ in data]),
                                     _mean_std([a for _, a in data]))
    spread = max(accel_std)
    rest = check(f"{sensor}.at_rest", "spread of the acceleration at rest (largest axis)",
                 spread, "m/s²", None, REST_ACCEL_STD)
    norm = math.sqrt(sum(a * a for a in accel))
    rate = max(abs(w) for w in gyro)
    zero_rate = driver.zero_rate
    if rest["verdict"] == FAIL:
        why = "not at rest: hold the IMU still"
        return [rest, check(f"{sensor}.gravity", "|acceleration| at rest", norm, "m/s²",
                            G - GRAVITY_TOLERANCE, G + GRAVITY_TOLERANCE, SKIP, why),
                check(f"{sensor}.zero_rate", "angular velocity at rest (largest axis)", rate,
                      "rad/s", None, zero_rate, SKIP, why)]
    return [rest, check(f"{sensor}.gravity", "|acceleration| at rest", norm, "m/s²",
                        G - GRAVITY_TOLERANCE, G + GRAVITY_TOLERANCE),
            check(f"{sensor}.zero_rate", "angular velocity at rest (largest axis)", rate,
                  "rad/s", None, zero_rate)]


def face_text(axis: str) -> str:
    down = ("-" if axis[0] == "+" else "+") + axis[1].upper()
    return f"put the IMU's {down} face down ({axis[0]}{axis[1].upper()} axis up) and hold it still"


def _settle(driver: Any, index: int, sign: int, timeout: float,
            axis: str) -> tuple[list[float], list[float]]:
    """The mean (acceleration, angular velocity) once WINDOW raw samples hold still with
    ``axis`` up."""
    window: deque[tuple[tuple, tuple]] = deque(maxlen=WINDOW)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        window.append(driver.sample(False))
        time.sleep(1.0 / RATE)
        if len(window) < WINDOW:
            continue
        accel, std = _mean_std([a for _, a in window])
        others = [abs(a) for k, a in enumerate(accel) if k != index]
        if max(std) <= REST_ACCEL_STD and sign * accel[index] > 0.8 * G and \
                max(others) < 0.3 * G:
            return accel, _mean_std([g for g, _ in window])[0]
    raise DeviceError(f"the IMU did not hold still with its {axis} axis up within "
                      f"{timeout:g} s", hint="turn it as asked and keep it still; "
                      "--timeout gives more time")


def tumble(driver: Any, ask: Ask, timeout: float) -> tuple[dict[str, Any], list[dict]]:
    """Six positions, each axis up then down: bias = (up + down)/2 and scale =
    (up − down)/2g per accelerometer axis, the gyroscope's bias its mean over all six."""
    sensor = driver.sensor.name
    faces: dict[str, list[float]] = {}
    rates = []
    for axis, index, sign in FACES:
        ask(face_text(axis))
        faces[axis], gyro = _settle(driver, index, sign, timeout, axis)
        rates.append(gyro)
    bias = [(faces[f"+{a}"][i] + faces[f"-{a}"][i]) / 2 for i, a in enumerate(AXES)]
    scale = [(faces[f"+{a}"][i] - faces[f"-{a}"][i]) / (2 * G) for i, a in enumerate(AXES)]
    gyro_bias = [statistics.fmean(column) for column in zip(*rates)]
    checks = []
    for i, a in enumerate(AXES):
        checks += [check(f"{sensor}.accel_bias.{a}", f"accelerometer bias, {a}", bias[i],
                         "m/s²", -BIAS_LIMIT, BIAS_LIMIT),
                   check(f"{sensor}.accel_scale.{a}", f"accelerometer scale, {a}", scale[i],
                         "", *SCALE_LIMITS),
                   check(f"{sensor}.gyro_bias.{a}", f"gyroscope bias, {a}", gyro_bias[i],
                         "rad/s", -driver.zero_rate, driver.zero_rate)]
    return {**driver.calibration_data(bias, scale, gyro_bias),
            "faces": {k: [round(v, 5) for v in f] for k, f in faces.items()}}, checks


def check_options(samples: int, timeout: float, output_dir: Path | None) -> None:
    if not 10 <= samples <= 100_000:
        raise InvalidInput(f"samples must be 10 to 100000, got {samples}")
    if not (math.isfinite(timeout) and 0 < timeout <= 3600):
        raise InvalidInput(f"--timeout must be a positive number of seconds up to 3600, "
                           f"got {timeout:g}")
    if output_dir is not None and not output_dir.is_dir():
        raise InvalidInput(f"--output-dir {output_dir} is not a directory")


def calibrate_imu(system: System, samples: int = 100, ask: Ask | None = None,
                  timeout: float = 120.0, output_dir: Path | None = None) -> dict[str, Any]:
    """Self-test and gravity check of every IMU; with ``ask`` (told which face to put down),
    the tumble too, its calibration saved in ``output_dir`` (``calibration_file``)."""
    check_options(samples, timeout, output_dir)
    blocks = []
    for m in imu_members(system):
        driver = m.driver
        ident = driver.identify()
        checks = self_test_checks(driver) + gravity_checks(driver, samples)
        entry: dict[str, Any] = {"block": m.name, "sensor": driver.sensor.name,
                                 "chip": ident.get("chip"), "target": m.url,
                                 "applied_calibration": ident.get("calibration")}
        if ask is not None:
            data, tumble_checks = tumble(driver, ask, timeout)
            checks += tumble_checks
            now = datetime.now(timezone.utc)
            report = {"kind": "imu_calibration", "profile": system.profile.name,
                      "block": m.name, "sensor": driver.sensor.name, "chip": ident.get("chip"),
                      "address": ident.get("address"), "target": m.url,
                      "time": now.isoformat(timespec="seconds"), "time_ns": time.time_ns(),
                      "pass": not failed(tumble_checks), **data}
            if output_dir is not None:
                path = output_dir / (f"calibration-{ident.get('chip')}-{ident.get('address')}-"
                                     f"{now.strftime('%Y%m%dT%H%M%SZ')}.json")
                import json

                path.write_text(json.dumps(report, indent=2) + "\n")
                entry["calibration_file"] = str(path)
            entry["calibration"] = report
        entry["checks"] = checks
        entry["pass"] = not failed(checks)
        blocks.append(entry)
    return {"pass": all(b["pass"] for b in blocks), "blocks": blocks}


def fail_imu(result: dict[str, Any]) -> None:
    """An IMU check that failed fails the calibration (``DeviceError``, exit 1), naming
    it."""
    bad = [c["id"] for b in result["blocks"] for c in b["checks"] if c["verdict"] == "fail"]
    if bad:
        raise DeviceError(f"IMU checks failed: {', '.join(bad)}",
                          hint="a failed self-test is a faulty part; a failed rest check "
                               "wants the IMU still")
