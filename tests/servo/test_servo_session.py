"""The session as a host/device pair with no transport, for both frame variants: the host's
request goes to the device session, whose requests the test's servos answer as the device
session's rules say, and their bytes go back to the host in pieces — who answers what
(Status Return Level, broadcast, sync, fast sync and bulk reads), matched by ID, in noise."""

from __future__ import annotations

import struct

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from deltoctl.errors import ProtocolError
from deltoctl.servo.frames import checksum, dxl2
from deltoctl.servo.session import (
    ANY,
    DEVICE,
    FAST,
    HOST,
    NEED_DATA,
    Done,
    Instructions,
    NeedData,
    Session,
)

PING, READ, WRITE, SYNC_READ, FAST_SYNC_READ, BULK_READ = 0x01, 0x02, 0x03, 0x82, 0x8A, 0x92
# Protocol 2.0: level 0 answers a PING, 1 a READ too, 2 everything; a PING's data: 3 bytes
PROTOCOL_2 = Instructions(ping=PING, read=READ, ping_length=3,
                          answered_at=(frozenset({PING}), frozenset({PING, READ}), None),
                          sync_read=SYNC_READ, fast_sync_read=FAST_SYNC_READ,
                          bulk_read=BULK_READ)
# a checksum-frame bus as Feetech's: level 0 answers a PING and a READ, 1 everything; a
# PING's status has no data; one-byte addresses
CHECKSUM = Instructions(ping=PING, read=READ, ping_length=0,
                        answered_at=(frozenset({PING, READ}), None), sync_read=SYNC_READ)
VARIANTS = {"protocol 2.0": (dxl2.FRAMES, PROTOCOL_2), "checksum": (checksum.FRAMES, CHECKSUM)}


def data_of(device_id: int, length: int) -> bytes:
    return bytes((device_id + k) & 0xFF for k in range(length))


class Bus:
    """Servos by ID at their Status Return Levels, behind a device session."""

    def __init__(self, frames, instructions, levels: dict[int, int]) -> None:
        self.session = Session(frames, instructions, DEVICE)
        self.levels = levels
        self.heard: list = []

    def answer(self, data: bytes) -> bytes:
        out = b""
        for request in self.session.receive_requests(data):
            self.heard.append(request)
            ids = self.session.addressed(request, self.levels)
            expect = self.session.expected(request.id, request.instruction, request.params)
            if expect.kind == FAST:
                blocks = [(0, i, data_of(i, expect.lengths[0])) for i in ids]
                out += self.session.frames.combined(blocks) if blocks else b""
                continue
            for i in ids or [i for i in self.levels if i == request.id]:
                if self.session.answers(request, i, self.levels[i]):
                    length = expect.lengths[0] if expect.kind == ANY else \
                        dict(zip(expect.ids, expect.lengths)).get(i)
                    out += self.session.reply(i, 0, data_of(i, length or 0))
        return out


def converse(host: Session, bus: Bus, device_id: int, instruction: int, params: bytes = b"",
             piece: int = 5, noise: bytes = b"") -> tuple[Done | None, list]:
    """The host's request through the bus; the replies back ``piece`` bytes at a time:
    (Done, or None when the host expected nothing), and the events before it."""
    replies = noise + bus.answer(noise + host.send(device_id, instruction, params))
    if not host.expecting:
        assert replies == b""
        return None, []
    events = [host.receive(replies[k:k + piece]) for k in range(0, len(replies), piece)]
    done = events[-1] if events and isinstance(events[-1], Done) else host.give_up()
    return done, events[:-1]


def params(frames, *values: int) -> bytes:
    size = frames.address_size
    return b"".join(v.to_bytes(size, "little") for v in values)


@pytest.fixture(params=sorted(VARIANTS))
def pair(request):
    frames, instructions = VARIANTS[request.param]
    return frames, Session(frames, instructions, HOST), \
        Bus(frames, instructions, {1: instructions.top_level, 2: instructions.top_level,
                                   3: instructions.top_level})


def test_a_read_is_answered_by_its_servo_with_its_length(pair):
    frames, host, bus = pair
    done, events = converse(host, bus, 2, READ, params(frames, 56, 4))
    assert done.replies == [(2, 0, data_of(2, 4))] and done.complete and not done.missing
    assert events and all(e is NEED_DATA for e in events)  # until the last piece
    assert host.expected_bytes == frames.status_size(4)
    assert bus.heard[-1].size == frames.request_size(len(params(frames, 56, 4)))


