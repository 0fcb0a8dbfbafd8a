"""The LSM6DS3 register conversation as a host/device pair with no transport (reads and
writes with auto-increment, bad and any bytes), the chip refusing a write to no register, and
the driver's exchange policy over a bus that fails."""

from __future__ import annotations

import errno

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from deltoctl.core.driver import Links
from deltoctl.errors import InvalidInput, NoAnswer, ProtocolError
from deltoctl.families.lsm6ds3 import codec
from deltoctl.families.lsm6ds3.codec import Device, Host, Read, Write
from deltoctl.families.lsm6ds3.driver import Lsm6ds3Driver
from deltoctl.families.lsm6ds3.emulator import Lsm6ds3Chip
from deltoctl.profile.catalog import load_profile
from deltoctl.sim.i2c_bus import SimSMBus
from deltoctl.transport.i2c import I2CBus
from tests.conftest import block_for


def pair(request, registers):
    """Host → device → host, as one transaction: what the host reads back (None: a write)."""
    device = Device()
    data, length = Host.encode(request)
    written = device.written(data)
    if isinstance(request, Write):
        assert written == request and length == 0
        for register, value in written.cells():
            registers[register] = value
        return None
    assert written == Write(request.register)  # the register selected, nothing stored
    read = device.read(length)
    assert read == request and device.pointer == (request.register + length) % 0x80
    return Host.decode(request, Device.reply(registers, read))


def test_writes_and_reads_with_auto_increment():
    registers = bytearray(codec.REGISTER_COUNT)
    registers[codec.WHO_AM_I] = 0x6A
    assert pair(Write(codec.CTRL1_XL, bytes([0x62, 0x60])), registers) is None
    assert registers[codec.CTRL1_XL:codec.CTRL2_G + 1] == bytes([0x62, 0x60])
    assert pair(Read(codec.CTRL1_XL, 2), registers) == bytes([0x62, 0x60])
    assert pair(Read(codec.WHO_AM_I), registers) == b"\x6a"
    pair(Write(0x0E, bytes([1, 2, 3])), registers)  # over WHO_AM_I: read-only
    assert registers[0x0E:0x11] == bytes([1, 0x6A, 3])
    assert Write(0x7F, bytes([5, 6])).cells() == [(0x7F, 5), (0x00, 6)]  # the address wraps


def test_bad_bytes_are_one_protocol_error():
    device = Device()
    with pytest.raises(ProtocolError, match="names no register"):
        device.written(b"")
    with pytest.raises(ProtocolError, match="0x80 is no LSM6DS3 register"):
        device.written(b"\x80\x01")
    with pytest.raises(ProtocolError, match=r"OUT_TEMP_L: expected 14 bytes, got 13"):
        Host.decode(Read(codec.OUT_TEMP_L, codec.BLOCK), bytes(13))
    with pytest.raises(ProtocolError, match="expected 0 bytes"):
        Host.decode(Write(codec.CTRL1_XL, b"\x00"), b"\x00")
    with pytest.raises(InvalidInput, match="no LSM6DS3 register"):
        Host.encode(Read(0x90))
    with pytest.raises(InvalidInput, match="a read of 0 bytes"):
        Host.encode(Read(codec.WHO_AM_I, 0))


def test_the_chip_refuses_a_write_to_no_register():
    chip = Lsm6ds3Chip()
    with pytest.raises(OSError) as nack:
        chip.write(b"\x90\x01")
    assert nack.value.errno == errno.EREMOTEIO
    chip.write(bytes([codec.WHO_AM_I]))
    assert chip.read(1) == b"\x6a"


quick = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@quick
@given(st.binary(max_size=6), st.integers(1, 20))
def test_any_write_is_a_request_or_a_protocol_error(data, count):
    device = Device()
    try:
        written = device.written(data)
    except ProtocolError:
        assert not data or data[0] >= 0x80
        return
    assert Host.encode(written) == (data, 0)
    assert device.read(count) == Read((data[0] + len(data) - 1) % 0x80, count)


@quick
@given(st.integers(0, 0x7F), st.integers(1, 16), st.binary(max_size=20))
def test_any_reply_is_the_bytes_asked_for_or_one_clear_error(register, count, reply):
    try:
        assert Host.decode(Read(register, count), reply) == reply
    except ProtocolError:
        assert len(reply) != count


class Flaky(SimSMBus):
    def __init__(self, devices, failures):
        super().__init__(devices)
        self.failures = failures

    def transact(self, ops):
        if self.failures:
            self.failures -= 1
            raise OSError(errno.EREMOTEIO, "Remote I/O error")
        return super().transact(ops)


def imu_driver(smbus):
    profile = load_profile("mh5")
    hw = next(hw for hw in profile.hardware if hw.name == "i2c")
    url = "i2c:///dev/i2c-1"
    links = Links()
    links.open[url] = I2CBus(smbus, url)
    return Lsm6ds3Driver(block_for(profile, hw, url, links=links))


def test_three_tries_then_a_clear_message():
    chip = Lsm6ds3Chip()
    driver = imu_driver(Flaky({0x6A: chip}, failures=2))
    driver.configure()  # WHO_AM_I on its third try, then the settings
    assert driver.chip == "LSM6DS3TR-C" and chip.registers[codec.CTRL1_XL] == 0x62
    assert driver.stats == {"packets": 6, "errors": 2, "reconnects": 0}
    driver = imu_driver(Flaky({0x6A: Lsm6ds3Chip()}, failures=3))
    with pytest.raises(NoAnswer, match=r"no answer from 0x6a on i2c:///dev/i2c-1 \(3 tries\)"):
        driver.configure()
    assert driver.stats == {"packets": 1, "errors": 3, "reconnects": 0}
