"""The toy device: a TCP server per block whose joints swing as sines (or, with the
``frozen`` fault, stand still), with a period that can be read and written."""

from __future__ import annotations

import math
import socketserver
import struct
import threading
import time
from typing import Any


class _Handler(socketserver.BaseRequestHandler):
    def handle(self) -> None:
        server: Any = self.server
        while True:
            request = self.request.recv(1)
            if not request:
                return
            if request == b"I":
                self.request.sendall(b"toy 1.0\n")
            elif request == b"C":
                self.request.sendall(struct.pack("<d", server.period))
            elif request == b"W":
                server.period = struct.unpack("<d", self.request.recv(8))[0]
                self.request.sendall(b"K")
            else:
                t = 0.0 if server.frozen else time.monotonic() * 2 * math.pi / server.period
                self.request.sendall(struct.pack(
                    f"<{server.joints}d",
                    *(0.0 if server.frozen else math.sin(t + j) for j in range(server.joints))))


def serve(ctx: Any, blocks: list[Any]) -> dict[str, str]:
    buses = {}
    for hw in blocks:
        server: Any = socketserver.ThreadingTCPServer((ctx.options.host, 0), _Handler)
        server.daemon_threads = True
        server.joints = len(hw.joints)
        server.period = 2.0
        server.frozen = ctx.options.frozen  # its declared fault (tests/toyfamily/__init__.py)
        threading.Thread(target=server.serve_forever, daemon=True).start()
        ctx.stack.callback(server.server_close)
        ctx.stack.callback(server.shutdown)
        host, port = server.server_address[:2]
        buses[hw.bus] = f"toy://{host}:{port}"
    return buses
