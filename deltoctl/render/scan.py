"""``deltoctl scan`` for people: a table of what answered (ID, model, firmware, baud,
protocol), what collided, and the bus time the scan took."""

from __future__ import annotations

from typing import Any

COLUMNS = ("id", "model", "firmware", "baud", "protocol")


def scan_parts(result: dict[str, Any]) -> list[str | tuple]:
    """Lines and a table (as deltoctl.cli.output.show takes them); the collisions are
    warnings (collision_lines)."""
    servos = result["servos"]
    parts: list[str | tuple] = []
    if servos:
        rows = [[_id(s), _model(s), s["firmware"], s["baud"], s["protocol"]] for s in servos]
        parts.append((None, COLUMNS, rows))
    tried = f"{result['probes']} of {result['of']} probes"
    parts.append(f"{len(servos) or 'nothing'} answered on {result['target']} ({tried}, "
                 f"{result['bus_seconds']:.3f} s of bus time)")
    if result["refused_bauds"]:
        parts.append("the adapter refused " + ", ".join(map(str, result["refused_bauds"]))
                     + " baud: not scanned")
    return parts


def _id(part: dict[str, Any]) -> Any:
    """A part's ID; "?" for garbled replies, "none" for a part that has none yet."""
    if part["id"] is None:
        return "?" if part["colliding"] else "none"
    return part["id"]


def _model(servo: dict[str, Any]) -> str:
    if not servo["colliding"]:
        return servo["model"]
    return f"{servo['model']} (several servos)" if servo["model"] else "garbled replies"


def collision_lines(result: dict[str, Any]) -> list[str]:
    """Why a colliding reply is no servo: several answer at one ID."""
    lines = [f"several servos at ID {i}: their replies collide — connect one at a time"
             for i in result["colliding"]]
    if any(s["colliding"] and s["id"] is None for s in result["servos"]):
        lines.append("replies garbled: several servos answer at once — connect one at a time")
    return lines
