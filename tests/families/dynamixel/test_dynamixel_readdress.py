"""A write to a servo's ID or Baud Rate is answered from the ID it was addressed at, at the
rate it was addressed at; then the servo moves (dynamixel-sdk accepts only that reply). The
bus finds it at its new ID, at its new rate only; a factory reset answers from the old ID too.
The ``connect`` control line plugs a factory-new bus's parts one at a time."""

from __future__ import annotations

import contextlib

import pytest

from deltoctl.errors import InvalidInput
from deltoctl.families.dynamixel.emulator import DynamixelBus, DynamixelPtyServer, Servo
from deltoctl.families.dynamixel.emulator1 import Protocol1Bus, Servo1
from deltoctl.families.dynamixel.models import by_number

sdk = pytest.importorskip("dynamixel_sdk")
XL330 = by_number(1200)


def patient(port) -> None:
    """Each reply awaited 0.5 s: the SDK's 34 ms is short on a loaded machine."""
    port.setPacketTimeout = lambda _length: port.setPacketTimeoutMillis(500)


@contextlib.contextmanager
def _sdk(bus, protocol: float, baud: int):
    with DynamixelPtyServer(bus) as server:
        port = sdk.PortHandler(server.port)
        assert port.openPort() and port.setBaudRate(baud)
        patient(port)
        try:
            yield port, sdk.PacketHandler(protocol)
        finally:
            port.closePort()


def test_protocol_2_id_and_baud_writes_answer_from_the_old_id_and_rate():
    bus = DynamixelBus([Servo(1, model=XL330)], baud=57_600)
    with _sdk(bus, 2.0, 57_600) as (port, ph):
        assert ph.write1ByteTxRx(port, 1, 7, 5) == (sdk.COMM_SUCCESS, 0)
        assert set(bus.servos) == {5}
        assert ph.ping(port, 1)[1] == sdk.COMM_RX_TIMEOUT
        assert ph.write1ByteTxRx(port, 5, 8, 3) == (sdk.COMM_SUCCESS, 0)  # 1 Mbps
        assert ph.ping(port, 5)[1] == sdk.COMM_RX_TIMEOUT  # it listens at 1 Mbps now
        assert port.setBaudRate(1_000_000)
        assert ph.ping(port, 5) == (1200, sdk.COMM_SUCCESS, 0)


def test_protocol_2_factory_reset_answers_from_the_old_id():
    bus = DynamixelBus([Servo(7, model=XL330)], baud=57_600)
    with _sdk(bus, 2.0, 57_600) as (port, ph):
        assert ph.factoryReset(port, 7, 0xFF) == (sdk.COMM_SUCCESS, 0)
        assert set(bus.servos) == {1}  # its factory ID, at 57,600
        assert ph.ping(port, 1) == (1200, sdk.COMM_SUCCESS, 0)


def test_protocol_1_id_and_baud_writes_answer_from_the_old_id_and_rate():
    bus = Protocol1Bus([Servo1(1)], baud=57_600)
    with _sdk(bus, 1.0, 57_600) as (port, ph):
        assert ph.write1ByteTxRx(port, 1, 3, 4) == (sdk.COMM_SUCCESS, 0)
        assert set(bus.servos) == {4}
        assert ph.write1ByteTxRx(port, 4, 4, 1) == (sdk.COMM_SUCCESS, 0)  # 1 Mbps
        assert ph.ping(port, 4)[1] == sdk.COMM_RX_TIMEOUT
        assert port.setBaudRate(1_000_000)
        assert ph.ping(port, 4) == (12, sdk.COMM_SUCCESS, 0)  # AX-12A


