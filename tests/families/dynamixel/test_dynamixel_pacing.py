"""The paced bus emulator keeps to the wire: no reply byte reaches the host before the wire
would have delivered it, whatever the timers of the machine do."""

from __future__ import annotations

import os
import select
import sys
import termios
import threading
import time
import tty

import pytest

from deltoctl.families.dynamixel import codec
from deltoctl.families.dynamixel.emulator import DynamixelBus, DynamixelPtyServer, Servo
from deltoctl.families.dynamixel.models import by_number
from deltoctl.servo.pty_server import precise_timers, wait_until

MIXED = [1020] * 5 + [1200] * 2  # five XM430-W350 and two XL330-M288
linux = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="prctl(2) is Linux's")


def _open_raw(path: str, baud: int) -> int:
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
    tty.setraw(fd)
    attrs = termios.tcgetattr(fd)
    attrs[4] = attrs[5] = getattr(termios, f"B{baud}")
    termios.tcsetattr(fd, termios.TCSANOW, attrs)
    return fd


@pytest.mark.parametrize("baud", [1_000_000, 4_000_000])
def test_a_paced_reply_never_reaches_the_host_before_the_wire_would_deliver_it(baud):
    """Every chunk of the replies to a sync read of a mixed bus arrives no sooner than the
    instruction's bytes, then every reply byte up to the chunk's last, take at 10 bits a
    byte. Timed from just before the write: the emulator serves from a thread of this
    process, and the GIL it holds between its reads may keep this thread from reading the
    clock after the write returns; before it, a wait only ever adds to the time."""
    ids = list(range(1, len(MIXED) + 1))
    servos = [Servo(i, model=by_number(n)) for i, n in zip(ids, MIXED)]
    for servo in servos:
        servo.set("Return Delay Time", 0)
    instruction = codec.sync_read(126, 10, ids)
    expected = len(ids) * 21
    byte = 10 / baud
    with DynamixelPtyServer(DynamixelBus(servos), pace=True) as server:
        fd = _open_raw(server.port, baud)
        poll = select.poll()
        poll.register(fd, select.POLLIN)
        try:
            for _ in range(30):
                sent = time.perf_counter()
                os.write(fd, instruction)
                got, arrivals = b"", []
                while len(got) < expected and poll.poll(1000):
                    got += os.read(fd, 4096)
                    arrivals.append((time.perf_counter() - sent, len(got)))
                assert len(codec.SyncReplies(10, ids).result(got)) == len(ids)
                for took, count in arrivals:
                    assert took >= (len(instruction) + count) * byte
                time.sleep(0.001)
        finally:
            os.close(fd)


@pytest.mark.parametrize("margin", [0.0002, 0.0001, 0.0])
def test_wait_until_never_returns_before_its_deadline(margin):
    for delay in (0.0, 0.00005, 0.0002, 0.0007):
        deadline = time.perf_counter() + delay
        wait_until(deadline, margin)
        assert time.perf_counter() >= deadline


@linux
def test_precise_timers_cut_the_timer_slack_of_the_calling_thread_only():
    import ctypes

    prctl = ctypes.CDLL(None).prctl
    get_slack = 30  # PR_GET_TIMERSLACK
    before = prctl(get_slack, 0, 0, 0, 0)
    seen = {}

    def serve() -> None:
        seen["took"] = precise_timers()
        seen["slack"] = prctl(get_slack, 0, 0, 0, 0)

    thread = threading.Thread(target=serve)
    thread.start()
    thread.join()
    assert seen == {"took": True, "slack": 1}  # 1 ns
    assert prctl(get_slack, 0, 0, 0, 0) == before  # the host's threads keep their own
