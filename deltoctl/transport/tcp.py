"""TCP transport: keepalive to notice a pulled cable, NODELAY for small frames, timeouts."""

from __future__ import annotations

import contextlib
import socket
import time

from deltoctl import trace
from deltoctl.errors import DeviceError, InvalidInput, Unreachable
from deltoctl.transport import Check, Target, Transport, split_url

DEFAULT_PORT = 502  # Modbus TCP's, which a Delto's developer mode keeps


def parse_tcp_url(url: str, default_port: int = DEFAULT_PORT) -> tuple[str, int]:
    """``tcp://HOST[:PORT]`` → (host, port); anything else in it (a query key, a path, a
    port out of range) is an error naming it, never silently dropped."""
    from urllib.parse import parse_qsl

    parts = split_url(url)
    if parts.scheme != "tcp" or not parts.hostname:
        raise InvalidInput(f"{url!r} is not a TCP target (expected tcp://HOST:PORT)")
    keys = [key for key, _ in parse_qsl(parts.query, keep_blank_values=True)]
    if keys:
        raise InvalidInput(f"{url!r}: unknown key {keys[0]!r} (a tcp:// target takes no keys)")
    if parts.path not in ("", "/") or parts.fragment or parts.username is not None:
        raise InvalidInput(f"{url!r}: expected tcp://HOST:PORT and nothing else")
    try:
        port = parts.port
    except ValueError:
        port = -1
    if port is not None and not 0 < port < 65536:
        raise InvalidInput(f"{url!r}: the port must be a number from 1 to 65535")
    _check_host(url, parts.hostname)
    return parts.hostname, port or default_port


def _check_host(url: str, host: str) -> None:
    """A dotted-number host must be an IPv4 address (169.254.186.720 is a typo, not a name)."""
    import ipaddress

    if ":" in host or not host.replace(".", "").isdigit():
        return
    try:
        ipaddress.IPv4Address(host)
    except ValueError:
        raise InvalidInput(f"{url!r}: {host} is not an IPv4 address") from None


class LinkLost(DeviceError):
    """The connection dropped or timed out mid-exchange."""


class TcpLink:
    def __init__(self, host: str, port: int, connect_timeout: float = 3.0) -> None:
        self.host, self.port = host, port
        started = time.perf_counter()
        try:
            sock = socket.create_connection((host, port), timeout=connect_timeout)
        except OSError as exc:
            trace.link("tcp %s:%d: cannot connect: %s", host, port, exc.strerror or exc)
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
        trace.link("tcp %s:%d: connected in %.1f ms", host, port,
                   (time.perf_counter() - started) * 1e3)
        if trace.PACKETS:  # checked once per link: an untraced link's methods stay as they are
            trace.trace_tcp(self)

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
        trace.link("tcp %s:%d: closed", self.host, self.port)
        with contextlib.suppress(OSError):
            self.sock.close()


def _open(url: str, timeout: float = 3.0) -> TcpLink:
    host, port = parse_tcp_url(url)
    return TcpLink(host, port, connect_timeout=timeout)


def _checks(target: Target) -> list[Check]:
    """A route from this host (a link-local device needs a link-local address here too),
    and a connection the device accepts."""
    from deltoctl.transport.doctor import reach, route

    host, port = parse_tcp_url(target.url)
    return [route(target.bus, host, port), reach(target, host, port)]


def _trace_label(url: str, address: int | None) -> str:
    host, port = parse_tcp_url(url)
    return f"{host}:{port}"


TRANSPORT = Transport("tcp", "tcp://HOST:PORT", parse_tcp_url, _open, _checks,
                      trace_label=_trace_label)
