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
"""

from __future__ import annotations

import contextlib
import ipaddress
import os
import queue
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
                 queue_cycles: int = QUEUE_CYCLES) -> None:
        if not 0 <= port <= 65535:
            raise InvalidInput(f"--foxglove-port must be 0-65535, got {port}")
        self.foxglove = load_foxglove()
        self.context = self.foxglove.Context()
        _check_port(host, port)
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
        try:
            self.server = self.foxglove.start_server(
                name="deltoctl", host=self.host, port=self.port, context=self.context)
        except RuntimeError as exc:  # taken since the check
            raise InvalidInput(_bind_error(self.host, self.port, str(exc))) from None
        self.url = ws_url(self.host, self.server.port)
        self.thread = threading.Thread(target=self._publish, name="deltoctl-foxglove",
                                       daemon=True)
        self.thread.start()

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


def _check_port(host: str, port: int) -> None:
    """The address resolves and the port is free (0: any free one will do)."""
    import socket

    try:
        infos = socket.getaddrinfo(host.strip("[]"), port, type=socket.SOCK_STREAM)
    except (OSError, UnicodeError) as exc:
        raise InvalidInput(f"--foxglove-host {host}: no such address "
                           f"({getattr(exc, 'strerror', None) or exc})") from None
    if not port:
        return
    family, kind, proto, _, address = infos[0]
    with socket.socket(family, kind, proto) as probe:
        if os.name != "nt":  # as the server binds: a port in TIME_WAIT is free
            probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind(address)
        except OSError as exc:
            raise InvalidInput(_bind_error(host, port, exc.strerror or str(exc))) from None


def _bind_error(host: str, port: int, reason: str) -> str:
    reason = reason.removeprefix("FoxgloveError: ")
    if "in use" in reason.lower():
        return (f"--foxglove-port {port}: the port is in use on {host} (another Foxglove "
                "server or deltoctl?): choose another port")
    return f"cannot serve Foxglove on {host}:{port}: {reason}"
