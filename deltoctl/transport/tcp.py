"""TCP transport: keepalive to notice a pulled cable, NODELAY for small frames, timeouts.

It moves bytes and knows no framing: a family's protocol session frames what it receives."""

from __future__ import annotations

import contextlib
import select
import socket
import time

from deltoctl import trace
from deltoctl.errors import InvalidInput, LinkLost, Unreachable
from deltoctl.transport import Check, Target, Transport, split_url

__all__ = ["TRANSPORT", "LinkLost", "TcpLink", "parse_tcp_url", "tcp_transport"]


def parse_tcp_url(url: str, default_port: int | None = None) -> tuple[str, int]:
    """``tcp://HOST[:PORT]`` → (host, port), the port ``default_port`` (the caller's: its
    device's) when the URL has none; anything else in it (a query key, a path, a port out of
    range, no port and no default) is an error naming it, never silently dropped."""
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
    port = port or default_port
    if port is None:
        raise InvalidInput(f"{url!r}: no port (expected tcp://HOST:PORT)")
    return parts.hostname, port


def _check_host(url: str, host: str) -> None:
    """A dotted-number host must be an IPv4 address (169.254.186.720 is a typo, not a name)."""
    import ipaddress

    if ":" in host or not host.replace(".", "").isdigit():
        return
    try:
        ipaddress.IPv4Address(host)
    except ValueError:
        raise InvalidInput(f"{url!r}: {host} is not an IPv4 address") from None


class TcpLink:
    """A connection in non-blocking mode: a send or a receive is one system call when the
    socket is ready, as it nearly always is, and a wait is one poll() bounded by the
    caller's timeout (a socket with a timeout would poll() before every call)."""

    def __init__(self, host: str, port: int, connect_timeout: float = 3.0) -> None:
        self.host, self.port = host, port
        started = time.perf_counter()
        try:
            sock = socket.create_connection((host, port), timeout=connect_timeout)
        except OSError as exc:
            trace.link("tcp %s:%d: cannot connect: %s", host, port, exc.strerror or exc)
            raise Unreachable(
                f"cannot connect to {host}:{port}: {exc.strerror or exc}",
                hint="check that the device is powered, cabled and at that address") from None
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE, 1)
        for name, value in (("TCP_KEEPIDLE", 1), ("TCP_KEEPINTVL", 1), ("TCP_KEEPCNT", 3)):
            if hasattr(socket, name):
                sock.setsockopt(socket.IPPROTO_TCP, getattr(socket, name), value)
        sock.setblocking(False)
        self.sock = sock
        self._readable, self._writable = select.poll(), select.poll()
        self._readable.register(sock, select.POLLIN)
        self._writable.register(sock, select.POLLOUT)
        self._timeout = connect_timeout  # a send's, should it wait: the last receive's
        trace.link("tcp %s:%d: connected in %.1f ms", host, port,
                   (time.perf_counter() - started) * 1e3)
        if trace.PACKETS:  # checked once per link: an untraced link's methods stay as they are
            trace.trace_tcp(self)

    def send(self, data: bytes) -> None:
        """The frame in one call; the rest, should the socket's buffer be full, as it drains."""
        try:
            sent = self.sock.send(data)
        except BlockingIOError:
            sent = 0
        except OSError as exc:
            raise LinkLost(f"send to {self.host}:{self.port} failed: {exc}") from None
        if sent < len(data):
            self._send_rest(memoryview(data)[sent:])

    def _send_rest(self, rest: memoryview) -> None:
        deadline = time.monotonic() + self._timeout
        while rest:
            if not self._wait(self._writable, deadline):
                raise LinkLost(f"send to {self.host}:{self.port} failed: timed out")
            try:
                rest = rest[self.sock.send(rest):]
            except BlockingIOError:
                continue
            except OSError as exc:
                raise LinkLost(f"send to {self.host}:{self.port} failed: {exc}") from None

    def recv_into(self, buffer: memoryview | bytearray, timeout: float) -> int:
        """What has arrived, into ``buffer``: usually one recv_into, after a poll() when
        nothing has arrived yet. 0: nothing within ``timeout`` seconds."""
        self._timeout = timeout
        deadline = None
        while True:
            try:
                received = self.sock.recv_into(buffer)
            except BlockingIOError:
                if deadline is None:
                    deadline = time.monotonic() + timeout
                if not self._wait(self._readable, deadline):
                    return 0
                continue
            except OSError as exc:
                raise LinkLost(f"receive from {self.host}:{self.port} failed: {exc}") from None
            if not received:
                raise LinkLost(f"{self.host}:{self.port} closed the connection")
            return received

    def _wait(self, poller: select.poll, deadline: float) -> bool:
        """Until the socket is ready as ``poller`` asks, or (False) the deadline passes."""
        remaining = deadline - time.monotonic()
        return remaining > 0 and bool(poller.poll(remaining * 1000))

    def close(self) -> None:
        trace.link("tcp %s:%d: closed", self.host, self.port)
        with contextlib.suppress(OSError):
            self.sock.close()


def tcp_transport(default_port: int | None = None) -> Transport:
    """The ``tcp://`` transport, a URL without a port meaning ``default_port`` (its caller's
    device's; None: the port is required)."""

    def parse(url: str) -> tuple[str, int]:
        return parse_tcp_url(url, default_port)

    def open_link(url: str, timeout: float = 3.0) -> TcpLink:
        host, port = parse(url)
        return TcpLink(host, port, connect_timeout=timeout)

    def checks(target: Target) -> list[Check]:
        """A route from this host (a link-local device needs a link-local address here
        too), and a connection the device accepts."""
        from deltoctl.transport.doctor import reach, route

        host, port = parse(target.url)
        return [route(target.bus, host, port), reach(target, host, port)]

    def trace_label(url: str, address: int | None) -> str:
        host, port = parse(url)
        return f"{host}:{port}"

    return Transport("tcp", "tcp://HOST:PORT", parse, open_link, checks,
                     trace_label=trace_label)


# doctor's and the trace's, by scheme: a URL without a port means Modbus TCP's registered
# port, as it does to a device driver on plain TCP (which passes its own default)
TRANSPORT = tcp_transport(502)
