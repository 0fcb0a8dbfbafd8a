"""A CAN bus between processes of this machine, and nothing else: the local hub.

The emulated drives and deltoctl meet on a hub that listens on a loopback address only; every
frame a member sends (a 16-byte record, ``codec.encode``) reaches every other member, as on a
CAN bus. ``HubBus`` is its python-can interface (entry point ``can.interface``: ``localhub``),
so canopen, deltoctl and any python-can program open it as ``can.Bus(interface="localhub",
channel="127.0.0.1:PORT")``.

Why not python-can's ``udp_multicast``: it sends to a multicast group through the default
route unless the host is set up otherwise (a route for the group on ``lo``, or a network
namespace), which needs root; a frame of a test could reach a network. A hub that only binds
and connects to loopback addresses cannot: both ends refuse any other address.
"""

from __future__ import annotations

import contextlib
import ipaddress
import select
import selectors
import socket
import threading
import time
from typing import Any

import can

from deltoctl_canopen import codec

MAX_MEMBERS = 64
BACKLOG_BYTES = 1 << 20  # a member that reads nothing is dropped past this much queued


def loopback_address(channel: str) -> tuple[str, int]:
    """``HOST:PORT`` of a hub, whose host must be a loopback address (ValueError if not)."""
    host, sep, port = channel.rpartition(":")
    host = host.strip("[]")
    try:
        address = ipaddress.ip_address(host)
        number = int(port)
    except ValueError:
        raise ValueError(f"a local hub is HOST:PORT on a loopback address, got {channel!r}") \
            from None
    if not sep or not address.is_loopback or not 0 <= number <= 65535:
        raise ValueError(f"a local hub listens on a loopback address (127.0.0.1, ::1) only, "
                         f"got {channel!r}")
    return host, number


class HubServer:
    """The bus itself: accepts members on a loopback address, repeats each frame to the
    others. ``with HubServer() as hub: hub.channel``."""

    def __init__(self, host: str = "127.0.0.1", port: int = 0) -> None:
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        loopback_address(f"{host}:{port}")
        self._listener = socket.socket(family, socket.SOCK_STREAM)
        self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._listener.bind((host, port))
        self._listener.listen(16)
        self._listener.setblocking(False)
        self.host, self.port = host, self._listener.getsockname()[1]
        self._selector = selectors.DefaultSelector()
        self._selector.register(self._listener, selectors.EVENT_READ)
        self._members: dict[socket.socket, bytearray] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="can-hub", daemon=True)
        self.frames = 0

    @property
    def channel(self) -> str:
        return f"[{self.host}]:{self.port}" if ":" in self.host else f"{self.host}:{self.port}"

    def start(self) -> HubServer:
        self._thread.start()
        return self

    def _run(self) -> None:
        while not self._stop.is_set():
            for key, _ in self._selector.select(0.1):
                if key.fileobj is self._listener:
                    self._accept()
                else:
                    self._receive(key.fileobj)  # type: ignore[arg-type]

    def _accept(self) -> None:
        with contextlib.suppress(BlockingIOError):
            conn, _ = self._listener.accept()
            if len(self._members) >= MAX_MEMBERS:
                conn.close()
                return
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._members[conn] = bytearray()
            self._selector.register(conn, selectors.EVENT_READ)

    def _receive(self, conn: socket.socket) -> None:
        try:
            data = conn.recv(65536)
        except OSError:
            data = b""
        if not data:
            self._drop(conn)
            return
        pending = self._members[conn]
        pending += data
        whole = len(pending) - len(pending) % codec.RECORD_SIZE
        if not whole:
            return
        chunk = bytes(pending[:whole])
        del pending[:whole]
        self.frames += whole // codec.RECORD_SIZE
        for other in list(self._members):
            if other is not conn:
                self._forward(other, chunk)

    def _forward(self, conn: socket.socket, chunk: bytes) -> None:
        try:
            conn.settimeout(0.5)  # a member that reads nothing must not stall the bus
            conn.sendall(chunk)
        except OSError:
            self._drop(conn)

    def _drop(self, conn: socket.socket) -> None:
        if conn in self._members:
            del self._members[conn]
            with contextlib.suppress(KeyError, ValueError):
                self._selector.unregister(conn)
            conn.close()

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=1)
        for conn in list(self._members):
            self._drop(conn)
        self._selector.close()
        self._listener.close()

    def __enter__(self) -> HubServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()


class HubBus(can.BusABC):
    """A member of a local hub, as a python-can bus."""

    def __init__(self, channel: Any = None, **kwargs: Any) -> None:
        try:
            host, port = loopback_address(str(channel))
        except ValueError as exc:
            raise can.CanInitializationError(str(exc)) from None
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self._sock = socket.socket(family, socket.SOCK_STREAM)
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        try:
            self._sock.settimeout(2.0)
            self._sock.connect((host, port))
            self._sock.settimeout(None)
        except OSError as exc:
            self._sock.close()
            raise can.CanInitializationError(
                f"no local CAN hub at {channel}: {exc.strerror or exc}") from None
        self._buffer = bytearray()
        self._send_lock = threading.Lock()
        self.channel_info = f"local hub {channel}"
        super().__init__(channel=channel, **kwargs)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        deadline = None if timeout is None else time.monotonic() + timeout
        while len(self._buffer) < codec.RECORD_SIZE:
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            try:  # the socket stays blocking for send: wait here, then read what came
                if not select.select([self._sock], [], [], left)[0]:
                    return None, False
                data = self._sock.recv(65536)
            except (ValueError, OSError) as exc:
                raise can.CanOperationError(f"local CAN hub lost: {exc}") from None
            if not data:
                raise can.CanOperationError("local CAN hub closed")
            self._buffer += data
        record = bytes(self._buffer[:codec.RECORD_SIZE])
        del self._buffer[:codec.RECORD_SIZE]
        try:
            frame = codec.decode(record)
        except Exception:  # a bad record is dropped, as a controller drops a bad frame
            return None, False
        msg = can.Message(timestamp=time.time(), arbitration_id=frame.can_id, data=frame.data,
                          is_extended_id=frame.extended, is_remote_frame=frame.remote,
                          dlc=len(frame.data), channel=self.channel_info)
        return msg, False

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        try:
            record = codec.encode(codec.Frame(msg.arbitration_id, bytes(msg.data),
                                              msg.is_extended_id, msg.is_remote_frame))
        except ValueError as exc:
            raise can.CanOperationError(str(exc)) from None
        with self._send_lock:
            try:
                self._sock.sendall(record)
            except OSError as exc:
                raise can.CanOperationError(f"local CAN hub lost: {exc}") from None

    def shutdown(self) -> None:
        super().shutdown()
        with contextlib.suppress(OSError):
            self._sock.shutdown(socket.SHUT_RDWR)
        self._sock.close()
