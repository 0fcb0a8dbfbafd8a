"""The XL430 bus emulator, driven by ROBOTIS' dynamixel-sdk over a pseudo-terminal."""

from __future__ import annotations

import time

import pytest

from deltoctl.families.dynamixel.emulator import DynamixelBus, DynamixelPtyServer, Servo
from tests.conftest import block_for, eventually

sdk = pytest.importorskip("dynamixel_sdk")


@pytest.fixture(autouse=True)
def _patient_sdk(monkeypatch):
    """The emulator shares this process with the test: give the SDK the reply timeouts of a
    slow USB adapter (a 50 ms latency timer) so that a busy machine does not fail the test."""
    monkeypatch.setattr(sdk.port_handler, "LATENCY_TIMER", 50)


@pytest.fixture
def bus():
    servos = DynamixelBus([Servo(i) for i in (11, 12, 13)])
    with DynamixelPtyServer(servos) as server:
        port = sdk.PortHandler(server.port)
        assert port.openPort() and port.setBaudRate(1000000)
        yield servos, port, sdk.PacketHandler(2.0)
        port.closePort()


def test_sdk_pings_reads_and_writes(bus):
    _servos, port, ph = bus
    model, result, error = ph.ping(port, 12)
    assert (model, result, error) == (1060, sdk.COMM_SUCCESS, 0)
    found, result = ph.broadcastPing(port)
    assert result == sdk.COMM_SUCCESS and sorted(found) == [11, 12, 13]
    assert found[11] == [1060, 46]
    value, result, _ = ph.read2ByteTxRx(port, 13, 0)
    assert (value, result) == (1060, sdk.COMM_SUCCESS)
    # EEPROM is refused while torque is on
    assert ph.write1ByteTxRx(port, 11, 64, 1)[0] == sdk.COMM_SUCCESS
    assert ph.write1ByteTxRx(port, 11, 11, 1)[1] == 7  # access error
    assert ph.write1ByteTxRx(port, 11, 0, 5)[1] == 7  # read-only item
    # a time-based profile: 200 ms to the goal
    assert ph.write1ByteTxRx(port, 12, 10, 4)[0] == sdk.COMM_SUCCESS
    ph.write1ByteTxRx(port, 12, 64, 1)
    ph.write4ByteTxRx(port, 12, 112, 200)
    ph.write4ByteTxRx(port, 12, 116, 3000)
    time.sleep(0.3)
    position, result, _ = ph.read4ByteTxRx(port, 12, 132)
    assert (position, result) == (3000, sdk.COMM_SUCCESS)


def test_sdk_group_sync_read_and_write(bus):
    servos, port, ph = bus
    writer = sdk.GroupSyncWrite(port, ph, 64, 1)
    for i in (11, 12, 13):
        writer.addParam(i, [1])
    assert writer.txPacket() == sdk.COMM_SUCCESS
    assert eventually(lambda: all(s.memory[64] == 1 for s in servos.servos.values()))
    reader = sdk.GroupSyncRead(port, ph, 126, 10)
    for i in (11, 12, 13):
        reader.addParam(i)
    assert reader.txRxPacket() == sdk.COMM_SUCCESS
    assert reader.getData(13, 132, 4) == 2047


def test_faults_missing_servo_and_bad_crc(bus):
    servos, port, ph = bus
    servos.faults.missing.add(12)
    assert ph.ping(port, 12)[1] == sdk.COMM_RX_TIMEOUT
    servos.faults.missing.clear()
    servos.faults.corrupt_crc.add(13)
    assert ph.ping(port, 13)[1] == sdk.COMM_RX_CORRUPT


def test_status_return_level_and_reboot(bus):
    servos, port, ph = bus
    servo = servos.servos[11]
    servo.memory[68] = 1  # reads only
    assert ph.write1ByteTxOnly(port, 11, 65, 1) == sdk.COMM_SUCCESS
    assert eventually(lambda: servo.memory[65] == 1)
    servo.memory[70] = 0x20  # overload: shut down
    servo.memory[68] = 2
    assert ph.write1ByteTxRx(port, 11, 64, 1)[1] == 1  # result fail until reboot
    assert ph.reboot(port, 11)[0] == sdk.COMM_SUCCESS
    assert servo.memory[70] == 0 and servo.memory[65] == 0


