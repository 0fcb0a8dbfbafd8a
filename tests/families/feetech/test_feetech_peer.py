"""Peer tests: Feetech's scservo_sdk (feetech-servo-sdk, the SDK LeRobot pins) puts the same
bytes on a (pseudo-terminal) wire as deltoctl's codec, and drives deltoctl's emulated bus."""

from __future__ import annotations

import os
import select
import tty

import pytest

from deltoctl.families.feetech import codec
from deltoctl.families.feetech.emulator import FeetechBus, FeetechPtyServer, Servo
from deltoctl.families.feetech.models import BY_NUMBER
from tests.conftest import eventually

scs = pytest.importorskip("scservo_sdk")


@pytest.fixture(autouse=True)
def _patient_sdk(monkeypatch):
    """The emulator shares this process with the test: the SDK gets a slow adapter's
    timeouts (a 50 ms latency timer, as Feetech's own later SDK) so a busy machine passes."""
    monkeypatch.setattr(scs.port_handler, "LATENCY_TIMER", 50)


@pytest.fixture
def wire():
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    port = scs.PortHandler(os.ttyname(slave))
    assert port.openPort() and port.setBaudRate(1000000)
    handler = scs.PacketHandler(0)

    def sent() -> bytes:
        data = b""
        while select.select([master], [], [], 0.2)[0]:
            data += os.read(master, 4096)
        return data

    yield port, handler, sent
    port.closePort()
    os.close(master)
    os.close(slave)


def test_requests_are_byte_identical(wire):
    port, ph, sent = wire
    cases = [
        (lambda: ph.write2ByteTxOnly(port, 1, 42, 2048), codec.write(1, 42, b"\x00\x08")),
        (lambda: ph.write1ByteTxOnly(port, 1, 55, 0), codec.write(1, 55, b"\x00")),
        (lambda: ph.readTx(port, 1, 56, 2), codec.read(1, 56, 2)),
        (lambda: ph.regWriteTxOnly(port, 2, 42, 2, [0, 4]), codec.reg_write(2, 42, b"\x00\x04")),
        (lambda: ph.syncReadTx(port, 56, 2, [1, 2, 3, 4, 5, 6], 6),
         codec.sync_read(56, 2, range(1, 7))),
        (lambda: ph.syncWriteTxOnly(port, 42, 2, [1, 0, 8, 2, 0, 4], 6),
         codec.sync_write(42, 2, {1: b"\x00\x08", 2: b"\x00\x04"})),
    ]
    for call, ours in cases:
        call()
        port.is_using = False  # the *Tx calls keep the port for a reply not read here
        assert sent() == ours
    # the reference's golden frames (§1.5)
    assert codec.sync_read(56, 2, range(1, 7)).hex() == "fffffe0a82380201020304050626"
    assert codec.write(1, 42, b"\x02\x00").hex() == "ffff0105032a0200ca"  # SCS, 512 BE


@pytest.fixture
def bus():
    servos = FeetechBus([Servo(i) for i in range(1, 7)])
    with FeetechPtyServer(servos) as server:
        port = scs.PortHandler(server.port)
        assert port.openPort() and port.setBaudRate(1000000)
        yield servos, port, scs.PacketHandler(0)
        port.closePort()


def test_sdk_pings_reads_and_writes_the_emulator(bus):
    servos, port, ph = bus
    assert ph.ping(port, 3) == (777, scs.COMM_SUCCESS, 0)  # PING, then READ of the model
    assert ph.ping(port, 9)[1] == scs.COMM_RX_TIMEOUT
    assert ph.read1ByteTxRx(port, 1, 0)[:2] == (3, scs.COMM_SUCCESS)  # firmware 3.10
    assert ph.read1ByteTxRx(port, 1, 1)[:2] == (10, scs.COMM_SUCCESS)
    assert ph.write2ByteTxRx(port, 2, 46, 3000) == (scs.COMM_SUCCESS, 0)
    assert ph.write2ByteTxRx(port, 2, 42, 2148) == (scs.COMM_SUCCESS, 0)
    assert ph.read1ByteTxRx(port, 2, 40)[0] == 1  # a goal turns the torque on
    assert eventually(lambda: ph.read2ByteTxRx(port, 2, 56)[:2] == (2148, scs.COMM_SUCCESS))
    # REG_WRITE waits for ACTION
    assert ph.regWriteTxRx(port, 4, 42, 2, [0x00, 0x07]) == (scs.COMM_SUCCESS, 0)
    assert servos.servos[3].get("Goal_Position") == 2048
    assert ph.action(port, scs.BROADCAST_ID) == scs.COMM_SUCCESS
    assert eventually(lambda: servos.servos[3].get("Goal_Position") == 0x700)  # no reply


def test_sdk_group_sync_read_and_write(bus):
    _servos, port, ph = bus
    writer = scs.GroupSyncWrite(port, ph, 42, 2)
    for i in range(1, 7):
        assert writer.addParam(i, [scs.SCS_LOBYTE(2000 + i), scs.SCS_HIBYTE(2000 + i)])
    assert writer.txPacket() == scs.COMM_SUCCESS
    reader = scs.GroupSyncRead(port, ph, 56, 2)
    for i in range(1, 7):
        reader.addParam(i)

    def arrived() -> bool:  # the servos move at their top speed: some ms
        assert reader.txRxPacket() == scs.COMM_SUCCESS
        return [reader.getData(i, 56, 2) for i in range(1, 7)] == [2000 + i for i in range(1, 7)]

    assert eventually(arrived)


def test_sdk_reads_a_big_endian_scs_servo(wire):
    """An SCS0009 holds its words big-endian: SDK1's PacketHandler(1) reads them as such."""
    scs0009 = BY_NUMBER[1284]
    bus = FeetechBus([Servo(7, scs0009)])
    with FeetechPtyServer(bus) as server:
        port = scs.PortHandler(server.port)
        assert port.openPort() and port.setBaudRate(1000000)
        ph = scs.PacketHandler(1)
        try:
            assert ph.read2ByteTxRx(port, 7, 3)[:2] == (1284, scs.COMM_SUCCESS)
            assert ph.read2ByteTxRx(port, 7, 56)[0] == 512  # mid-turn of 1024 steps
            assert bus.servos[0].memory[56:58] == b"\x02\x00"
        finally:
            scs.PacketHandler(0)  # SDK1's byte order is module-global: put it back
            port.closePort()


def test_the_servos_answer_only_at_their_baud_rate():
    bus = FeetechBus([Servo(1)], baud=1_000_000)
    with FeetechPtyServer(bus) as server:
        port = scs.PortHandler(server.port)
        assert port.openPort() and port.setBaudRate(500000)
        ph = scs.PacketHandler(0)
        assert ph.ping(port, 1)[1] == scs.COMM_RX_TIMEOUT
        assert port.setBaudRate(1000000)
        assert ph.ping(port, 1)[:2] == (777, scs.COMM_SUCCESS)
        port.closePort()