def test_a_ping_and_a_broadcast_ping(pair):
    frames, host, bus = pair
    length = host.instructions.ping_length
    done, _ = converse(host, bus, 3, PING)
    assert done.replies == [(3, 0, data_of(3, length))]
    done, events = converse(host, bus, frames.broadcast_id, PING)
    # every servo answers, in ID order; how many there are the host cannot know: it takes
    # them until its time is up
    assert all(e is NEED_DATA for e in events) and done.expected == []
    assert [r[0] for r in done.replies] == [1, 2, 3] and done.complete


def test_a_broadcast_write_is_answered_by_none(pair):
    frames, host, bus = pair
    done, _ = converse(host, bus, frames.broadcast_id, WRITE, params(frames, 64) + b"\x01")
    assert done is None and bus.heard[-1].instruction == WRITE


@pytest.mark.parametrize("variant", sorted(VARIANTS))
def test_status_return_levels(variant):
    frames, instructions = VARIANTS[variant]
    top = instructions.top_level
    for level in range(top + 1):
        host = Session(frames, instructions, HOST, level=level)
        bus = Bus(frames, instructions, {5: level})
        answered = instructions.answered_at[level]
        for instruction, body in ((PING, b""), (READ, params(frames, 56, 2)),
                                  (WRITE, params(frames, 65) + b"\x01")):
            done, _ = converse(host, bus, 5, instruction, body)
            says = answered is None or instruction in answered or instruction == PING
            assert (done is not None) == says, (level, instruction)
            if done is not None:
                assert [r[0] for r in done.replies] == [5]
    # Protocol 2.0's three levels and a Feetech-style bus's two
    assert top == {"protocol 2.0": 2, "checksum": 1}[variant]


def test_a_sync_read_gets_one_status_per_id_in_order(pair):
    frames, host, bus = pair
    done, events = converse(host, bus, frames.broadcast_id, SYNC_READ,
                            params(frames, 56, 4) + bytes([3, 1, 2]), piece=7)
    assert done.replies == [(i, 0, data_of(i, 4)) for i in (3, 1, 2)]
    assert len(events) > 2 and host.expected_bytes == 3 * frames.status_size(4)


def test_a_servo_missing_from_a_sync_read_is_waited_for_then_named(pair):
    frames, host, bus = pair
    done, events = converse(host, bus, frames.broadcast_id, SYNC_READ,
                            params(frames, 56, 2) + bytes([1, 9, 2]))
    assert events[-1] is NEED_DATA and host.waiting == [9]
    assert [r[0] for r in done.replies] == [1, 2] and done.missing == [9]
    assert not done.complete


def test_replies_in_noise_and_a_corrupted_one(pair):
    frames, host, bus = pair
    request = host.send(frames.broadcast_id, SYNC_READ, params(frames, 56, 2) + bytes([1, 2, 3]))
    replies = bytearray(bus.answer(request))
    replies[frames.status_size(2) + 5] ^= 0x40  # servo 2's data: its check fails
    noisy = b"\x00\xff\x13" + bytes(replies)
    assert host.receive(noisy) is NEED_DATA and host.waiting == [2]
    done = host.give_up()
    assert [r[0] for r in done.replies] == [1, 3] and done.missing == [2]


def test_a_reply_from_another_id_or_of_another_length_is_no_match(pair):
    frames, host, _ = pair
    host.send(2, READ, params(frames, 56, 4))
    assert host.receive(frames.status(1, 0, data_of(1, 4))) is NEED_DATA  # another servo
    assert host.receive(frames.status(2, 0, data_of(2, 3))) is NEED_DATA  # 3 bytes, not 4
    done = host.receive(frames.status(2, 0x04, b""))  # an error needs no data
    assert done.replies == [(2, 0x04, b"")]


def test_a_refused_read_is_done_as_soon_as_its_short_status_is_in(pair):
    frames, host, _ = pair
    host.send(2, READ, params(frames, 56, 4))
    done = host.receive(frames.status(2, 0x07, b""))  # no wait for the 4 bytes never sent
    assert isinstance(done, Done) and done.replies == [(2, 0x07, b"")]


