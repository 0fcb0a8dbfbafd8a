"""The toy driver: ``I`` → a version line; ``R`` → one little-endian double per joint; ``C``
→ the pendulums' period; ``W`` + a double → a new period (the swing restarts), ``K``."""

from __future__ import annotations

import struct
from typing import Any

from deltoctl import registry
from deltoctl.core.driver import Driver
from deltoctl.errors import Refused

REWIND = "toy-rewind"  # the permission a new period needs (declared in the descriptor)


class ToyDriver(Driver):
    link: Any = None

    def configure(self) -> None:
        self.link = registry.open_link(self.url)  # whatever link its URL names
        self.version = self.link.ask(b"I", 8).decode().strip()
        self.connected = True

    def read(self) -> dict[str, float]:
        n = len(self.hw.joints)
        data = self.link.ask(b"R", 8 * n)
        self.stats["packets"] += 1
        for joint, value in zip(self.hw.joints, struct.unpack(f"<{n}d", data)):
            self.values[f"{joint.name}/position"] = value
        return self.values

    def identify(self) -> dict:
        return {"version": self.version, "joints": len(self.hw.joints)}

    def detect(self) -> dict:
        return {"checks": [{"what": "joints", "profile": len(self.hw.joints),
                            "device": len(self.hw.joints), "match": True}],
                "summary": f"{self.hw.name}: {self.version}"}

    def _period(self) -> float:
        return float(struct.unpack("<d", self.link.ask(b"C", 8))[0])

    def config_read(self) -> dict[str, dict[str, dict[str, Any]]]:
        return {"pendulums": {"period": {"value": self._period(), "unit": "s", "access": "RW",
                                         "needs": REWIND}}}

    def config_write(self, changes: dict[str, dict[str, Any]],
                     allow: frozenset[str] = frozenset()) -> dict[str, dict[str, Any]]:
        if REWIND not in allow:
            raise Refused(f"{self.hw.name}: a new period restarts the swing",
                          hint=f"pass --allow {REWIND}")
        period = changes.get("pendulums", {}).get("period")
        if period is not None:
            self.link.ask(b"W" + struct.pack("<d", float(period)), 1)
        return {"pendulums": {"period": self._period()}}

    def cleanup(self) -> None:
        if self.link is not None:
            self.link.close()
            self.link = None
