"""The live view in Foxglove: the topics and CDR bytes a recording has, served over the Foxglove
WebSocket protocol (foxglove-sdk, the optional extra ``deltoctl[foxglove]``).

``McapRecorder`` plans the topics and packs each cycle's messages; here its writer is
``FoxgloveWriter``, which turns each MCAP channel into a Foxglove channel (schema encoding
ros2msg, message encoding cdr) and logs each message with its log time. So Foxglove shows
every topic a recording of the same robot would have, with the same bytes.

``FoxgloveLive`` is the cycle runner's sink: a cycle only keeps a copy of its values, handed
to a thread of its own a few cycles at a time (the loop never waits for the network, and the
two threads hand the interpreter over a few hundred times a second, not at every cycle); that
thread packs and logs them while a client watches. When it falls more than ``QUEUE_CYCLES``
behind, cycles are dropped and counted.

A browser lets any web page open a WebSocket to any address, loopback included, and says
which page in the handshake's ``Origin``: ``OriginGate`` listens on the address people connect
to and passes a client on only when its Origin is Foxglove's own (or one the user names), or
when it sends none (a program, not a page). foxglove-sdk's server cannot filter origins, so it
listens behind the gate on a random loopback address and port no page can guess.
"""

from __future__ import annotations

import contextlib
import ipaddress
import os
import queue
import secrets
import socket
import threading
import time
from types import ModuleType
from typing import Any

from deltoctl.core.runner import Sink
from deltoctl.errors import DeltoctlError, InvalidInput
from deltoctl.profile.model import Profile
from deltoctl.record.mcap_recorder import OK, WARN, McapRecorder

FOXGLOVE_EXTRA = "pip install 'deltoctl[foxglove]'"
QUEUE_CYCLES = 2000  # cycles waiting for the publisher thread: 2 s at 1 kHz
BATCH_NS = 5_000_000  # cycles go to the publisher at least every 5 ms ...
BATCH_CYCLES = 50  # ... and at most 50 at a time (an unpaced loop)
CLOSE_TIMEOUT = 5.0  # s the publisher gets to send what is queued when the loop ends
LOCAL_HOSTS = ("localhost",)
# the Origins Foxglove's own clients send: the web app (and its former address); the desktop
# app, an Electron page loaded from file:// URLs. "null" (a sandboxed frame of any page) is
# not one of them. A client without an Origin is a program and is let in.
FOXGLOVE_ORIGINS = ("https://app.foxglove.dev", "https://studio.foxglove.dev", "file://")
HEAD_LIMIT = 16 * 1024  # bytes of a handshake's request line and headers
HEAD_TIMEOUT = 10.0  # s a client gets to send its handshake
MAX_CLIENTS = 16  # connections passed on at a time


def load_foxglove() -> ModuleType:
    """foxglove-sdk, or one clear message naming the extra."""
    try:
        import foxglove
    except ImportError:
        raise DeltoctlError("--foxglove needs foxglove-sdk, which is not installed",
                            FOXGLOVE_EXTRA) from None
    return foxglove


def is_local(host: str) -> bool:
    """The address is reachable from this machine only (loopback)."""
    if host.lower() in LOCAL_HOSTS:
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def ws_url(host: str, port: int) -> str:
    host = host.strip("[]")
    return f"ws://[{host}]:{port}" if ":" in host else f"ws://{host}:{port}"