def test_the_device_reads_requests_in_noise_and_skips_a_corrupted_one(pair):
    frames, host, bus = pair
    first = host.send(1, READ, params(frames, 56, 2))
    bad = bytearray(host.send(2, READ, params(frames, 56, 2)))
    bad[-1] ^= 0x55
    last = host.send(3, PING)
    requests = bus.session.receive_requests(b"\xff\x00" + first + bytes(bad) + last)
    assert [(r.id, r.instruction) for r in requests] == [(1, READ), (3, PING)]
    assert bus.session.garbled == 1


def test_protocol_2_fast_sync_and_bulk_reads():
    frames, instructions = VARIANTS["protocol 2.0"]
    host = Session(frames, instructions, HOST)
    bus = Bus(frames, instructions, {1: 2, 2: 2, 3: 2})
    done, _ = converse(host, bus, frames.broadcast_id, FAST_SYNC_READ,
                       struct.pack("<HH", 132, 4) + bytes([2, 3]), piece=4)
    assert done.replies == [(2, 0, data_of(2, 4)), (3, 0, data_of(3, 4))]
    assert host.expected_bytes == 8 + 2 * (4 + 4)  # one status: 7 bytes less per servo
    bulk = struct.pack("<BHH", 3, 132, 4) + struct.pack("<BHH", 1, 126, 10)
    done, _ = converse(host, bus, frames.broadcast_id, BULK_READ, bulk, piece=9)
    assert done.replies == [(3, 0, data_of(3, 4)), (1, 0, data_of(1, 10))]
    assert done.complete


def test_a_sync_read_sent_again_is_built_once():
    frames, instructions = VARIANTS["protocol 2.0"]
    host = Session(frames, instructions, HOST)
    body = struct.pack("<HH", 126, 10) + bytes([1, 2])
    assert host.send(0xFE, SYNC_READ, body) is host.send(0xFE, SYNC_READ, body)


def test_each_role_receives_its_own():
    frames, instructions = VARIANTS["checksum"]
    with pytest.raises(ProtocolError, match="receive_requests"):
        Session(frames, instructions, DEVICE).receive(b"")
    with pytest.raises(ProtocolError, match="receives replies"):
        Session(frames, instructions, HOST).receive_requests(b"")
    with pytest.raises(ValueError, match="role"):
        Session(frames, instructions, "servo")


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.sampled_from(sorted(VARIANTS)), st.dictionaries(st.integers(0, 20), st.integers(0, 2),
                                                           min_size=1, max_size=6),
       st.lists(st.integers(0, 24), min_size=1, max_size=8, unique=True), st.integers(0, 6),
       st.integers(1, 40))
def test_host_and_device_agree_on_who_answers(variant, servos, asked, length, piece):
    frames, instructions = VARIANTS[variant]
    levels = {i: min(level, instructions.top_level) for i, level in servos.items()}
    host, bus = Session(frames, instructions, HOST), Bus(frames, instructions, levels)
    done, _ = converse(host, bus, frames.broadcast_id, SYNC_READ,
                       params(frames, 56, length) + bytes(asked), piece=piece)
    assert done.replies == [(i, 0, data_of(i, length)) for i in asked if i in levels]
    assert done.missing == [i for i in asked if i not in levels]
    for device_id in asked[:3]:
        level = levels.get(device_id)
        host.level = instructions.top_level if level is None else level
        done, _ = converse(host, bus, device_id, WRITE, params(frames, 65) + b"\x01")
        if done is not None:  # the host waits for what the servo's level says it sends
            assert [r[0] for r in done.replies] == ([device_id] if level is not None else [])


@settings(max_examples=200, deadline=None)
@given(st.sampled_from(sorted(VARIANTS)), st.binary(max_size=80), st.integers(1, 30))
def test_any_bytes_are_events_or_requests(variant, data, piece):
    frames, instructions = VARIANTS[variant]
    host = Session(frames, instructions, HOST)
    host.send(frames.broadcast_id, SYNC_READ, params(frames, 56, 2) + bytes([1, 2]))
    for k in range(0, len(data), piece):
        assert isinstance(host.receive(data[k:k + piece]), (NeedData, Done))
    done = host.give_up()
    assert {r[0] for r in done.replies} <= {1, 2} and all(len(r[2]) == 2 for r in done.replies)
    device = Session(frames, instructions, DEVICE)
    assert all(r.size >= frames.request_size(0) for r in device.receive_requests(data))
