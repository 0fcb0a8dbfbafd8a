"""The toy driver: ``I`` → a version line; ``R`` → one little-endian double per joint."""

from __future__ import annotations

import socket
import struct
from urllib.parse import urlsplit

from deltoctl.core.driver import Driver
from deltoctl.errors import Unreachable


class ToyDriver(Driver):
    sock: socket.socket | None = None

    def configure(self) -> None:
        parts = urlsplit(self.url)
        try:
            self.sock = socket.create_connection((parts.hostname, parts.port), timeout=1.0)
        except OSError as exc:
            raise Unreachable(f"{self.hw.name}: cannot reach {self.url}: {exc}") from None
        self.sock.sendall(b"I")
        self.version = self.sock.recv(64).decode().strip()
        self.connected = True

    def read(self) -> dict[str, float]:
        assert self.sock is not None
        n = len(self.hw.joints)
        self.sock.sendall(b"R")
        data = b""
        while len(data) < 8 * n:
            data += self.sock.recv(8 * n - len(data))
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

    def cleanup(self) -> None:
        if self.sock is not None:
            self.sock.close()
            self.sock = None
