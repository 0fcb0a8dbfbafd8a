"""A Feetech servo answers a write of its ID or Baud_Rate from the ID and at the rate it was
addressed at, then moves (scservo_sdk accepts only that reply, LeRobot's setup relies on it);
the bus finds it at its new ID, at its new rate only."""

from __future__ import annotations

import pytest

from deltoctl.families.feetech.emulator import FeetechBus, FeetechPtyServer, Servo
from deltoctl.families.feetech.models import BAUD_RATES

scs = pytest.importorskip("scservo_sdk")


def test_id_and_baud_writes_answer_from_the_old_id_and_rate():
    servo = Servo(1)
    bus = FeetechBus([servo], baud=1_000_000)
    code = next(c for c, b in BAUD_RATES.items() if b == 500_000)
    with FeetechPtyServer(bus) as server:
        port = scs.PortHandler(server.port)
        assert port.openPort() and port.setBaudRate(1_000_000)
        # each reply awaited 0.5 s: the SDK's 34 ms is short on a loaded machine
        port.setPacketTimeout = lambda _length: port.setPacketTimeoutMillis(500)
        ph = scs.PacketHandler(0)
        try:
            assert ph.write1ByteTxRx(port, 1, 55, 0) == (scs.COMM_SUCCESS, 0)  # Lock 0
            assert ph.write1ByteTxRx(port, 1, 5, 4) == (scs.COMM_SUCCESS, 0)
            assert ph.ping(port, 1)[1] == scs.COMM_RX_TIMEOUT
            assert ph.write1ByteTxRx(port, 4, 6, code) == (scs.COMM_SUCCESS, 0)
            assert ph.ping(port, 4)[1] == scs.COMM_RX_TIMEOUT  # it listens at 500 kbps now
            assert port.setBaudRate(500_000)
            assert ph.write1ByteTxRx(port, 4, 55, 1) == (scs.COMM_SUCCESS, 0)  # Lock 1
            assert ph.ping(port, 4) == (777, scs.COMM_SUCCESS, 0)
        finally:
            port.closePort()
    servo.power_cycle()  # the EEPROM kept them
    assert (servo.id, servo.baud) == (4, 500_000)
