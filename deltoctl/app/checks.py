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


def failures(checks: list[dict[str, Any]]) -> list[str]:
    """Each failed check as ``id: what is wrong`` (a figure with its limit)."""
    return [f"{c['id']}: {c['what']}{_figure(c)}" for c in checks if c["verdict"] == FAIL]


def fail_on(checks: list[dict[str, Any]], doing: str = "") -> None:
    """Raise DeviceError (exit 1) naming each failed check and what is wrong with it."""
    from deltoctl.errors import DeviceError

    if failures(checks):
        raise DeviceError(doing + "; ".join(failures(checks)))


def _figure(c: dict[str, Any]) -> str:
    value, low, high = c["value"], c["limit"]["min"], c["limit"]["max"]
    if not isinstance(value, (int, float)) or (low is None and high is None):
        return ""
    limit = f"≥ {low:g}" if high is None else f"≤ {high:g}" if low is None \
        else f"{low:g} … {high:g}"
    unit = f" {c['unit']}" if c["unit"] else ""
    return f" is {value:g}{unit}, not {limit}"


def _slug(text: str) -> str:
    return "_".join("".join(ch if ch.isalnum() else " " for ch in text.lower()).split())


def _detect_message(c: dict[str, Any]) -> str:
    what, device = c["what"], c["device"]
    if c["match"]:
        return what
    if c.get("missing"):
        return f"{what} does not answer" + (
            "" if device in ("no answer", "missing") else f" ({device})")
    return f"{what}: {device}, the profile says {c['profile']}"


def detect_checks(blocks: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The verdict on what detect found (its blocks, each with the driver's checks), the same
    for ``detect`` and the commissioning report: a part the profile declares that does not
    answer fails; any other difference from the profile (a device the profile does not
    declare, another model or sensor) warns. Each check's id is ``detect.<block>.<part>``."""
    out: list[dict[str, Any]] = []
    seen: set[str] = set()
    for b in blocks:
        for c in b["checks"]:
            key = f"detect.{b['name']}.{c.get('part') or _slug(str(c['what']))}"
            check_id, n = key, 2
            while check_id in seen:
                check_id, n = f"{key}.{n}", n + 1
            seen.add(check_id)
            verdict = PASS if c["match"] else FAIL if c.get("missing") else WARN
            out.append(check(check_id, _detect_message(c), str(c["device"]), verdict=verdict,
                             note=f"profile: {c['profile']}"))
    return out