class FoxgloveWriter:
    """What ``McapRecorder`` calls on mcap's Writer, done with Foxglove channels of one
    context: schemas and channels become Foxglove channels, messages are logged."""

    def __init__(self, foxglove: ModuleType, context: Any) -> None:
        self.foxglove = foxglove
        self.context = context
        self.schemas: list[Any] = []
        self.channels: list[Any] = []

    def start(self, profile: str = "", library: str = "") -> None:
        """Nothing to start: the server runs already."""

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        self.schemas.append(self.foxglove.Schema(name=name, encoding=encoding, data=bytes(data)))
        return len(self.schemas)  # MCAP's ids: 0 is "no schema"

    def register_channel(self, topic: str, message_encoding: str, schema_id: int,
                         metadata: dict[str, str] | None = None) -> int:
        schema = self.schemas[schema_id - 1] if schema_id else None
        self.channels.append(self.foxglove.Channel(
            topic, message_encoding=message_encoding, schema=schema, context=self.context,
            metadata=dict(metadata or {})))
        return len(self.channels) - 1

    def add_message(self, channel_id: int, log_time: int, data: bytes, publish_time: int = 0,
                    sequence: int = 0) -> None:
        self.channels[channel_id].log(data, log_time=log_time)

    def watched(self) -> bool:
        """A client is subscribed to one of the channels at least."""
        return any(channel.has_sinks() for channel in self.channels)

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """The WebSocket protocol carries no metadata records."""

    def flush(self) -> None:
        """Every message goes out when logged."""

    def finish(self) -> None:
        """The channels end: clients see them unadvertised."""
        for channel in self.channels:
            channel.close()


