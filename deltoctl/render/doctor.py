"""``deltoctl doctor``'s checks for people: one line per check, ✔ or ✘, the fix to type under
each ✘, and how many passed."""

from __future__ import annotations

from typing import Any


def doctor_lines(checks: list[dict[str, Any]]) -> list[str]:
    """The lines of the checks (deltoctl.app.doctor.diagnose's ``checks``)."""
    width = max([len(r["subject"]) for r in checks] + [0])
    lines = []
    for r in checks:
        lines.append(f"{'✔' if r['ok'] else '✘'} {r['subject']:<{width}}  {r['check']}: "
                     f"{r['detail']}")
        if r["fix"]:
            lines.append(f"  {'':<{width}}  fix: {r['fix']}")
    passed = sum(r["ok"] for r in checks)
    return [*lines, f"{passed} of {len(checks)} checks passed"]
