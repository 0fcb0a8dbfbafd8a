"""What ``-v``, ``-vv`` and ``--log-file`` show: the links and lifecycle, and every packet.

Logging goes through the ``deltoctl`` logger: on stderr through rich's handler (``-v`` links
and lifecycle, ``-vv`` every packet too), and as NDJSON lines to ``--log-file`` (or
``DELTOCTL_LOG``), which always gets everything. Never on stdout.

Tracing costs nothing when it is off. Nothing is imported or set up until a command asks
(``configure``), and a transport looks at ``PACKETS`` once, when it opens a link: only then
does it swap in traced methods (``trace_tcp``, ``trace_i2c``). An untraced link runs the
code it always ran, without an ``if`` per packet.

It sits beside ``errors`` rather than in ``core`` so that transports, which import nothing
above them, may call it.
"""

from __future__ import annotations

import time
from typing import Any

PACKETS = False  # trace every packet: -vv or --log-file
_logger: Any = None  # the "deltoctl" logger, once a command asked for logging
_OURS = "_deltoctl_handler"


def configure(verbose: int, log_file: str | None) -> None:
    """Set up (or, with nothing asked, tear down) the handlers of this process's command."""
    global PACKETS, _logger
    import logging

    logger = logging.getLogger("deltoctl")
    for handler in [h for h in logger.handlers if getattr(h, _OURS, False)]:
        logger.removeHandler(handler)
        handler.close()
    PACKETS = verbose >= 2 or bool(log_file)
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
    _logger.getChild("wire").debug("%s %s %4d B %s%s", direction, bus, len(data), extra["hex"],
                                   f"  ({frame})" if frame else "", extra=extra)


def trace_tcp(link_: Any) -> None:
    """Swap a TcpLink's send and recv_frame for traced ones (this link only)."""
    bus = f"{link_.host}:{link_.port}"
    send, recv = link_.send, link_.recv_frame

    def traced_send(data: bytes) -> None:
        packet(bus, "tx", bytes(data))
        send(data)

    def traced_recv(timeout: float) -> bytes:
        frame = recv(timeout)
        packet(bus, "rx", frame)
        return frame

    link_.send, link_.recv_frame = traced_send, traced_recv


def trace_i2c(bus: Any) -> None:
    """Swap an I2CBus's transaction for a traced one: each write message out, then each
    read message's bytes in, named by the device address."""
    run = bus._run

    def traced_run(address: int, *msgs: Any) -> None:
        where = f"{bus.url} @{address:#04x}"
        for m in msgs:
            if not m.flags & 1:  # I2C_M_RD clear: a write
                packet(where, "tx", bytes(m))
        run(address, *msgs)
        for m in msgs:
            if m.flags & 1:
                packet(where, "rx", bytes(m))

    bus._run = traced_run


def trace_serial(port: Any, bus: str) -> None:
    """Swap a pyserial port's write and read for traced ones (this port only); for
    ``serial_port.open_serial`` to call when ``PACKETS`` is set."""
    write, read = port.write, port.read

    def traced_write(data: bytes) -> int | None:
        packet(bus, "tx", bytes(data))
        return write(data)

    def traced_read(size: int = 1) -> bytes:
        data = read(size)
        if data:
            packet(bus, "rx", data)
        return data

    port.write, port.read = traced_write, traced_read