class FoxgloveLive(Sink):
    """A Foxglove WebSocket server on ``host:port`` (port 0: any free one) and the sink that
    feeds it. Create it before the devices are opened (the extra, the address and the port
    are checked at once), ``begin`` with the robot's profile (the server starts then, with
    every topic there: foxglove-sdk refuses a subscription to a channel created while the
    client connects), then hand it to the cycle runner; as a context manager the server
    stops whatever happens."""

    def __init__(self, host: str = "127.0.0.1", port: int = 8765,
                 queue_cycles: int = QUEUE_CYCLES, origins: tuple[str, ...] = ()) -> None:
        if not 0 <= port <= 65535:
            raise InvalidInput(f"--foxglove-port must be 0-65535, got {port}")
        self.foxglove = load_foxglove()
        self.context = self.foxglove.Context()
        self.gate = OriginGate(host, port, (*FOXGLOVE_ORIGINS, *map(check_origin, origins)))
        self.host, self.port = host, port
        self.server: Any = None
        self.url = ws_url(host, port)
        self.limit = queue_cycles
        self.queue: queue.SimpleQueue[tuple | None] = queue.SimpleQueue()
        self.queued = 0  # cycles handed over (the publisher counts those it took)
        self.taken = 0
        self.batch: list[tuple[int, list[float]]] = []
        self._prioritized = False
        self.keys: list[str] = []
        self.sent = 0  # cycles packed and logged (while a client watched)
        self.dropped = 0  # cycles the publisher was too far behind for
        self._dropping = False
        self.error: str | None = None
        self.recorder: Any = None
        self.thread: threading.Thread | None = None
        self.stopped = False

    def __enter__(self) -> FoxgloveLive:
        return self

    @property
    def local(self) -> bool:
        """Served to this machine only (a loopback address)."""
        return is_local(self.host)

    def summary(self) -> dict[str, Any]:
        """What the live view did, for a verb's JSON: its address, the cycles sent and those
        dropped (it fell behind)."""
        return {"url": self.url, "cycles_sent": self.sent, "cycles_dropped": self.dropped}

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def begin(self, profile: Profile, extra_states: tuple[str, ...] = (),
              gpio_type: str = "group-values", commands: bool = False) -> None:
        """Advertise the robot's topics (as ``McapRecorder`` plans them, with the same
        options) and start the publisher thread."""
        writer = FoxgloveWriter(self.foxglove, self.context)
        self.recorder = McapRecorder(None, profile, {}, extra_states, gpio_type, writer=writer,
                                     commands=commands)
        # /diagnostics comes with the first status: this one, before any client
        self.recorder.diagnostic(time.time_ns(), OK, "foxglove", "live view started", {
            "topics": len(writer.channels) + 1})
        self.server, inner = self._start_behind_gate()
        self.gate.start((inner, self.server.port))
        self.url = ws_url(self.host, self.gate.port)
        self.thread = threading.Thread(target=self._publish, name="deltoctl-foxglove",
                                       daemon=True)
        self.thread.start()

    def _start_behind_gate(self) -> tuple[Any, str]:
        """foxglove-sdk's server and its address: a random loopback one (Linux routes all of
        127/8 to loopback; elsewhere 127.0.0.1) and a free port, reached through the gate."""
        error = ""
        for host in (f"127.{secrets.randbelow(254) + 1}.{secrets.randbelow(256)}."
                     f"{secrets.randbelow(254) + 1}", "127.0.0.1"):
            try:
                return self.foxglove.start_server(name="deltoctl", host=host, port=0,
                                                  context=self.context), host
            except RuntimeError as exc:
                error = str(exc)
        raise InvalidInput(_bind_error("127.0.0.1", 0, error))

    # -- the cycle thread: queue, never wait -------------------------------------------------

    def frame(self, t_ns: int, values: dict[str, float]) -> None:
        if len(values) != len(self.keys):  # the set of interfaces changed (the first cycle)
            if not self._prioritized:
                self._prioritized = True
                self._follow_priority()
            self._hand_over()
            self.keys = list(values)
            self.queue.put(("k", self.keys))
        batch = self.batch
        batch.append((t_ns, list(values.values())))
        if t_ns - batch[0][0] >= BATCH_NS or len(batch) >= BATCH_CYCLES:
            self._hand_over()

    def _follow_priority(self) -> None:
        """On a loop that runs real-time (``core.runner.realtime``), the publisher runs
        real-time too, one step below it: preempted by ordinary processes while it holds the
        interpreter's lock, it would stall the loop for as long (a priority inversion)."""
        if self.thread is None or self.thread.native_id is None:
            return
        with contextlib.suppress(OSError, AttributeError):
            policy = os.sched_getscheduler(0)
            if policy in (os.SCHED_FIFO, os.SCHED_RR):
                priority = max(os.sched_getparam(0).sched_priority - 1, 1)
                os.sched_setscheduler(self.thread.native_id, policy, os.sched_param(priority))

    def _hand_over(self) -> None:
        """The cycles gathered so far to the publisher, or dropped when it is too far behind
        (only this thread writes ``queued``; only the publisher, ``taken``)."""
        batch = self.batch
        if not batch:
            return
        self.batch = []
        if self.queued - self.taken + len(batch) > self.limit:
            self.dropped += len(batch)
            self._dropping = True
            return
        if self._dropping:  # the cycles after a hole in what was sent are no gap of the loop
            self.queue.put(("h",))
            self._dropping = False
        self.queued += len(batch)
        self.queue.put(("v", batch))

    def periodic(self, t_ns: int, stats: Any, comm_loops: list[Any]) -> None:
        statuses = [(OK, "loop", "loop", stats.summary()),
                    *((OK if not c.errors else WARN, c.name, "bus loop", c.report())
                       for c in comm_loops)]
        if self.dropped:
            statuses.append((WARN, "foxglove", "live view behind: cycles not sent",
                             {"dropped": self.dropped}))
        self._hand_over()
        self.queue.put(("d", t_ns, statuses))

    def close(self, stats: Any) -> None:
        """Send what is queued and the loop's final statistics, then stop the server."""
        if self.thread is not None and self.thread.is_alive():
            self._hand_over()
            self.queue.put(("c", stats.summary()))
            self.queue.put(None)
            self.thread.join(CLOSE_TIMEOUT)
        self.stop()

    def stop(self) -> None:
        if self.stopped:
            return
        self.stopped = True
        if self.thread is not None and self.thread.is_alive():
            self.queue.put(None)
        self.gate.stop()
        if self.server is not None:
            self.server.stop()

    # -- the publisher thread ----------------------------------------------------------------

    def _publish(self) -> None:
        """Pack and log each cycle while a client watches (else skip it: nothing to send)."""
        recorder, get, watched = self.recorder, self.queue.get, self.recorder.writer.watched
        try:
            while (item := get()) is not None:
                kind = item[0]
                if kind == "v":
                    if watched():
                        for t_ns, row in item[1]:
                            recorder.write_row(row, t_ns)
                        self.sent += len(item[1])
                    else:
                        recorder.skipped()  # cycles not sent are no gap of the loop
                    self.taken += len(item[1])
                elif kind == "k":
                    recorder.set_keys(item[1])
                elif kind == "h":
                    recorder.skipped()  # dropped cycles: no gap to report
                elif kind == "d":
                    recorder.diagnostics(item[1], item[2])
                elif kind == "c":
                    recorder.close(item[1], time.time_ns())
        except Exception as exc:  # the live view ends; the loop and a recording go on
            self.error = f"{type(exc).__name__}: {exc}"
            with contextlib.suppress(Exception):
                recorder.writer.finish()


