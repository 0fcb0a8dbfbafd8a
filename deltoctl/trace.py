"""What ``-v``, ``-vv`` and ``--log-file`` show: the links and lifecycle, and every packet.

Logging goes through the ``deltoctl`` logger: on stderr through rich's handler (``-v`` links
and lifecycle, ``-vv`` every packet too), and as NDJSON lines to ``--log-file`` (or
``DELTOCTL_LOG``), which always gets everything. Never on stdout.

Tracing costs nothing when it is off. Nothing is imported or set up until a command asks
(``configure``), and a transport looks at ``PACKETS`` once, when it opens a link: only then
does it swap in traced methods (``trace_tcp``, ``trace_i2c``). An untraced link runs the
code it always ran, without an ``if`` per packet.

Each traced frame is named by its family's codec (``GET_DATA``, ``SYNC_READ``, ``PING`` …):
the System tells ``name_frames`` which namer serves each link (and each device address on an
I2C bus), so this module names no family.

It sits beside ``errors`` rather than in ``core`` so that transports, which import nothing
above them, may call it.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from typing import Any

PACKETS = False  # trace every packet: -vv or --log-file
_logger: Any = None  # the "deltoctl" logger, once a command asked for logging
_OURS = "_deltoctl_handler"
FrameNamer = Callable[[bytes], "str | None"]
# a link's label in the trace (host:port, a serial URL, "i2c URL @0x11") → its frames' namer
_namers: dict[str, FrameNamer] = {}


def configure(verbose: int, log_file: str | None) -> None:
    """Set up (or, with nothing asked, tear down) the handlers of this process's command."""
    global PACKETS, _logger
    import logging

    logger = logging.getLogger("deltoctl")
    for handler in [h for h in logger.handlers if getattr(h, _OURS, False)]:
        logger.removeHandler(handler)
        handler.close()
    PACKETS = verbose >= 2 or bool(log_file)
    _namers.clear()
    if not (verbose or log_file):
        logger.setLevel(logging.NOTSET)
        logger.propagate = True
        _logger = None
        return
    logger.setLevel(logging.DEBUG)
    logger.propagate = False
    if verbose:
        _add(logger, _console_handler(logging.INFO if verbose == 1 else logging.DEBUG))
    if log_file:
        _add(logger, _file_handler(log_file))
    _logger = logger


def _add(logger: Any, handler: Any) -> None:
    setattr(handler, _OURS, True)
    logger.addHandler(handler)


def _console_handler(level: int) -> Any:
    from rich.console import Console
    from rich.logging import RichHandler

    handler = RichHandler(console=Console(stderr=True), show_path=False, markup=False,
                          log_time_format="%H:%M:%S.%f")
    handler.setLevel(level)
    return handler


def _file_handler(path: str) -> Any:
    import logging

    from deltoctl.errors import InvalidInput

    try:
        handler = logging.FileHandler(path, encoding="utf-8")
    except OSError as exc:
        raise InvalidInput(f"--log-file {path}: {exc.strerror}") from None
    handler.setFormatter(_NdjsonFormatter())
    handler.setLevel(logging.DEBUG)
    return handler


class _NdjsonFormatter:
    """One JSON object a line: t (ns since the epoch), level, logger, msg, and a packet's
    fields (dir, bus, len, hex, frame) when it is one."""

    FIELDS = ("dir", "bus", "len", "hex", "frame", "block", "transition", "state")

    def format(self, record: Any) -> str:
        import json

        line = {"t": getattr(record, "t_ns", int(record.created * 1e9)),
                "level": record.levelname.lower(), "logger": record.name,
                "msg": record.getMessage()}
        line.update({k: getattr(record, k) for k in self.FIELDS if hasattr(record, k)})
        return json.dumps(line, separators=(",", ":"))


# -- hooks: each is a no-op until configure() set a logger up ---------------------------------

def link(message: str, *args: Any) -> None:
    """A link opened, closed or lost (-v)."""
    if _logger is not None:
        _logger.getChild("link").info(message, *args)


