"""What ``deltoctl setup`` reports, whichever family's parts it set up: the outcome (each
joint's row, the writes in order, the bus time), a row from where a part was found to where
the profile wants it, and the row marked verified once the part answers there."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from deltoctl.errors import DeviceError


@dataclass
class Outcome:
    """What setup did (or, dry, would do): each joint's row, the writes in order."""

    mode: str
    dry_run: bool
    joints: list[dict[str, Any]] = field(default_factory=list)
    steps: list[dict[str, Any]] = field(default_factory=list)
    bus_seconds: float = 0.0

    def as_dict(self) -> dict[str, Any]:
        return {"mode": self.mode, "dry_run": self.dry_run, "joints": self.joints,
                "steps": self.steps, "bus_seconds": round(self.bus_seconds, 3)}


def step(joint: str, action: str, at_id: int | None, at_baud: int,
         value: Any = None) -> dict[str, Any]:
    """One write: to the part at ``at_id`` (None: a part with no address yet), ``at_baud``."""
    return {"joint": joint, "action": action, "at_id": at_id, "at_baud": at_baud,
            "value": value}


def row(w: Any, part: dict[str, Any] | None, status: str) -> dict[str, Any]:
    """A joint's row: ``w`` as the profile wants it (a Wanted or a LinkJoint), ``part`` as
    found (its serial too, where the family names parts by one)."""
    found = None if part is None else {k: part[k] for k in ("id", "baud", "protocol", "model")}
    if found is not None and part.get("serial") is not None:
        found["serial"] = part["serial"]
    return {"joint": w.joint, "block": w.block, "from": found,
            "to": {"id": w.id, "baud": w.baud, "protocol": w.protocol, "model": w.model},
            "status": status, "verified": False}


def verified(row: dict[str, Any], w: Any, model: str | None, was: str) -> None:
    """The row marked verified, or DeviceError when the part does not answer at its new ID
    and rate as the model it was."""
    if model is None:
        raise DeviceError(f"{w.joint}: no answer at ID {w.id}, {w.baud} baud after the writes",
                          hint=f"scan the bus (deltoctl scan) to see where it went, then run "
                               f"setup {w.joint} again with it alone")
    if model != was:
        raise DeviceError(f"{w.joint}: a {model} answers at ID {w.id}, {w.baud} baud, not "
                          f"the {was} written to")
    row["status"] = "set" if (row["from"]["id"], row["from"]["baud"]) != (w.id, w.baud) \
        else "already set"
    row["verified"] = True