def _listen(host: str, port: int) -> socket.socket:
    """A listening socket on the address (port 0: any free one), or one clear message."""
    try:
        infos = socket.getaddrinfo(host.strip("[]"), port, type=socket.SOCK_STREAM)
    except (OSError, UnicodeError) as exc:
        raise InvalidInput(f"--foxglove-host {host}: no such address "
                           f"({getattr(exc, 'strerror', None) or exc})") from None
    family, kind, proto, _, address = infos[0]
    sock = socket.socket(family, kind, proto)
    try:
        if os.name != "nt":  # a port in TIME_WAIT is free
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(address)
        sock.listen(MAX_CLIENTS)
    except OSError as exc:
        sock.close()
        raise InvalidInput(_bind_error(host, port, exc.strerror or str(exc))) from None
    return sock


def check_origin(origin: str) -> str:
    """An origin as a browser sends it: ``scheme://host[:port]``, nothing more (``file://``
    too); a trailing slash is dropped. Anything else is a usage error."""
    from urllib.parse import urlsplit

    text = _normal(origin)
    if text == "file://":
        return text
    try:
        parts = urlsplit(text)
        parts.port  # noqa: B018 - a port that is no number raises here
    except ValueError:
        parts = None
    if (parts is None or not parts.scheme or not parts.hostname or parts.path or parts.query
            or parts.fragment or parts.username is not None):
        raise InvalidInput(f"--foxglove-origin {origin!r}: expected an origin as a browser "
                           "sends it, scheme://host[:port] (e.g. https://app.foxglove.dev)")
    return text


def _normal(origin: str) -> str:
    """An origin as compared: lower case, without a trailing slash (``file://`` whole)."""
    text = origin.strip().lower()
    return "file://" if text in ("file:", "file://", "file:///") else text.rstrip("/")


class OriginGate:
    """The live view's listening socket: each client's WebSocket handshake is read (bounded in
    size and time); one whose ``Origin`` is not accepted gets 403 and is closed, the others are
    passed on, bytes both ways, to the server behind the gate."""

    def __init__(self, host: str, port: int, origins: tuple[str, ...]) -> None:
        self.sock = _listen(host, port)
        self.port = self.sock.getsockname()[1]
        self.origins = frozenset(origins)
        self.inner: tuple[str, int] = ("127.0.0.1", 0)
        self.slots = threading.BoundedSemaphore(MAX_CLIENTS)
        self.open: set[socket.socket] = set()
        self.lock = threading.Lock()
        self.refused = 0  # handshakes refused for their origin

    def start(self, inner: tuple[str, int]) -> None:
        self.inner = inner
        threading.Thread(target=self._accept, name="deltoctl-foxglove-gate", daemon=True).start()

    def stop(self) -> None:
        with contextlib.suppress(OSError):
            self.sock.close()
        with self.lock:
            for conn in self.open:
                with contextlib.suppress(OSError):
                    conn.shutdown(socket.SHUT_RDWR)
                with contextlib.suppress(OSError):
                    conn.close()
            self.open.clear()

    def _accept(self) -> None:
        while True:
            try:
                client, _ = self.sock.accept()
            except OSError:  # stopped
                return
            if not self.slots.acquire(blocking=False):
                _reply(client, "503 Service Unavailable", "too many live view clients",
                       drain=False)  # this thread accepts: it never waits on a client
                continue
            threading.Thread(target=self._serve, args=(client,), daemon=True).start()

    def _serve(self, client: socket.socket) -> None:
        try:
            head = _read_head(client)
            if head is None:
                _reply(client, "400 Bad Request", "expected a WebSocket handshake")
                return
            origin = _origin(head)
            if origin is not None and origin not in self.origins:
                self.refused += 1
                _reply(client, "403 Forbidden", f"origin {origin} is not allowed "
                                                 "(deltoctl --foxglove-origin)")
                return
            self._pass_on(client, head)
        finally:
            self.slots.release()

    def _pass_on(self, client: socket.socket, head: bytes) -> None:
        try:
            server = socket.create_connection(self.inner, timeout=HEAD_TIMEOUT)
        except OSError:
            _reply(client, "502 Bad Gateway", "the live view is not running")
            return
        client.settimeout(None)
        server.settimeout(None)
        for conn in (client, server):
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        with self.lock:
            self.open.update((client, server))
        try:
            server.sendall(head)
            other = threading.Thread(target=_pipe, args=(server, client), daemon=True)
            other.start()
            _pipe(client, server)
            other.join()
        except OSError:
            pass
        finally:
            with self.lock:
                self.open.difference_update((client, server))
            for conn in (client, server):
                with contextlib.suppress(OSError):
                    conn.close()