def lifecycle(block: str, transition: str, state: str) -> None:
    """A block's lifecycle transition (-v)."""
    if _logger is not None:
        _logger.getChild("lifecycle").info("%s: %s → %s", block, transition, state,
                                           extra={"block": block, "transition": transition,
                                                  "state": state})


def packet(bus: str, direction: str, data: bytes, frame: str | None = None) -> None:
    """One packet (-vv): direction tx or rx, the bus (host:port, the I2C URL …), its bytes."""
    if _logger is None:
        return
    extra = {"t_ns": time.time_ns(), "dir": direction, "bus": bus, "len": len(data),
             "hex": data.hex(" ")}
    if frame:
        extra["frame"] = frame
    # the name before the bytes: a long frame's hex wraps, its name stays in sight
    _logger.getChild("wire").debug("%s %s %4d B %s%s", direction, bus, len(data),
                                   f"{frame}: " if frame else "", extra["hex"], extra=extra)


def name_frames(url: str, namer: FrameNamer | None, addresses: Iterable[int] = (),
                label: Callable[[str, int | None], str] | None = None) -> None:
    """Name the frames traced on the link to ``url`` with ``namer`` (a family codec's
    ``frame_name``); on an I2C bus, those of the devices at ``addresses`` only (several
    families may share one bus). ``label``: how the link's transport labels its packets
    (host:port, a device on a shared bus …; None: the URL)."""
    if not PACKETS or namer is None:
        return
    for address in list(addresses) or [None]:
        _namers[label(url, address) if label else url] = namer


def _name(bus: str, data: bytes) -> str | None:
    """The frame's name, when its link has a namer and the namer knows the frame; a namer
    that fails on odd bytes names nothing (the trace never breaks a command)."""
    namer = _namers.get(bus)
    if namer is None:
        return None
    try:
        return namer(data)
    except Exception:
        return None


def trace_tcp(link_: Any) -> None:
    """Swap a TcpLink's send and recv_into for traced ones (this link only): each send, and
    the bytes of each receive (a frame, as a rule: a protocol's replies come one at a time)."""
    bus = f"{link_.host}:{link_.port}"
    send, recv_into = link_.send, link_.recv_into

    def traced_send(data: bytes) -> None:
        packet(bus, "tx", bytes(data), _name(bus, bytes(data)))
        send(data)

    def traced_recv_into(buffer: Any, timeout: float) -> int:
        count = recv_into(buffer, timeout)
        if count:
            data = bytes(buffer[:count])
            packet(bus, "rx", data, _name(bus, data))
        return count

    link_.send, link_.recv_into = traced_send, traced_recv_into


def trace_i2c(bus: Any) -> None:
    """Swap an I2CBus's transaction for a traced one: each write message out, then each
    read message's bytes in, labelled by the device address; a reply is named after the
    command written before it."""
    run = bus._run

    def traced_run(address: int, *msgs: Any) -> None:
        where = f"{bus.url} @{address:#04x}"  # as the I2C transport's trace_label
        name = None
        for m in msgs:
            if not m.flags & 1:  # I2C_M_RD clear: a write
                name = _name(where, bytes(m))
                packet(where, "tx", bytes(m), name)
        run(address, *msgs)
        for m in msgs:
            if m.flags & 1:
                packet(where, "rx", bytes(m), name and f"{name} reply")

    bus._run = traced_run


def trace_serial(port: Any, bus: str) -> None:
    """Swap a pyserial port's write and read for traced ones (this port only); for
    ``serial_port.open_serial`` to call when ``PACKETS`` is set."""
    write, read = port.write, port.read

    def traced_write(data: bytes) -> int | None:
        packet(bus, "tx", bytes(data), _name(bus, bytes(data)))
        return write(data)

    def traced_read(size: int = 1) -> bytes:
        data = read(size)
        if data:
            packet(bus, "rx", data, _name(bus, data))
        return data

    port.write, port.read = traced_write, traced_read