def test_sim_serve_mh5_serves_every_bus(tmp_path):
    import json
    import subprocess
    import sys
    from urllib.parse import urlsplit

    proc = subprocess.Popen([sys.executable, "-m", "deltoctl", "sim", "serve", "mh5", "--json"],
                            stdout=subprocess.PIPE, text=True)
    try:
        buses = json.loads(proc.stdout.readline())["buses"]
        assert set(buses) == {"upper_body", "lower_body", "i2c"}
        assert buses.pop("i2c").startswith("i2c+tcp://127.0.0.1:")  # the IMU's bus
        ph = sdk.PacketHandler(2.0)
        found = {}
        for name, url in buses.items():
            parts = urlsplit(url)
            assert parts.scheme == "serial" and "baud=2000000" in parts.query
            port = sdk.PortHandler(parts.path)
            assert port.openPort() and port.setBaudRate(2000000)  # what the URL says
            ids, result = ph.broadcastPing(port)
            port.closePort()
            assert result == sdk.COMM_SUCCESS
            found[name] = sorted(ids)
        assert found["upper_body"] == [31, 32, 33, 34, 41, 42, 43, 44, 51, 52]
        assert found["lower_body"] == [11, 12, 13, 14, 15, 16, 21, 22, 23, 24, 25, 26]
    finally:
        proc.terminate()
        assert proc.wait(timeout=5) == 0


def test_a_paced_bus_takes_the_wire_time():
    import time

    from deltoctl.families.dynamixel import codec
    from deltoctl.families.dynamixel.driver import DynamixelDriver
    from deltoctl.families.dynamixel.emulator import DynamixelBus, DynamixelPtyServer, Servo
    from deltoctl.profile.model import Component, Hardware, Profile

    servos = [Servo(i) for i in range(1, 12)]
    for servo in servos:
        servo.set("Return Delay Time", 0)
    hw = Hardware("bus", family="dynamixel", joints=[
        Component("joint", f"j{i}", address=i) for i in range(1, 12)])
    with DynamixelPtyServer(DynamixelBus(servos), pace=True) as server:
        driver = DynamixelDriver(block_for(Profile("t", hardware=[hw]), hw,
                                           f"serial://{server.port}?baud=57600"))
        driver.configure()
        start = time.perf_counter()
        replies = driver._sync_read(126, 10, list(range(1, 12)))
        took = time.perf_counter() - start
        driver.cleanup()
    sent = len(codec.sync_read(126, 10, range(1, 12))) + 11 * 21  # bytes both ways
    assert len(replies) == 11
    assert took >= sent * 10 / 57600 * 0.95  # 44 ms at 57600 baud: the bus never beats it


def test_sdk_fast_sync_read_and_the_driver_agree(bus):
    from deltoctl.families.dynamixel.driver import DynamixelDriver
    from deltoctl.profile.model import Component, Hardware, Profile

    servos, port, ph = bus
    servos.servos[12].set("Present Position", 1000)
    servos.servos[12].position = 1000.0
    group = sdk.GroupSyncRead(port, ph, 132, 4)
    for i in (11, 12, 13):
        assert group.addParam(i)
    assert group.fastSyncRead() == sdk.COMM_SUCCESS
    assert [group.getData(i, 132, 4) for i in (11, 12, 13)] == [2047, 1000, 2047]
    port.closePort()
    hw = Hardware("bus", family="dynamixel", params={"fast_sync_read": "true"},
                  joints=[Component("joint", f"j{i}", address=i) for i in (11, 12, 13)])
    driver = DynamixelDriver(block_for(Profile("t", hardware=[hw]), hw,
                                       f"serial://{port.port_name}?baud=1000000"))
    driver.configure()
    replies = driver._sync_read(132, 4, [11, 12, 13])
    values = driver.read()
    driver.cleanup()
    assert [(i, int.from_bytes(d, "little")) for i, _, d in replies] == [
        (11, 2047), (12, 1000), (13, 2047)]
    assert values["j12/position"] == pytest.approx((1000 - 2047) * 0.001533980787886)
    assert driver.stats["errors"] == 0


def test_a_refused_write_is_the_servo_s_fault_with_its_code_tried_once():
    from deltoctl.errors import DeviceFault
    from deltoctl.families.dynamixel.control_table import BY_NAME
    from deltoctl.families.dynamixel.driver import DynamixelDriver
    from deltoctl.families.dynamixel.emulator import DynamixelBus, DynamixelPtyServer, Servo
    from deltoctl.profile.model import Component, Hardware, Profile

    servo = Servo(1)
    servo.set("Torque Enable", 1)  # EEPROM is locked
    hw = Hardware("bus", family="dynamixel", joints=[Component("joint", "j1", address=1)])
    with DynamixelPtyServer(DynamixelBus([servo])) as server:
        driver = DynamixelDriver(block_for(Profile("t", hardware=[hw]), hw,
                                           f"serial://{server.port}?baud=1000000"))
        driver.configure()
        before = dict(driver.stats)
        with pytest.raises(DeviceFault, match=r"refused to write Max Position Limit .*: "
                                              r"access error") as refused:
            driver.write_register_item(1, BY_NAME["Max Position Limit"], 3000)
        driver.cleanup()
    assert refused.value.code == 7
    assert driver.stats["packets"] == before["packets"] + 1  # an answer: not tried again
    assert driver.stats["errors"] == before["errors"]
