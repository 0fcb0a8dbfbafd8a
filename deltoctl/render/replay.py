"""A replay's report for people: what was replayed, and per joint the difference between
recorded and replayed position."""

from __future__ import annotations

from pathlib import Path
from typing import Any


def replay_parts(report: dict[str, Any], joint_types: dict[str, str],
                 tolerance: str | None = None) -> list[Any]:
    """Its line and its table; each difference in the unit of ``tolerance`` (as typed), else
    degrees or millimetres by the joint's type."""
    from deltoctl.units import joint_dimension, parse_unit, shown

    line = (f"replayed {report['commands']} commands of {Path(report['file']).name} on the "
            f"{report['on']} in {report['seconds']:.2f} s (recorded: "
            f"{report['recorded_seconds']:.2f} s; latest command {report['late_max_ms']:.1f} "
            "ms late)")
    unit = parse_unit(tolerance).unit if tolerance else ""
    rows = []
    for j, d in report["joints"].items():
        dim = joint_dimension(joint_types[j]) if j in joint_types else None
        rows.append([j, d["block"], d["samples"], shown(d["rms"], dim, unit),
                     shown(d["max"], dim, unit)])
    return [line, ("recorded vs replayed position", ["joint", "block", "samples", "RMS", "max"],
                   rows)]