@pytest.mark.parametrize(("model", "factory"), [(12, 1_000_000), (29, 57_600)])
def test_protocol_1_reset_answers_from_the_old_id_and_rate_then_the_factory_s(model, factory):
    bus = Protocol1Bus([Servo1(4, by_number(model))], baud=115_200)
    with _sdk(bus, 1.0, 115_200) as (port, ph):
        assert ph.factoryReset(port, 4) == (sdk.COMM_SUCCESS, 0)
        assert set(bus.servos) == {1}
        assert ph.ping(port, 1)[1] == sdk.COMM_RX_TIMEOUT  # no longer at 115,200
        assert port.setBaudRate(factory)
        assert ph.ping(port, 1) == (model, sdk.COMM_SUCCESS, 0)


def test_connect_plugs_factory_new_parts_one_at_a_time():
    from deltoctl.profile.catalog import load_profile
    from deltoctl.sim.controls import Controls
    from deltoctl.sim.serve import ServeOptions, serve_profile

    controls = Controls()
    with contextlib.ExitStack() as stack:
        info = serve_profile(stack, load_profile("koch-arm"), ServeOptions(factory_new=True),
                             controls=controls)
        assert {"connect", "disconnect"} <= set(info["controls"])
        port = sdk.PortHandler(info["endpoint"].split("?")[0].removeprefix("serial://"))
        assert port.openPort() and port.setBaudRate(57_600)
        patient(port)
        ph = sdk.PacketHandler(2.0)
        try:
            assert ph.ping(port, 1)[1] != sdk.COMM_SUCCESS  # six answer at once
            assert controls.run("connect elbow_flex") == "on the wire: elbow_flex"
            assert ph.ping(port, 1) == (1200, sdk.COMM_SUCCESS, 0)  # the XL330 alone
            assert controls.run("disconnect all") == "on the wire: nothing"
            assert ph.ping(port, 1)[1] == sdk.COMM_RX_TIMEOUT
            assert controls.run("connect shoulder_pan elbow_flex").endswith(
                "shoulder_pan, elbow_flex")
            with pytest.raises(InvalidInput, match="no joint 'elbow'"):
                controls.run("connect elbow")
        finally:
            port.closePort()


@contextlib.contextmanager
def _factory_new(profile: str, protocol: float, baud: int = 57_600):
    """A factory-new ``profile`` served, its control lines, and dynamixel-sdk on its bus at
    ``baud`` (its servos' factory rate)."""
    from deltoctl.profile.catalog import load_profile
    from deltoctl.sim.controls import Controls
    from deltoctl.sim.serve import ServeOptions, serve_profile

    controls = Controls()
    with contextlib.ExitStack() as stack:
        info = serve_profile(stack, load_profile(profile), ServeOptions(factory_new=True),
                             controls=controls)
        port = sdk.PortHandler(info["endpoint"].split("?")[0].removeprefix("serial://"))
        assert port.openPort() and port.setBaudRate(baud)
        patient(port)
        try:
            yield port, sdk.PacketHandler(protocol), controls
        finally:
            port.closePort()


def test_factory_new_servos_at_one_id_garble_and_never_answer_cleanly():
    with _factory_new("koch-arm", 2.0) as (port, ph, controls):
        assert ph.ping(port, 1)[1] != sdk.COMM_SUCCESS  # XL430s and XL330s: garbled
        assert ph.read4ByteTxRx(port, 1, 132)[1] != sdk.COMM_SUCCESS
        controls.run("connect shoulder_pan shoulder_lift")  # two XL430-W250s, alike
        assert ph.ping(port, 1) == (1060, sdk.COMM_SUCCESS, 0)  # identical bytes: clean
        assert ph.read4ByteTxRx(port, 1, 132)[1] != sdk.COMM_SUCCESS  # their poses differ
        controls.run("connect shoulder_pan")
        assert ph.read4ByteTxRx(port, 1, 132)[1:] == (sdk.COMM_SUCCESS, 0)
    with _factory_new("phantomx-arm", 1.0, 1_000_000) as (port, ph, controls):  # AX-12As
        assert ph.ping(port, 1) == (12, sdk.COMM_SUCCESS, 0)  # five AX-12As, alike
        assert ph.read2ByteTxRx(port, 1, 36)[1] != sdk.COMM_SUCCESS
