"""The kit's frame variants: the checksum frame of Dynamixel Protocol 1.0 and Feetech against
the byte examples of feetech-sts-and-lerobot.md §1.5, its reader in noise, and round trips
of both variants however the bytes are split."""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from deltoctl.errors import ProtocolError
from deltoctl.servo.frames import checksum, dxl2

quick = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@pytest.mark.parametrize("device_id,code,params,wire", [
    (1, 0x01, b"", "FF FF 01 02 01 FB"),  # PING ID 1
    (0xFE, 0x01, b"", "FF FF FE 02 01 FE"),  # broadcast PING
    (1, 0x02, bytes([0x38, 2]), "FF FF 01 04 02 38 02 BE"),  # READ Present_Position
    (1, 0x03, bytes([0x2A, 0x00, 0x08]), "FF FF 01 05 03 2A 00 08 C4"),  # WRITE 2048 (LE)
    (1, 0x03, bytes([0x37, 0x00]), "FF FF 01 04 03 37 00 C0"),  # WRITE Lock = 0
    (0xFE, 0x82, bytes([0x38, 2, 1, 2, 3, 4, 5, 6]), "FF FF FE 0A 82 38 02 01 02 03 04 05 06 26"),
    (0xFE, 0x83, bytes([0x2A, 2, 1, 0, 8, 2, 0, 4]), "FF FF FE 0A 83 2A 02 01 00 08 02 00 04 39"),
    (1, 0x03, bytes([0x2A, 0x02, 0x00]), "FF FF 01 05 03 2A 02 00 CA"),  # SCS, big-endian
])
def test_checksum_requests_are_the_reference_bytes(device_id, code, params, wire):
    packet = checksum.frame(device_id, code, params)
    assert packet == bytes.fromhex(wire)
    assert checksum.ChecksumReader().feed(packet) == [(device_id, code, params)]


@pytest.mark.parametrize("error,data,wire", [
    (0, b"", "FF FF 01 02 00 FC"),  # ping OK
    (0, bytes([0x00, 0x08]), "FF FF 01 04 00 00 08 F2"),  # read 2048
    (0x20, bytes([0x00, 0x08]), "FF FF 01 04 20 00 08 D2"),  # the same, overload bit set
])
def test_checksum_statuses_are_the_reference_bytes(error, data, wire):
    assert checksum.status(1, error, data) == bytes.fromhex(wire)
    assert checksum.split_statuses(bytes.fromhex(wire)) == [(1, error, data)]
    assert checksum.as_status((1, error, data)) == (1, error, data)


def test_the_checksum_reader_resynchronises_on_noise():
    ping, status = checksum.frame(1, 1), checksum.status(2, 0, b"\x07")
    reader = checksum.ChecksumReader()
    # a stray FF, an FF FF FF run, and a header whose length is out of bounds
    stream = b"\x00\xff" + b"\xff\xff\xff" + ping[2:] + b"\xff\xff\x05\xff" + status
    got = []
    for k in range(0, len(stream), 3):  # as it arrives
        got += reader.feed(stream[k:k + 3])
    assert got == [(1, 1, b""), (2, 0, b"\x07")]


def test_a_bad_checksum_costs_only_its_frame():
    good, bad = checksum.status(3, 0, b"\x01\x02"), bytearray(checksum.status(4, 0, b"\x09"))
    bad[-1] ^= 0xFF
    reader = checksum.ChecksumReader()
    with pytest.raises(ProtocolError, match="checksum mismatch in a frame from ID 4"):
        reader.feed(bytes(bad) + good)
    assert reader.feed(b"") == [(3, 0, b"\x01\x02")]  # the search went on after it
    assert checksum.split_statuses(bytes(bad) + good) == [(3, 0, b"\x01\x02")]


def test_frames_are_bounded_and_instructions_are_no_statuses():
    with pytest.raises(ValueError, match="at most 244"):
        checksum.frame(1, 3, bytes(245))
    assert len(checksum.frame(1, 3, bytes(244))) == checksum.MAX_FRAME
    with pytest.raises(ValueError):
        checksum.frame(0xFF, 1)
    # a header claiming more than a frame holds is noise: the reader does not wait for it
    reader = checksum.ChecksumReader()
    assert reader.feed(b"\xff\xff\x01\xfb" + checksum.frame(1, 1)) == [(1, 1, b"")]
    with pytest.raises(ProtocolError, match="where a status was expected"):
        checksum.as_status((0xFE, 0x82, b""))
    assert checksum.split_statuses(checksum.frame(0xFE, 0x82, b"\x38\x02\x01")) == []
    assert checksum.error_words(0x24, {2: "overheat", 5: "overload"}) == ["overheat",
                                                                         "overload"]


def test_the_protocol_2_variant_is_the_e_manual_s():
    assert dxl2.packet(1, 0x01) == bytes.fromhex("fffffd0001030001194e")
    assert dxl2.FRAMES.status_size(10) == len(dxl2.status(1, 0, bytes(10))) == 21
    assert dxl2.FRAMES.request_size(0) == len(dxl2.packet(1, 0x01)) == 10
    assert checksum.FRAMES.status_size(2) == len(checksum.status(1, 0, bytes(2))) == 8
    assert checksum.FRAMES.request_size(2) == len(checksum.frame(1, 2, bytes(2))) == 8


