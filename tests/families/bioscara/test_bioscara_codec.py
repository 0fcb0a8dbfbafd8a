"""The Bioscara joint protocol: request bytes, replies, flags and the transmission."""

from __future__ import annotations

import math

import pytest

from deltoctl.errors import InvalidInput, ProtocolError
from deltoctl.families.bioscara import codec


def test_request_bytes():
    assert codec.setup(20, 40) == bytes([0x10, 20, 40, 0, 0])  # drive first, as a uint32
    assert codec.write_float(codec.MOVETOANGLE, 90.0) == bytes.fromhex("150000b442")
    assert codec.write_float(codec.SETRPM, -1.5) == bytes.fromhex("110000c0bf")
    assert codec.write_u8(codec.ENABLESTALLGUARD, 12) == bytes([0x1E, 12])
    assert codec.write_u8(codec.STOP, 0) == bytes([0x29, 0])
    assert codec.move_steps(-200) == bytes.fromhex("1338ffffff")
    assert codec.read_request(codec.ANGLEMOVED) == b"\x18"
    # HOME: direction, |rpm|, sensitivity, current
    assert codec.home(-45.0, 50, 30) == bytes([0x2D, 0, 45, 50, 30])
    assert codec.home(10.0, 30, 15) == bytes([0x2D, 1, 10, 30, 15])


def test_bad_arguments_are_refused_before_the_wire():
    for rpm in (0.4, 251, -300):
        with pytest.raises(InvalidInput, match="1-250"):
            codec.home(rpm, 30, 15)
    with pytest.raises(InvalidInput, match="0-100 %"):
        codec.setup(120, 20)
    with pytest.raises(InvalidInput, match="one byte"):
        codec.write_u8(codec.ENABLESTALLGUARD, 300)


def test_replies_end_with_the_flags():
    assert codec.decode_float(bytes.fromhex("0000b4420c")) == (90.0, 0x0C)
    assert codec.decode_ping(b"O\x08") == codec.NOTENABLED
    with pytest.raises(ProtocolError, match="instead of 'O'"):
        codec.decode_ping(b"N\x00")
    with pytest.raises(ProtocolError, match="4 payload bytes"):
        codec.decode_float(b"\x00\x00\x0c")
    assert codec.describe_flags(0x0F) == "stalled, busy, not homed, not enabled"
    assert codec.describe_flags(0) == "homed, enabled"
    assert codec.ERRORS[-109].startswith("incorrect state")


def test_the_transmission():
    # J2: 4 mm per motor turn, reduction −2π/0.004; its homing speed 3 mm/s is −45 motor rpm
    reduction = -1570.79632679
    assert codec.to_motor_rpm(0.003, reduction) == pytest.approx(-45.0)
    assert codec.from_motor_rpm(-45.0, reduction) == pytest.approx(0.003)
    degrees = codec.to_motor_degrees(0.1, 35, 3.04647)
    assert degrees == pytest.approx(math.degrees(35 * (0.1 - 3.04647)))
    assert codec.from_motor_degrees(degrees, 35, 3.04647) == pytest.approx(0.1)
