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
