"""``config`` for people: what a snapshot holds per block, the items that differ, and what a
restore did to each; and a servo's control table items (``register get``)."""

from __future__ import annotations

from typing import Any

from deltoctl.render.identity import Table
from deltoctl.units import shown_value as show


def snapshot_table(live: dict[str, dict[str, Any]]) -> Table:
    """One row per block of a snapshot: its family, target, parts and items."""
    return (None, ["block", "family", "target", "parts", "items"],
            [[name, b["family"], b["target"] or "in-process", len(b["parts"]),
              sum(len(items) for items in b["parts"].values())] for name, b in live.items()])


def diff_table(rows: list[dict[str, Any]], column: str) -> Table:
    """The items that differ: the snapshot's value against ``column``'s (live, other)."""
    return (None, ["block", "part", "item", "snapshot", column, "unit"],
            [[r["block"], r["part"], r["item"], show(r["snapshot"]), show(r[column]),
              r["unit"] or ""] for r in rows])


def restore_parts(rows: list[dict[str, Any]], counts: dict[str, int],
                  snapshot: str) -> list[Any]:
    """What a restore did to each item, and how many of each status; or that nothing
    differed."""
    if not rows:
        return [f"nothing to restore: the devices match {snapshot}"]
    return [(None, ["block", "part", "item", "snapshot", "live", "status", "note"],
             [[r["block"], r["part"], r["item"], show(r["snapshot"]), show(r["live"]),
               r["status"], r["note"]] for r in rows]),
            ", ".join(f"{n} {status}" for status, n in counts.items())]


def register_table(joint: str, result: dict[str, Any]) -> Table:
    """The control table items read from a servo, with their addresses and access."""
    return (f"{joint} (ID {result['id']})", ["address", "item", "value", "access"],
            [[i["address"], i["item"], i["value"], i["access"]] for i in result["items"]])
