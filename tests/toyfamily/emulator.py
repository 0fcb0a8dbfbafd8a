"""The toy device: a TCP server per block whose joints swing as sines."""

from __future__ import annotations

import math
import socketserver
import struct
import threading
import time
from typing import Any


class _Handler(socketserver.BaseRequestHandler):
    def handle(self) -> None:
        joints: int = self.server.joints  # type: ignore[attr-defined]
        while True:
            request = self.request.recv(1)
            if not request:
                return
            if request == b"I":
                self.request.sendall(b"toy 1.0\n")
            else:
                t = time.monotonic()
                self.request.sendall(struct.pack(f"<{joints}d",
                                                 *(math.sin(t + j) for j in range(joints))))


def serve(ctx: Any, blocks: list[Any]) -> dict[str, str]:
    buses = {}
    for hw in blocks:
        server = socketserver.ThreadingTCPServer((ctx.options.host, 0), _Handler)
        server.daemon_threads = True
        server.joints = len(hw.joints)  # type: ignore[attr-defined]
        threading.Thread(target=server.serve_forever, daemon=True).start()
        ctx.stack.callback(server.server_close)
        ctx.stack.callback(server.shutdown)
        host, port = server.server_address[:2]
        buses[hw.bus] = f"toy://{host}:{port}"
    return buses