def chunks(data: bytes, cuts: list[int]) -> list[bytes]:
    at = sorted({c % (len(data) + 1) for c in cuts})
    return [data[a:b] for a, b in zip([0, *at], [*at, len(data)])]


ids = st.integers(0, 0xFE)
params = st.one_of(st.binary(max_size=40),
                   st.lists(st.sampled_from([b"\xff", b"\xfd", b"\x00", b"\xff\xff"]),
                            max_size=10).map(b"".join))


@quick
@given(ids, st.integers(0, 255), params, st.lists(st.integers(0, 300), max_size=5))
def test_checksum_frames_round_trip_however_split(device_id, code, body, cuts):
    packet = checksum.frame(device_id, code, body)
    reader = checksum.ChecksumReader()
    assert [f for piece in chunks(packet, cuts) for f in reader.feed(piece)] == \
        [(device_id, code, body)]


@quick
@given(st.lists(st.tuples(ids, st.integers(0, 0x7F), params), max_size=5),
       st.binary(max_size=12).map(lambda b: b.replace(b"\xff", b"")))
def test_checksum_statuses_round_trip_after_noise(statuses, noise):
    raw = b"".join(checksum.status(*s) for s in statuses)
    assert checksum.split_statuses(raw) == statuses
    assert checksum.split_statuses(noise + raw) == statuses  # noise without a header
    reader = checksum.ChecksumReader()
    assert reader.feed(noise + raw) == statuses


@quick
@given(st.binary(max_size=120), st.lists(st.integers(0, 200), max_size=5))
def test_the_checksum_reader_takes_any_bytes(data, cuts):
    reader = checksum.ChecksumReader()
    for piece in chunks(data, cuts):
        try:
            found = reader.feed(piece)
        except ProtocolError as exc:
            assert "checksum" in str(exc)
            continue
        for device_id, code, body in found:
            assert device_id <= 0xFE and 0 <= code <= 255 and len(body) <= checksum.MAX_FRAME


@quick
@given(ids.filter(lambda i: i != 0xFD), st.integers(0, 255), params,
       st.lists(st.integers(0, 300), max_size=5))
def test_protocol_2_packets_round_trip_however_split(device_id, instruction, body, cuts):
    packet = dxl2.packet(device_id, instruction, body)
    reader = dxl2.PacketReader()
    assert [f for piece in chunks(packet, cuts) for f in reader.feed(piece)] == \
        [(device_id, instruction, body)]


def test_a_protocol_2_header_with_a_length_beyond_any_packet_is_passed_by():
    reader = dxl2.PacketReader()
    ping = dxl2.packet(1, 0x01)
    with pytest.raises(ProtocolError, match="length 65535"):
        reader.feed(dxl2.HEADER + b"\x07\xff\xff" + ping)  # a garbled length, then a request
    assert reader.feed(b"") == [(1, 0x01, b"")]
    # the longest of ours, stuffed at every chance, still comes through
    data = b"\xff\xff\xfd" * 3 + b"\xff"
    longest = dxl2.fast_sync_status([(0, i, data) for i in range(dxl2.MAX_ID + 1)])
    [(device_id, instruction, body)] = dxl2.PacketReader().feed(longest)
    assert (device_id, instruction) == (dxl2.BROADCAST_ID, dxl2.STATUS)
    assert len(body) == (dxl2.MAX_ID + 1) * 14 - 2


def test_a_checksum_sync_read_s_replies_are_checked_in_place_as_they_arrive():
    first, second = checksum.status(1, 0, bytes(range(6))), checksum.status(2, 0x20, bytes(6))
    check = checksum.FRAMES.sync_replies(6, [1, 2, 3])
    check.feed(first + second[:5])  # the first whole, the second on its way
    assert check.found == [(1, 0, bytes(range(6)))] and check.in_shape
    bad = bytearray(checksum.status(3, 0, bytes(6)))
    bad[-2] ^= 1
    check.feed(first + second + bytes(bad))
    assert check.found == [(1, 0, bytes(range(6))), (2, 0x20, bytes(6)), False]
    assert check.in_shape


@pytest.mark.parametrize("wire", [
    checksum.status(2, 0x08),  # an error with no data: shorter than asked
    checksum.status(3, 0, bytes(6)),  # another servo's
    checksum.frame(2, 0x82, bytes(6)),  # an instruction heard back, not a status
], ids=["short", "other-id", "instruction"])
def test_a_checksum_sync_reply_out_of_shape_is_left_to_split(wire):
    check = checksum.FRAMES.sync_replies(6, [1, 2])
    check.feed(checksum.status(1, 0, bytes(6)) + wire + bytes(12))
    assert not check.in_shape and check.found == [(1, 0, bytes(6))]
