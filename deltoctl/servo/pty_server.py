"""An emulated servo bus behind a pseudo-terminal that pyserial (and so the vendors' SDKs)
opens as a serial port, and its wire pacing: paced, the bus takes the time a real one would at
the baud rate the host set — the request's bytes arrive, each servo waits its return delay,
and its status leaves when its last byte would have crossed the wire (10 bits a byte).

The server is generic over a :class:`Bus`: request bytes in (the bus reads them with its
device session), per request its size and its replies out."""

from __future__ import annotations

import contextlib
import os
import sys
import termios
import threading
import time
import tty
from typing import Protocol

PR_SET_TIMERSLACK = 29  # prctl(2)
PRECISE_MARGIN = 0.0001  # s a paced bus spins before a byte time, its timer slack cut
TCGETS2 = 0x802C542A  # ioctl(2) of struct termios2 on Linux (x86, ARM)
SPEEDS = {getattr(termios, name): int(name[1:]) for name in dir(termios)
          if name[:1] == "B" and name[1:].isdigit()}  # termios speed code → baud

Replies = list[tuple[float, bytes]]  # per status: the servo's return delay (s), its bytes


class Bus(Protocol):
    """What the server serves. ``baud``: the rate the servos listen at (None: any);
    ``line_baud``: the rate the host set on the line, told by the server."""

    baud: int | None
    line_baud: int | None

    def serve(self, data: bytes) -> list[tuple[int, Replies]]:
        """The requests in the bytes heard, each as (its bytes on the wire, its replies)."""
        ...


def wait_until(deadline: float, margin: float = 0.0002) -> None:
    """Sleep to ``margin`` before the deadline, then spin: byte-time precision. The spin
    yields the CPU at each turn, so a host on a small machine is not starved by its devices;
    a thread whose sleeps overshoot less (``precise_timers``) can sleep closer."""
    while True:
        left = deadline - time.perf_counter()
        if left <= 0:
            return
        if left > margin + 0.0001:
            time.sleep(left - margin)
        else:
            os.sched_yield()


def precise_timers() -> bool:
    """The calling thread's timer slack cut from Linux's default 50 µs to 1 ns, so that its
    sleeps end at their time, within the wake-up latency, instead of up to 50 µs after it
    (a sleep of ``wait_until`` then leaves its spin the margin it counts on, even on a busy
    machine). Returns whether it took (False elsewhere than on Linux)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        import ctypes

        return ctypes.CDLL(None, use_errno=True).prctl(PR_SET_TIMERSLACK, 1, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def line_rate(fd: int) -> int | None:
    """The rate the host set on a pseudo-terminal: a standard speed's, or one set as any
    number (pyserial's for 250,000 or 2,250,000), read back with Linux's TCGETS2."""
    rate = SPEEDS.get(termios.tcgetattr(fd)[5])
    if rate is not None or not sys.platform.startswith("linux"):
        return rate
    import array
    import fcntl

    attrs = array.array("i", [0] * 64)
    try:
        fcntl.ioctl(fd, TCGETS2, attrs)
    except OSError:
        return None
    return attrs[10] or None  # struct termios2's c_ospeed


class PtyServer:
    """Serves a bus on a pseudo-terminal; ``port`` is the path a serial client opens.
    ``latency``: seconds each reply is held before the host sees it, as a USB adapter's
    latency timer holds a short packet (an FTDI's: 16 ms unless set)."""

    def __init__(self, bus: Bus, pace: bool = False, name: str = "servo-bus",
                 latency: float = 0.0) -> None:
        self.bus = bus
        self.pace = pace
        self.latency = latency
        self.master, self.slave = os.openpty()
        tty.setraw(self.master)
        tty.setraw(self.slave)
        self.port = os.ttyname(self.slave)
        self._stop = threading.Event()
        self._margin = 0.0002  # s spun before each byte time (the default timer slack's)
        self._thread = threading.Thread(target=self._serve, name=name, daemon=True)

    def start(self) -> PtyServer:
        self._thread.start()
        return self

    def _serve(self) -> None:
        import select

        if self.pace:
            if precise_timers():  # this thread's: it sleeps to its byte times, spins less
                self._margin = PRECISE_MARGIN
            os.set_blocking(self.master, False)
        while not self._stop.is_set():
            data = self._spin_read() if self.pace else b""
            if not data:
                if not select.select([self.master], [], [], 0.1)[0]:
                    continue
                try:
                    data = os.read(self.master, 4096)
                except BlockingIOError:
                    continue
                except OSError:
                    return
            arrived = time.perf_counter()
            if self.bus.baud is not None or self.pace:  # the rate the host set on the pty
                self.bus.line_baud = line_rate(self.master)
            for size, replies in self.bus.serve(data):
                if self.pace and self.bus.line_baud:
                    self._paced(arrived, size, replies)
                elif replies:
                    if self.latency:
                        time.sleep(self.latency)
                    os.write(self.master, b"".join(packet for _, packet in replies))

    def _spin_read(self, spin: float = 0.002) -> bytes:
        """Paced, the bus watches the line like a UART: no wake-up delay for the next
        request within ``spin`` seconds of the last one."""
        end = time.perf_counter() + spin
        while time.perf_counter() < end:
            try:
                return os.read(self.master, 4096)
            except BlockingIOError:
                os.sched_yield()
                continue
            except OSError:
                break
        return b""

    def _paced(self, arrived: float, sent: int, replies: Replies) -> None:
        byte_time = 10.0 / (self.bus.line_baud or 1)
        t = arrived + sent * byte_time  # the request's last byte is in
        for delay, packet in replies:
            t += delay + len(packet) * byte_time
            wait_until(t, self._margin)
            os.write(self.master, packet)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=1)
        for fd in (self.master, self.slave):
            with contextlib.suppress(OSError):
                os.close(fd)

    def __enter__(self) -> PtyServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()
