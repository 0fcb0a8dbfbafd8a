"""The toy link, ``toy://HOST:PORT``: a TCP stream of one-letter requests. A transport of the
toy family's own, registered through the ``deltoctl.transports`` entry point (or
``registry.register_transport``): its URL parsing, its link and what ``doctor`` checks."""

from __future__ import annotations

import socket

from deltoctl.errors import DeviceError, InvalidInput, Unreachable
from deltoctl.transport import Check, Target, Transport, split_url


def parse_toy_url(url: str) -> tuple[str, int]:
    parts = split_url(url)
    try:
        port = parts.port
    except ValueError:
        port = None
    if parts.scheme != "toy" or not parts.hostname or not port or parts.path not in ("", "/") \
            or parts.query:
        raise InvalidInput(f"{url!r} is not a toy target (expected toy://HOST:PORT)")
    return parts.hostname, port


class ToyLink:
    def __init__(self, host: str, port: int, timeout: float) -> None:
        try:
            self.sock = socket.create_connection((host, port), timeout=timeout)
        except OSError as exc:
            raise Unreachable(f"cannot reach the toy at {host}:{port}: "
                              f"{exc.strerror or exc}") from None

    def ask(self, request: bytes, size: int) -> bytes:
        """Send a request, receive exactly ``size`` bytes of reply."""
        try:
            self.sock.sendall(request)
            data = b""
            while len(data) < size:
                chunk = self.sock.recv(size - len(data))
                if not chunk:
                    raise OSError("the toy closed the connection")
                data += chunk
        except OSError as exc:
            raise DeviceError(f"toy link: {exc}") from None
        return data

    def close(self) -> None:
        self.sock.close()


def _open(url: str, timeout: float = 1.0) -> ToyLink:
    return ToyLink(*parse_toy_url(url), timeout)


def _checks(target: Target) -> list[Check]:
    from deltoctl.transport.doctor import reach

    host, port = parse_toy_url(target.url)
    return [reach(target, host, port)]


TRANSPORT = Transport("toy", "toy://HOST:PORT", parse_toy_url, _open, _checks)