def _read_head(client: socket.socket) -> bytes | None:
    """The handshake's request line and headers, with any bytes after them (a client may send
    its first frame at once), or None: too long, too slow, or the client left."""
    client.settimeout(HEAD_TIMEOUT)
    data = b""
    try:
        while b"\r\n\r\n" not in data:
            if len(data) > HEAD_LIMIT:
                return None
            chunk = client.recv(4096)
            if not chunk:
                return None
            data += chunk
    except OSError:
        return None
    return data if data.index(b"\r\n\r\n") <= HEAD_LIMIT else None


def _origin(head: bytes) -> str | None:
    """The Origin a handshake names (lower case, as ``check_origin`` keeps them); None when it
    names none. Several, or an old draft's Sec-WebSocket-Origin besides, read as "several":
    never accepted."""
    lines = head.split(b"\r\n\r\n", 1)[0].split(b"\r\n")[1:]
    found = [_normal(value.decode("latin-1"))
             for name, _, value in (line.partition(b":") for line in lines)
             if name.strip().lower() in (b"origin", b"sec-websocket-origin")]
    if not found:
        return None
    return found[0] if len(found) == 1 else "several origins"


def _reply(client: socket.socket, status: str, reason: str, drain: bool = True) -> None:
    """An HTTP answer instead of the handshake, then the connection closed once the client
    has stopped sending (briefly, and boundedly: closed with bytes unread, it would be reset
    before the client read the answer)."""
    body = reason.encode() + b"\n"
    with contextlib.suppress(OSError):
        client.sendall(f"HTTP/1.1 {status}\r\nContent-Type: text/plain\r\nContent-Length: "
                       f"{len(body)}\r\nConnection: close\r\n\r\n".encode() + body)
        client.shutdown(socket.SHUT_WR)
        client.settimeout(1.0)
        drained = 0
        while drain and drained < 4 * HEAD_LIMIT and (chunk := client.recv(4096)):
            drained += len(chunk)
    with contextlib.suppress(OSError):
        client.close()


def _pipe(source: socket.socket, sink: socket.socket) -> None:
    """Bytes from one end to the other until the source ends; then the sink's sending half
    closes (the other direction finishes on its own)."""
    try:
        while data := source.recv(65536):
            sink.sendall(data)
    except OSError:
        pass
    with contextlib.suppress(OSError):
        sink.shutdown(socket.SHUT_WR)


def _bind_error(host: str, port: int, reason: str) -> str:
    reason = reason.removeprefix("FoxgloveError: ")
    if "in use" in reason.lower():
        return (f"--foxglove-port {port}: the port is in use on {host} (another Foxglove "
                "server or deltoctl?): choose another port")
    return f"cannot serve Foxglove on {host}:{port}: {reason}"
