"""One acceptance check as data: what the calibrations and the commissioning report hold, each
with an id, a value, a unit, a limit and a verdict (pass, fail, warn or skip)."""

from __future__ import annotations

import math
from typing import Any

PASS, FAIL, WARN, SKIP = "pass", "fail", "warn", "skip"
SEVERITY = {FAIL: 0, WARN: 1, SKIP: 2, PASS: 3}  # the worst first


def check(check_id: str, what: str, value: Any, unit: str = "", low: float | None = None,
          high: float | None = None, verdict: str | None = None,
          note: str = "") -> dict[str, Any]:
    """A check; its verdict, unless given, is whether a number lies within [low, high]."""
    if verdict is None:
        ok = isinstance(value, (int, float)) and math.isfinite(value) and \
            (low is None or value >= low) and (high is None or value <= high)
        verdict = PASS if ok else FAIL
    if isinstance(value, float):
        value = round(value, 6)
    entry = {"id": check_id, "what": what, "value": value, "unit": unit,
             "limit": {"min": low, "max": high}, "verdict": verdict}
    if note:
        entry["note"] = note
    return entry


def overall(checks: list[dict[str, Any]]) -> str:
    """fail when one fails, warn when one warns, else pass."""
    verdicts = {c["verdict"] for c in checks}
    return FAIL if FAIL in verdicts else WARN if WARN in verdicts else PASS


def failed(checks: list[dict[str, Any]]) -> list[str]:
    return [c["id"] for c in checks if c["verdict"] == FAIL]
