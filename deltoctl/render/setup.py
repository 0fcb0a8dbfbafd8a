"""``deltoctl setup`` for people: each joint's servo from where it was found to where the
profile wants it, the writes in order, and the bus time."""

from __future__ import annotations

from typing import Any

COLUMNS = ("joint", "found", "set to", "status")


def _where(at: dict[str, Any] | None) -> str:
    if at is None:
        return "not found"
    model = f" {at['model']}" if at.get("model") else ""
    return f"{_id(at['id'])} @ {at['baud']}{model}"


def _id(device_id: int | None) -> str:
    return "no ID" if device_id is None else f"ID {device_id}"


def joint_rows(result: dict[str, Any]) -> list[list[Any]]:
    return [[r["joint"], _where(r["from"]), f"ID {r['to']['id']} @ {r['to']['baud']}",
             r["status"] + (", verified" if r["verified"] else "")] for r in result["joints"]]


def step_lines(result: dict[str, Any]) -> list[str]:
    """The writes, one a line: ``elbow_flex: ID 1 → 3 (at ID 1, 57600 baud)``."""
    words = {"factory reset": "factory reset {}", "torque off": "torque off",
             "id": "{at} → {}", "baud": "baud {at_baud} → {}",
             "bit rate": "bit rate {at_baud} → {}, taken at the next power-on",
             "store": "ID and baud {} stored", "item": "{item} {was} → {to}"}
    return [f"{s['joint']}: " + words[s["action"]].format(
        s.get("value"), at=_id(s["at_id"]), was=_read(s.get("from")), **s)
            + f" (at {_id(s['at_id'])}, {s['at_baud']} baud)" for s in result["steps"]]


def _read(value: Any) -> str:
    return "(read once addressed)" if value is None else str(value)


def setup_parts(result: dict[str, Any]) -> list[str | tuple]:
    """The joints' table and the summary (as deltoctl.cli.output.show takes them)."""
    done = sum(1 for r in result["joints"] if r["verified"])
    what = "planned (dry run: nothing written)" if result["dry_run"] else \
        f"{done} of {len(result['joints'])} verified"
    items = [f"{s['joint']}: {s['item']} {_read(s['from'])} → {s['to']}, {s['status']}"
             + (", verified" if s["verified"] else "")
             for s in result["steps"] if s["action"] == "item" and "status" in s]
    return [(None, COLUMNS, joint_rows(result)), *items,
            f"setup {result['mode']}: {what}, {result['bus_seconds']:.3f} s of bus time"]


def joint_lines(result: dict[str, Any]) -> list[str]:
    """A line a joint: ``elbow_flex: ID 3 at 1000000 baud (XL330-M288), set, verified``."""
    return [f"{r['joint']}: ID {r['to']['id']} at {r['to']['baud']} baud "
            f"({r['to']['model'] or r['to']['protocol']}), {r['status']}"
            + (", verified" if r["verified"] else "") for r in result["joints"]]
