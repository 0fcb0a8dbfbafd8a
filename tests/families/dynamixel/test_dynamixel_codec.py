"""Dynamixel Protocol 2.0 codec: the e-manual's example packets as golden vectors."""

from __future__ import annotations

import pytest

from deltoctl.errors import ProtocolError
from deltoctl.families.dynamixel import codec


def test_crc_check_value():
    assert codec.crc16(b"123456789") == 0xFEE8


@pytest.mark.parametrize("packet,crc", [
    (codec.ping(1), (0x19, 0x4E)),
    (codec.ping(), (0x31, 0x42)),
    (codec.read(1, 132, 4), (0x1D, 0x15)),
    (codec.write(1, 116, (512).to_bytes(4, "little")), (0xCA, 0x89)),
    (codec.reboot(1), (0x2F, 0x4E)),
    (codec.sync_read(132, 4, [1, 2]), (0xCE, 0xFA)),
    (codec.status(1, 0, bytes([0x06, 0x04, 0x26])), (0x65, 0x5D)),
])
def test_golden_crcs(packet, crc):
    assert tuple(packet[-2:]) == crc


def test_packet_layout():
    assert codec.ping(1) == bytes.fromhex("fffffd0001030001194e")
    assert codec.read(1, 132, 4) == bytes.fromhex("fffffd0001070002840004001d15")


def test_stuffing_round_trip():
    data = bytes.fromhex("fffffd")
    pkt = codec.write(1, 116, data + b"\x00")
    assert b"\xff\xff\xfd\xfd" in pkt[7:]
    [(dev, inst, body)] = codec.PacketReader().feed(pkt)
    assert (dev, inst) == (1, codec.WRITE) and body[2:] == data + b"\x00"


def test_reader_finds_packets_in_noise_and_checks_crc():
    reader = codec.PacketReader()
    stream = b"\x00\xff" + codec.status(3, 0, b"\x01\x02") + codec.status(4, 0x80, b"")
    got = []
    for i in range(0, len(stream), 3):  # arrives in pieces
        got += reader.feed(stream[i:i + 3])
    statuses = [codec.decode_status(*p) for p in got]
    assert [(s.id, s.params, s.alert) for s in statuses] == [(3, b"\x01\x02", False),
                                                              (4, b"", True)]
    bad = bytearray(codec.status(5, 0, b"\x01"))
    bad[-1] ^= 0xFF
    with pytest.raises(ProtocolError, match="CRC"):
        codec.PacketReader().feed(bytes(bad))


def test_error_words():
    assert codec.Status(1, 0x84, b"").error_text() == "data range error, hardware alert"
    assert codec.hardware_error_text(0x34) == ["overheating", "electrical shock", "overload"]
    assert codec.Status(1, 0, b"").error_text() is None


def test_sync_write_bulk_and_fast_sync():
    pkt = codec.sync_write(64, 1, {1: b"\x01", 2: b"\x00"})
    [(dev, inst, body)] = codec.PacketReader().feed(pkt)
    assert (dev, inst, body) == (0xFE, codec.SYNC_WRITE, bytes.fromhex("400001000101" "0200"))
    with pytest.raises(ValueError):
        codec.sync_write(64, 2, {1: b"\x01"})
    assert codec.bulk_read([(1, 132, 4)])[8:13] == bytes.fromhex("0184000400")
    with pytest.raises(ValueError):
        codec.factory_reset(codec.BROADCAST_ID, 0xFF)
    # fast sync read reply: [ERR, ID, data×2, CRC×2] per servo inside one status packet
    blocks = bytes([0, 1, 0x10, 0x00, 0xAA, 0xBB, 0, 2, 0x20, 0x00, 0xCC, 0xDD])
    st = codec.decode_status(*codec.PacketReader().feed(codec.status(0xFE, 0, blocks[1:]))[0])
    assert codec.decode_fast_sync(st, 2, [1, 2]) == {1: (0, b"\x10\x00"), 2: (0, b"\x20\x00")}


def test_sync_replies_by_offsets_and_by_the_reader():
    from deltoctl.families.dynamixel import codec

    ids = [1, 2, 3]
    replies = [codec.status(i, 0, bytes([i] * 10)) for i in ids]
    check = codec.SyncReplies(10, ids)
    check.feed(replies[0] + replies[1][:5])  # as the bytes arrive
    assert check.found == [(1, 0, bytes([1] * 10))]
    assert check.result(b"".join(replies)) == [(i, 0, bytes([i] * 10)) for i in ids]
    bad = bytearray(b"".join(replies))
    bad[21 + 12] ^= 0x01  # servo 2's data: its CRC no longer checks
    assert [r[0] for r in codec.SyncReplies(10, ids).result(bytes(bad))] == [1, 3]
    # servo 2 silent, servo 3's data needs stuffing: the reader takes over
    stuffed = codec.status(3, 0, b"\xff\xff\xfd" + bytes(7))
    got = codec.SyncReplies(10, ids).result(replies[0] + stuffed)
    assert got == [(1, 0, bytes([1] * 10)), (3, 0, b"\xff\xff\xfd" + bytes(7))]
    assert codec.split_statuses(bytes(bad)) == [(1, 0, bytes([1] * 10)), (3, 0, bytes([3] * 10))]
    assert codec.status_at(replies[0], 0, 10, 2) is None  # not the servo expected there


def test_crc16_two_bytes_a_step_matches_the_byte_table():
    from deltoctl.families.dynamixel import codec

    data = bytes(range(37))
    crc = 0
    for byte in data:  # the e-manual's byte-at-a-time algorithm
        crc = ((crc << 8) ^ codec._TABLE[((crc >> 8) ^ byte) & 0xFF]) & 0xFFFF
    assert codec.crc16(data) == crc
    assert codec.crc16(data[:36]) != crc


@pytest.mark.parametrize("device_id,error,params", [
    (1, 0, bytes(10)), (7, 0x80, bytes(range(10))), (0xFE, 0, b"\x01\x02"), (3, 0, b""),
    (3, 0, b"\xff\xff\xfd" + bytes(7)), (3, 0xff, b"\xff\xfd\x00"), (200, 4, bytes(300))])
def test_a_status_is_the_packet_it_stands_for(device_id, error, params):
    """The emulator's quick status packet, CRC carried on from a cached head, is byte for
    byte the general one (stuffed when it must be)."""
    assert codec.status(device_id, error, params) == codec.packet(
        device_id, codec.STATUS, bytes([error]) + params)
    with pytest.raises(ValueError):
        codec.status(0xFD, 0, b"")


def test_crc16_of_a_slice_in_place_and_carried_on():
    data = bytes(range(256)) * 2
    for start, end in ((0, 19), (21, 40), (5, 6), (7, 7), (3, 300)):
        assert codec.crc16(data, 0, start, end) == codec.crc16(data[start:end])
        middle = (start + end) // 2
        assert codec.crc16(data, codec.crc16(data, 0, start, middle), middle, end) == \
            codec.crc16(data[start:end])
