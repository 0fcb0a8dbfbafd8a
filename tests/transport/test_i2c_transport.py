"""The I2C transport: URLs, clear errors, one try per transaction, and the simulated bus as
smbus2 sees it."""

from __future__ import annotations

import errno

import pytest
import smbus2

from deltoctl import errors
from deltoctl.errors import DeviceError, InvalidInput, Unreachable
from deltoctl.families.lsm6ds3.emulator import Lsm6ds3Chip
from deltoctl.sim.i2c_bus import I2CSocketServer, SimSMBus
from deltoctl.transport.i2c import I2CBus, NoAnswer, open_smbus, parse_i2c_url, wire_bits


def test_urls():
    assert parse_i2c_url("i2c:///dev/i2c-1") == ("dev", "/dev/i2c-1", 0)
    assert parse_i2c_url("i2c+tcp://127.0.0.1:4000") == ("tcp", "127.0.0.1", 4000)
    for bad in ("i2c://", "tcp://127.0.0.1:4000", "i2c+tcp://127.0.0.1"):
        with pytest.raises(InvalidInput, match="not an I2C target"):
            parse_i2c_url(bad)


def test_a_missing_bus_and_a_permission_problem_say_what_to_do(monkeypatch):
    with pytest.raises(Unreachable, match="no I2C bus /dev/i2c-99") as missing:
        open_smbus("i2c:///dev/i2c-99")
    assert "i2c-dev" in missing.value.hint

    def refuse(self, bus):
        raise PermissionError(errno.EACCES, "Permission denied")

    monkeypatch.setattr(smbus2.SMBus, "open", refuse)
    with pytest.raises(Unreachable, match="no permission") as denied:
        open_smbus("i2c:///dev/i2c-1")
    assert "i2c group" in denied.value.hint
    with pytest.raises(Unreachable, match="cannot reach the simulated I2C bus") as gone:
        open_smbus("i2c+tcp://127.0.0.1:1")
    assert "sim serve" in gone.value.hint


class Flaky(SimSMBus):
    """Fails the first ``failures`` transactions with ``code`` (EREMOTEIO: a NACK)."""

    def __init__(self, devices, failures, code=errno.EREMOTEIO):
        super().__init__(devices)
        self.failures, self.code = failures, code

    def transact(self, ops):
        if self.failures:
            self.failures -= 1
            raise OSError(self.code, "Remote I/O error")
        return super().transact(ops)


def test_one_try_per_transaction_and_a_clear_message():
    """The transport moves bytes: the tries are the drivers' exchange policy."""
    assert NoAnswer is errors.NoAnswer
    bus = I2CBus(Flaky({0x6A: Lsm6ds3Chip()}, failures=1), "i2c:///dev/i2c-1")
    with pytest.raises(NoAnswer, match=r"^no answer from 0x6a on i2c:///dev/i2c-1$") as silent:
        bus.transfer(0x6A, b"\x0f", 1)
    assert "wiring" in silent.value.hint
    assert bus.transfer(0x6A, b"\x0f", 1) == b"\x6a"  # the next transaction
    assert bus.stats["bytes"] == 8  # what each moved: [addr W][reg] Sr [addr R][byte]
    bus = I2CBus(Flaky({0x6A: Lsm6ds3Chip()}, failures=1, code=errno.EINVAL), "i2c:///dev/i2c-1")
    with pytest.raises(DeviceError, match="I2C transfer to 0x6a on i2c:///dev/i2c-1 failed") \
            as failed:
        bus.write(0x6A, b"\x10\x60")
    assert not isinstance(failed.value, NoAnswer)


@pytest.mark.parametrize("served", [False, True], ids=["in-process", "over loopback"])
def test_the_simulated_bus_answers_smbus2_calls(served):
    chip = Lsm6ds3Chip(who_am_i=0x69)
    sim = SimSMBus({0x6A: chip})
    server = I2CSocketServer(sim).start() if served else None
    bus = open_smbus(server.url) if server else sim
    try:
        assert bus.read_byte_data(0x6A, 0x0F) == 0x69
        bus.write_byte_data(0x6A, 0x10, 0x62)
        assert chip.registers[0x10] == 0x62
        write, read = smbus2.i2c_msg.write(0x6A, [0x10]), smbus2.i2c_msg.read(0x6A, 2)
        bus.i2c_rdwr(write, read)  # smbus2's own messages, filled in place
        assert list(read) == [0x62, 0x00]
        assert len(bus.read_i2c_block_data(0x6A, 0x20, 14)) == 14
        with pytest.raises(OSError) as nack:
            bus.read_byte_data(0x50, 0)
        assert nack.value.errno == errno.EREMOTEIO
    finally:
        if server:
            bus.close()
            server.close()


def test_wire_bits():
    # [addr W][reg] Sr [addr R][4 payload + flags]: 8 bytes of 9 bits
    assert wire_bits(1, 5) == 72
    assert wire_bits(5, 0) == 54  # a write alone: address + 5 bytes


def test_an_exchange_under_a_policy_counts_once_and_names_the_device():
    """What every I2C family's exchange is (Bioscara joints, the LSM6DS3): one packet on the
    bus however many tries, each failed try an error, no answer naming the device and bus."""
    from deltoctl.core.exchange import ExchangePolicy
    from deltoctl.transport.i2c import exchange

    policy = ExchangePolicy(tries=3)
    bus = I2CBus(Flaky({0x6A: Lsm6ds3Chip()}, failures=2), "i2c:///dev/i2c-1")
    assert exchange(bus, 0x6A, lambda: bus.transfer(0x6A, b"\x0f", 1), policy.run, 3) == b"\x6a"
    assert bus.stats["packets"] == 1 and bus.stats["errors"] == 2
    bus = I2CBus(Flaky({0x6A: Lsm6ds3Chip()}, failures=5), "i2c:///dev/i2c-1")
    with pytest.raises(NoAnswer, match=r"^no answer from 0x6a on i2c:///dev/i2c-1 \(3 tries\)$"):
        exchange(bus, 0x6A, lambda: bus.transfer(0x6A, b"\x0f", 1), policy.run, 3)
    assert bus.stats["packets"] == 1 and bus.stats["errors"] == 3
