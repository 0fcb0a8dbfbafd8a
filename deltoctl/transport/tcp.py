"""TCP transport: keepalive to notice a pulled cable, NODELAY for small frames, timeouts."""

from __future__ import annotations

import contextlib
import socket
import time

from deltoctl.errors import DeviceError, Unreachable


class LinkLost(DeviceError):
    """The connection dropped or timed out mid-exchange."""


class TcpLink:
    def __init__(self, host: str, port: int, connect_timeout: float = 3.0) -> None:
        self.host, self.port = host, port
        try:
            sock = socket.create_connection((host, port), timeout=connect_timeout)
        except OSError as exc:
            raise Unreachable(
                f"cannot connect to {host}:{port}: {exc.strerror or exc}",
                hint="check that the device is powered, cabled and at that address "
                     "(Delto: developer mode, DIP switches 2 and 4)") from None
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE, 1)
        for name, value in (("TCP_KEEPIDLE", 1), ("TCP_KEEPINTVL", 1), ("TCP_KEEPCNT", 3)):
            if hasattr(socket, name):
                sock.setsockopt(socket.IPPROTO_TCP, getattr(socket, name), value)
        self.sock = sock

    def send(self, data: bytes) -> None:
        try:
            self.sock.sendall(data)
        except OSError as exc:
            raise LinkLost(f"send to {self.host}:{self.port} failed: {exc}") from None

    def recv_exact(self, n: int, timeout: float) -> bytes:
        deadline = time.monotonic() + timeout
        chunks = bytearray()
        while len(chunks) < n:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise LinkLost(f"no reply from {self.host}:{self.port} within {timeout:g} s "
                               f"({len(chunks)} of {n} bytes)")
            self.sock.settimeout(remaining)
            try:
                chunk = self.sock.recv(n - len(chunks))
            except TimeoutError:
                continue
            except OSError as exc:
                raise LinkLost(f"receive from {self.host}:{self.port} failed: {exc}") from None
            if not chunk:
                raise LinkLost(f"{self.host}:{self.port} closed the connection")
            chunks += chunk
        return bytes(chunks)

    def recv_frame(self, timeout: float) -> bytes:
        """One length-prefixed frame (2-byte big-endian total length)."""
        head = self.recv_exact(2, timeout)
        length = (head[0] << 8) | head[1]
        if length < 3:
            raise LinkLost(f"bad frame length {length} from {self.host}:{self.port}")
        return head + self.recv_exact(length - 2, timeout)

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self.sock.close()
