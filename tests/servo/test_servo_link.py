"""The kit end to end: a host session over the serial link, through pyserial and the kit's
pseudo-terminal server, to a bus of checksum-frame servos behind a device session — replies,
a silent servo, tries by the exchange policy, a lost port reopened, and pacing."""

from __future__ import annotations

import os
import time

import pytest

from deltoctl.core.exchange import ExchangePolicy
from deltoctl.errors import NoAnswer
from deltoctl.servo.frames import checksum
from deltoctl.servo.pty_server import PtyServer, Replies
from deltoctl.servo.serial_io import SerialLink
from deltoctl.servo.session import DEVICE, HOST, Instructions, Session

PING, READ, SYNC_READ = 0x01, 0x02, 0x82
RULES = Instructions(ping=PING, read=READ, ping_length=0,
                     answered_at=(frozenset({PING, READ}), None), sync_read=SYNC_READ)


class CounterBus:
    """Servos whose every byte of table reads as its ID plus its address."""

    baud: int | None = None
    line_baud: int | None = None

    def __init__(self, ids: list[int]) -> None:
        self.ids = ids
        self.session = Session(checksum.FRAMES, RULES, DEVICE)

    def serve(self, data: bytes) -> list[tuple[int, Replies]]:
        out = []
        for request in self.session.receive_requests(data):
            expect = self.session.expected(request.id, request.instruction, request.params)
            address = request.params[0] if request.params else 0
            replies = [(0.0, self.session.reply(i, 0, bytes(
                (i + address + k) & 0xFF for k in range(length or 0))))
                for i, length in zip(expect.ids, expect.lengths) if i in self.ids]
            out.append((request.size, replies))
        return out


@pytest.fixture
def bus():
    with PtyServer(CounterBus([1, 2, 3]), pace=False) as server:
        yield server


def link_to(server: PtyServer, **policy) -> tuple[SerialLink, Session]:
    link = SerialLink(f"serial://{server.port}?baud=1000000",
                      ExchangePolicy(**{"timeout": 0.05, **policy}), {})
    link.open()
    return link, Session(checksum.FRAMES, RULES, HOST)


def test_replies_through_the_pty_and_a_silent_servo(bus):
    link, session = link_to(bus)
    try:
        done = link.exchange(session, 2, READ, bytes([10, 3]))
        assert done.replies == [(2, 0, bytes([12, 13, 14]))]
        done = link.exchange(session, 0xFE, SYNC_READ, bytes([20, 2, 3, 7, 1]))
        assert done.replies == [(3, 0, bytes([23, 24])), (1, 0, bytes([21, 22]))]
        assert done.missing == [7]
    finally:
        link.close()


def test_tries_by_the_policy_then_no_answer(bus):
    link, session = link_to(bus, tries=4)
    try:
        assert link.request(session, 1, PING, b"", "ping servo 1") == (1, 0, b"")
        with pytest.raises(NoAnswer, match=r"no valid reply to ping servo 9 \(4 tries\)"):
            link.request(session, 9, PING, b"", "ping servo 9")
        assert link.stats == {"packets": 5, "errors": 4, "reconnects": 0}
    finally:
        link.close()


def test_a_lost_port_is_reopened_one_period_later(bus):
    link, session = link_to(bus, reopen_period=0.05)
    try:
        link.lost()
        assert link.port is None and not link.reopen()  # not yet
        time.sleep(0.06)
        assert link.reopen() and link.stats["reconnects"] == 1
        assert link.exchange(session, 3, PING).replies == [(3, 0, b"")]
    finally:
        link.close()


def test_a_paced_bus_takes_the_wire_time():
    with PtyServer(CounterBus([1, 2, 3]), pace=True) as server:
        link, session = link_to(server, timeout=0.5)
        try:
            link.port.baudrate = 9600  # about 1 ms a byte
            request = bytes([20, 4, 1, 2, 3])
            started = time.perf_counter()
            done = link.exchange(session, 0xFE, SYNC_READ, request)
            took = time.perf_counter() - started
            assert len(done.replies) == 3
            wire = len(checksum.frame(0xFE, SYNC_READ, request)) + 3 * checksum.FRAMES.status_size(4)
            assert took >= wire * 10 / 9600
        finally:
            link.close()


def test_the_sync_loops_read_slow_in_full_and_leave_the_fast_one_on_the_wire(bus):
    from deltoctl.core.loop import CommLoop
    from deltoctl.servo.sync_loops import SyncLoops, SyncRead

    link, session = link_to(bus)
    taken: dict[str, list] = {"slow": [], "fast": []}
    lost: list[Exception] = []
    loops = SyncLoops(link, session, SYNC_READ, lost.append)
    slow, fast = CommLoop("slow", 0.001), CommLoop("fast", 0.0)  # once a ~17 min; every cycle
    loops.add(SyncRead(slow, 40, 1, taken["slow"].extend))
    loops.add(SyncRead(fast, 10, 2, taken["fast"].extend))
    try:
        loops.start([1, 2, 3])
        assert taken["slow"] == [(1, 0, b"\x29"), (2, 0, b"\x2a"), (3, 0, b"\x2b")]
        assert loops.pending and taken["fast"] == []  # sent, its replies on their way
        loops.finish()
        assert [r[0] for r in taken["fast"]] == [1, 2, 3] and not loops.pending
        loops.start([1, 2, 9])  # the slow loop is not due; servo 9 is silent
        loops.finish()
        assert len(taken["slow"]) == 3 and [r[0] for r in taken["fast"][3:]] == [1, 2]
        assert (fast.total_packets, fast.total_errors, slow.total_packets) == (2, 1, 1)
        assert link.stats == {"packets": 3, "errors": 1, "reconnects": 0}
        os.close(link.port.fd)  # the adapter goes away
        loops.start([1, 2, 3])
        assert lost and not loops.pending
    finally:
        link.close()


def test_a_lost_port_raises_link_lost_not_attribute_errors(bus):
    from deltoctl.errors import LinkLost

    link, session = link_to(bus)
    try:
        os.close(link.port.fd)  # the adapter goes away under an open port
        with pytest.raises(LinkLost):
            link.exchange(session, 1, PING)
        link.lost()
        for call in (lambda: link.write(b"\x00"), link.flush,
                     lambda: link.collect(session, 0.01),
                     lambda: link.request(session, 1, READ, bytes([0, 1]), "read 1")):
            with pytest.raises(LinkLost, match="not open"):
                call()
    finally:
        link.close()


@pytest.mark.parametrize("baud", [57_600, 250_000, 2_250_000])
def test_the_server_hears_the_rate_the_host_set_standard_or_not(baud):
    """A rate with no termios speed of its own (250,000; 2,250,000) is set as a number:
    the bus is told it, not None (a servo at another rate would otherwise answer it)."""
    import serial

    from deltoctl.servo.pty_server import line_rate

    with PtyServer(CounterBus([1])) as server:
        port = serial.Serial(server.port, 9_600)
        try:
            port.baudrate = baud
            assert line_rate(server.master) == baud
        finally:
            port.close()
