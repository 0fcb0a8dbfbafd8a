"""Checks as a person reads them: one table row per check (its id, value, unit, limit and
verdict, a failure in capitals), for the calibrations and the commissioning report."""

from __future__ import annotations

from typing import Any


def limit_text(check: dict[str, Any]) -> str:
    """A check's limit: ``≤ high``, ``≥ low``, ``low … high``, or nothing."""
    low, high = check["limit"]["min"], check["limit"]["max"]
    return ("" if low is None and high is None else f"≤ {high:g}" if low is None
            else f"≥ {low:g}" if high is None else f"{low:g} … {high:g}")


def check_rows(checks: list[dict[str, Any]], *first: str) -> list[list[Any]]:
    """One table row per check: ``first`` (e.g. its sensor), then its id, value, unit,
    limit and verdict."""
    return [[*first, c["id"], c["value"], c["unit"], limit_text(c),
             c["verdict"].upper() if c["verdict"] == "fail" else c["verdict"]] for c in checks]


def verdict_text(doc: dict[str, Any]) -> str:
    """A report's verdict as people read it: a failure in capitals, and SIMULATED before it
    when simulators stood in for devices (a rehearsal, not an acceptance)."""
    verdict = doc["verdict"].upper() if doc["verdict"] == "fail" else doc["verdict"]
    simulated = doc.get("simulated") or []
    return f"SIMULATED ({', '.join(simulated)}): {verdict}" if simulated else verdict


def residual_rows(blocks: list[dict[str, Any]]) -> list[list[Any]]:
    """One table row per F/T sensor of a tare: its block, the residual force and torque left,
    and whether they pass."""
    return [[r["block"], s, v["residual_force_n"], v["residual_torque_nm"],
             "yes" if v["pass"] else "NO"] for r in blocks for s, v in r["sensors"].items()]


def ft_table(result: dict[str, Any], verify: bool) -> tuple[None, list[str], list[list[Any]]]:
    """A tare's table: its checks (``verify``), else each sensor's residual."""
    if verify:
        return None, ["check", "value", "unit", "limit", "verdict"], check_rows(result["checks"])
    return (None, ["block", "sensor", "residual force N", "residual torque N·m", "pass"],
            residual_rows(result["blocks"]))


def imu_table(result: dict[str, Any]) -> tuple[None, list[str], list[list[Any]]]:
    """An IMU calibration's table: each sensor's checks."""
    return (None, ["sensor", "check", "value", "unit", "limit", "verdict"],
            [row for b in result["blocks"] for row in check_rows(b["checks"], b["sensor"])])


def calibration_files(result: dict[str, Any]) -> list[str]:
    """Where an IMU calibration saved each sensor's tumble, and what to do with it."""
    return [f"calibration: {b['calibration_file']} (name it in {b['sensor']}'s calibration "
            "param)" for b in result["blocks"] if "calibration_file" in b]


def servo_tables(result: dict[str, Any]) -> list[tuple[str, list[str], list[list[Any]]]]:
    """``calibrate servos``: one table per block (a row per part, its file's fields), and
    the line naming the file each was saved in."""
    return [(b["block"], ["part", *next(iter(b["parts"].values()), {})],
             [[part, *values.values()] for part, values in b["parts"].items()])
            for b in result["blocks"]]


def servo_files(result: dict[str, Any]) -> list[str]:
    return [f"{b['format']}: {b['file']}" for b in result["blocks"]]
