"""Each emulated servo starts with its own model's e-manual defaults, as ROBOTIS' dynamixel-sdk
reads them over a pseudo-terminal (docs/en/dxl/x/<model>.md, the Initial Value column)."""

from __future__ import annotations

import pytest

from deltoctl.families.dynamixel.emulator import DynamixelBus, DynamixelPtyServer, Servo
from deltoctl.families.dynamixel.models import by_name

sdk = pytest.importorskip("dynamixel_sdk")

# address, size of the items read
ITEMS = {"Return Delay Time": (9, 1), "Moving Threshold": (24, 4), "Temperature Limit": (31, 1),
         "Max Voltage Limit": (32, 2), "Min Voltage Limit": (34, 2), "Current Limit": (38, 2),
         "Velocity Limit": (44, 4), "Shutdown": (63, 1), "Velocity I Gain": (76, 2),
         "Velocity P Gain": (78, 2), "Position D Gain": (80, 2), "Position I Gain": (82, 2),
         "Position P Gain": (84, 2), "Feedforward 1st Gain": (90, 2)}
# the pages' values (None: the model has no such item)
PAGES = {
    "XL330-M288": dict(zip(ITEMS, (250, 10, 70, 70, 35, 1750, 445, 53, 1600, 180, 0, 0, 400, 0))),
    "XM430-W350": dict(zip(ITEMS, (250, 10, 80, 160, 95, 1193, 200, 52, 1920, 100, 0, 0, 800,
                                   0))),
    "XH540-W270": dict(zip(ITEMS, (250, 10, 80, 160, 95, 2047, 167, 52, 1920, 100, 0, 0, 800,
                                   0))),
    "XL430-W250": dict(zip(ITEMS, (250, 10, 72, 140, 60, None, 265, 52, 1000, 100, 4000, 0, 640,
                                   0))),
    "XC430-W150": dict(zip(ITEMS, (250, 20, 80, 160, 60, None, 460, 52, 1920, 100, 0, 0, 460,
                                   0))),
    "XL330-M077": dict(zip(ITEMS, (250, 10, 70, 70, 35, 1750, 1620, 53, 400, 40, 0, 400, 400,
                                   0))),
    "XW430-T333": dict(zip(ITEMS, (250, 10, 80, 160, 95, 2047, 139, 52, 1920, 100, 0, 0, 900,
                                   0))),
}


@pytest.fixture(autouse=True)
def _patient_sdk(monkeypatch):
    monkeypatch.setattr(sdk.port_handler, "LATENCY_TIMER", 50)


@pytest.fixture
def bus():
    servos = DynamixelBus([Servo(i, model=by_name(name)) for i, name in enumerate(PAGES, 1)])
    with DynamixelPtyServer(servos) as server:
        port = sdk.PortHandler(server.port)
        assert port.openPort() and port.setBaudRate(1000000)
        yield port, sdk.PacketHandler(2.0)
        port.closePort()


def test_the_sdk_reads_each_models_defaults(bus):
    port, ph = bus
    read = {1: ph.read1ByteTxRx, 2: ph.read2ByteTxRx, 4: ph.read4ByteTxRx}
    for device_id, (name, page) in enumerate(PAGES.items(), 1):
        model, result, _ = ph.ping(port, device_id)
        assert (model, result) == (by_name(name).number, sdk.COMM_SUCCESS)
        got = {}
        for item, (address, size) in ITEMS.items():
            if page[item] is None:
                continue
            value, result, error = read[size](port, device_id, address)
            assert (result, error) == (sdk.COMM_SUCCESS, 0), (name, item)
            got[item] = value
        assert got == {k: v for k, v in page.items() if v is not None}, name


def test_a_reboot_restores_the_models_gains(bus):
    port, ph = bus
    assert ph.write2ByteTxRx(port, 1, 84, 1234)[0] == sdk.COMM_SUCCESS
    assert ph.read2ByteTxRx(port, 1, 84)[0] == 1234
    assert ph.reboot(port, 1)[0] == sdk.COMM_SUCCESS
    value, result, _ = ph.read2ByteTxRx(port, 1, 84)
    assert (value, result) == (400, sdk.COMM_SUCCESS)  # the XL330-M288's, not the XL430's 640
