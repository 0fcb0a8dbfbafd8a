"""Control-table items: their bytes as unsigned, two's complement or sign-magnitude numbers
(feetech-sts-and-lerobot.md §1.4: −100 with its sign in bit 15 is 0x8064)."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from deltoctl.servo.items import Item, item_at

POSITION = Item(56, 2, "Present_Position", "R", sign_bit=15)
OFFSET = Item(31, 2, "Homing_Offset", sign_bit=11)
LOAD = Item(60, 2, "Present_Load", "R", sign_bit=10)
GOAL = Item(116, 4, "Goal Position", signed=True)
LIMIT = Item(48, 4, "Max Position Limit", default=4095)
SCS_GOAL = Item(42, 2, "Goal_Position", big_endian=True)


def test_sign_magnitude_is_the_reference_s():
    assert POSITION.encode(-100) == (0x8064).to_bytes(2, "little")
    assert POSITION.decode(b"\x64\x80") == -100 and POSITION.decode(b"\x64\x00") == 100
    assert OFFSET.span() == (-2047, 2047) and LOAD.span() == (-1023, 1023)
    assert OFFSET.encode(-2047) == (0x0FFF).to_bytes(2, "little")
    with pytest.raises(OverflowError, match="sign in bit 11"):
        OFFSET.encode(2114)  # the calibration that LeRobot's encoder refuses too
    assert POSITION.encoding == "sign-magnitude" and GOAL.encoding == "two's complement"
    assert LIMIT.encoding == "unsigned"


def test_twos_complement_unsigned_and_big_endian():
    assert GOAL.encode(-1) == b"\xff\xff\xff\xff" and GOAL.decode(b"\xff\xff\xff\xff") == -1
    assert GOAL.span() == (-(1 << 31), (1 << 31) - 1) and LIMIT.span() == (0, (1 << 32) - 1)
    with pytest.raises(OverflowError):
        LIMIT.encode(-1)
    assert SCS_GOAL.encode(512) == b"\x02\x00"  # as the reference's SCS write: 2A 02 00
    table = bytearray(120)
    table[116:120] = GOAL.encode(-2048)
    assert GOAL.of_table(table) == -2048 and GOAL.of_table(table[100:], base=100) == -2048
    with pytest.raises(ValueError, match="takes 4 byte"):
        GOAL.decode(b"\x00\x01")
    assert item_at(118, (LIMIT, GOAL)) is GOAL and item_at(60, (LIMIT, GOAL)) is None
    assert Item(8, 1, "Max Position Limit").key == "max-position-limit"


@given(st.sampled_from([POSITION, OFFSET, LOAD, GOAL, LIMIT, SCS_GOAL]), st.data())
def test_every_value_of_an_encoding_round_trips(item, data):
    low, high = item.span()
    value = data.draw(st.integers(low, high))
    assert item.decode(item.encode(value)) == value
