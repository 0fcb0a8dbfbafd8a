"""The frame record and the CANopen decoding: golden vectors and a property test."""

import pytest
from deltoctl.errors import ProtocolError
from hypothesis import given
from hypothesis import strategies as st

from deltoctl_canopen import codec
from deltoctl_canopen.codec import Frame


def test_golden_record():
    record = codec.encode(Frame(0x602, bytes([0x40, 0x41, 0x60, 0, 0, 0, 0, 0])))
    assert record.hex() == "02060000080000004041600000000000"
    assert codec.decode(record) == Frame(0x602, bytes([0x40, 0x41, 0x60, 0, 0, 0, 0, 0]))


frames = st.one_of(
    st.builds(Frame, st.integers(0, 0x7FF), st.binary(max_size=8), st.just(False), st.booleans()),
    st.builds(Frame, st.integers(0, 0x1FFFFFFF), st.binary(max_size=8), st.just(True),
              st.booleans()))


@given(frames)
def test_round_trip(frame):
    record = codec.encode(frame)
    assert len(record) == codec.RECORD_SIZE
    assert codec.decode(record) == frame
    assert isinstance(codec.describe(frame), str)


@given(st.binary(min_size=16, max_size=16))
def test_any_record_decodes_or_is_refused(record):
    try:
        frame = codec.decode(record)
    except ProtocolError:
        return
    assert len(frame.data) <= 8 and codec.encode(frame)[:5] == record[:5]


@pytest.mark.parametrize("record", [b"", bytes(15), bytes(17),
                                    bytes.fromhex("000800000900000000000000000000 00".replace(" ", "")),
                                    (0x20000000).to_bytes(4, "little") + bytes(12)])
def test_bad_records(record):
    with pytest.raises(ProtocolError):
        codec.decode(record)


@pytest.mark.parametrize("frame, text", [
    (Frame(0x000, bytes([0x01, 0x00])), "NMT start all nodes"),
    (Frame(0x000, bytes([0x80, 0x03])), "NMT enter pre-operational node 3"),
    (Frame(0x080), "SYNC"),
    (Frame(0x082, bytes.fromhex("1186010000000000")), "EMCY node 2 0x8611"),
    (Frame(0x182, bytes(6)), "TPDO1 node 2"),
    (Frame(0x203, bytes(6)), "RPDO1 node 3"),
    (Frame(0x602, bytes.fromhex("2b40600006000000")), "SDO request to node 2: write 0x6040:00 = 0600"),
    (Frame(0x582, bytes.fromhex("4b41600037060000")), "SDO reply from node 2: read 0x6041:00 = 3706"),
    (Frame(0x582, bytes.fromhex("8000200000000206")), "SDO reply from node 2: abort 0x2000:00 0x06020000 (object does not exist)"),
    (Frame(0x702, bytes([0x05])), "heartbeat node 2: OPERATIONAL"),
    (Frame(0x702, bytes([0x00])), "boot-up node 2"),
    (Frame(0x7E5, bytes.fromhex("5100000000800000")), "LSS fast scan"),
    (Frame(0x7E4, bytes.fromhex("5eff000000000000")), "LSS reply inquire node ID: none"),
    (Frame(0x7E4, bytes.fromhex("1101000000000000")), "LSS reply configure node ID: error 1"),
    (Frame(0x7E4, bytes.fromhex("4f00000000000000")), "LSS reply identify slave"),
])
def test_describe(frame, text):
    assert codec.describe(frame) == text


def test_states():
    assert codec.state_of(0x0237) == "OPERATION ENABLED"
    assert codec.state_of(0x0250) == "SWITCH ON DISABLED"
    assert codec.state_of(0x0218) == "FAULT"
    assert codec.state_of(0x0217) == "QUICK STOP ACTIVE"
