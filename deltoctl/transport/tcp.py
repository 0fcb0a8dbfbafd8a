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
        self._pending = bytearray()
        self._timeout: float | None = None

    def send(self, data: bytes) -> None:
        try:
            self.sock.sendall(data)
        except OSError as exc:
            raise LinkLost(f"send to {self.host}:{self.port} failed: {exc}") from None

    def recv_frame(self, timeout: float) -> bytes:
        """One frame prefixed by its 2-byte big-endian total length; usually one recv call."""
        buf = self._pending
        deadline = None
        while True:
            if len(buf) >= 2:
                length = (buf[0] << 8) | buf[1]
                if length < 3:
                    raise LinkLost(f"bad frame length {length} from {self.host}:{self.port}")
                if len(buf) >= length:
                    frame = bytes(buf[:length])
                    del buf[:length]
                    return frame
            if deadline is None:
                deadline = time.monotonic() + timeout
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise LinkLost(f"no complete reply from {self.host}:{self.port} within "
                               f"{timeout:g} s ({len(buf)} bytes received)")
            if timeout != self._timeout:  # a syscall: only when the timeout changes
                self.sock.settimeout(timeout)
                self._timeout = timeout
            try:
                chunk = self.sock.recv(65536)
            except TimeoutError:
                continue
            except OSError as exc:
                raise LinkLost(f"receive from {self.host}:{self.port} failed: {exc}") from None
            if not chunk:
                raise LinkLost(f"{self.host}:{self.port} closed the connection")
            buf += chunk

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self.sock.close()
