"""The joint conversation as a host/device pair with no transport (every command, bad bytes,
any bytes), and the driver's exchange policy over a bus that fails."""

from __future__ import annotations

import errno
import math
import struct

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from deltoctl.core.driver import Links
from deltoctl.errors import DeviceError, DeviceFault, InvalidInput, NoAnswer, ProtocolError
from deltoctl.families.bioscara import codec
from deltoctl.families.bioscara.codec import Device, Host, Reply, Request
from deltoctl.families.bioscara.driver import BioscaraDriver, Joint
from deltoctl.families.bioscara.emulator import JointFirmware
from deltoctl.profile.catalog import load_profile
from deltoctl.sim.i2c_bus import SimSMBus
from deltoctl.transport.i2c import I2CBus
from tests.conftest import block_for

# one request per command (HOMEOFFSET read and written), with values a float32 holds exactly
EVERY_COMMAND = [
    Request(codec.PING), Request(codec.ANGLEMOVED), Request(codec.GETENCODERRPM),
    Request(codec.GETDRIVERRPM), Request(codec.HOMEOFFSET), Request(codec.HOMEOFFSET, (3.5,)),
    Request(codec.SETUP, (20, 40)), Request(codec.HOME, (1, 45, 30, 15)),
    Request(codec.SETRPM, (-1.5,)), Request(codec.MOVETOANGLE, (90.0,)),
    Request(codec.SETMAXACCELERATION, (4000.0,)), Request(codec.SETMAXVELOCITY, (2000.0,)),
    Request(codec.CHECKORIENTATION, (10.0,)), Request(codec.MOVESTEPS, (-200,)),
    Request(codec.SETCURRENT, (50,)), Request(codec.SETHOLDCURRENT, (0,)),
    Request(codec.ENABLESTALLGUARD, (12,)), Request(codec.SETBRAKEMODE, (2,)),
    Request(codec.STOP, (0,)), Request(codec.DISABLECLOSEDLOOP, (0,)),
]


def test_every_command_covers_the_protocol():
    assert {r.command for r in EVERY_COMMAND} == set(codec.ARGS)


@pytest.mark.parametrize("request_", EVERY_COMMAND, ids=lambda r: f"{r.name}{len(r.args)}")
def test_host_and_device_agree_on_every_command(request_):
    data, length = Host.encode(request_)
    assert data[0] == request_.command
    assert Device.parse(data) == request_  # the device reads what the host meant
    value = 12.25 if request_.payload_size == 4 else None
    reply = Device.reply(Device.answer(request_, value), codec.NOTHOMED, length)
    assert len(reply) == length and reply[-1] == codec.NOTHOMED
    assert Host.decode(request_, reply) == Reply(codec.NOTHOMED, value)


def test_reads_and_commands_expect_their_reply_lengths():
    assert Host.encode(Request(codec.ANGLEMOVED)) == (b"\x18", 5)
    assert Host.encode(Request(codec.PING)) == (b"\x0f", 2)
    assert Host.encode(Request(codec.HOMEOFFSET)) == (b"\x2e", 5)  # a read
    assert Host.encode(Request(codec.HOMEOFFSET, (0.0,)))[1] == 1  # a write: the flags
    assert Host.encode(codec.setup_command(20, 40))[0] == bytes([0x10, 20, 40, 0, 0])


def test_bad_bytes_are_one_protocol_error():
    for data, why in [(b"", "empty"), (b"\x14", "no command"), (b"\x10\x01", "takes 4"),
                      (b"\x15\x00\x00", "takes 4"), (b"\x0f\x00", "takes 0"),
                      (b"\x2e\x00\x00", "takes 0 or 4")]:
        with pytest.raises(ProtocolError, match=why):
            Device.parse(data)
    with pytest.raises(ProtocolError, match="4 payload bytes"):
        Host.decode(Request(codec.ANGLEMOVED), b"\x0c")
    with pytest.raises(ProtocolError, match="flags byte alone"):
        Host.decode(Request(codec.STOP, (0,)), b"\x00\x0c")
    with pytest.raises(ProtocolError, match="instead of 'O'"):
        Host.decode(Request(codec.PING), b"X\x0c")


def test_a_nack_is_the_joints_own_fault():
    with pytest.raises(DeviceFault) as nack:
        Host.decode(Request(codec.PING), b"N\x0c")
    assert nack.value.code == codec.NACK


def test_requests_the_joint_cannot_take_are_refused_before_the_wire():
    with pytest.raises(InvalidInput, match="takes no 2 arguments"):
        Host.encode(Request(codec.STOP, (0, 1)))
    with pytest.raises(InvalidInput, match="do not fit"):
        Host.encode(Request(codec.SETCURRENT, (300,)))
    with pytest.raises(InvalidInput, match="takes no 0 arguments"):
        Host.encode(Request(0x14))  # MOVEANGLE: not implemented by the firmware
    with pytest.raises(InvalidInput, match="do not fit"):  # past a 32-bit float
        Host.encode(Request(codec.SETMAXVELOCITY, (1e40,)))


quick = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@quick
@given(st.binary(max_size=8))
def test_any_write_is_a_request_or_a_protocol_error(data):
    try:
        request = Device.parse(data)
    except ProtocolError:
        return
    assume(not any(isinstance(a, float) and math.isnan(a) for a in request.args))
    # the host would have written those bytes (SETUP's upper two bytes are always zero)
    again = Host.encode(request)[0]
    assert again == (data[:3] + b"\0\0" if request.command == codec.SETUP else data)


@quick
@given(st.sampled_from(EVERY_COMMAND), st.binary(max_size=6))
def test_any_reply_is_a_reply_or_one_clear_error(request_, reply):
    try:
        decoded = Host.decode(request_, reply)
    except (ProtocolError, DeviceFault):
        return
    assert 0 <= decoded.flags <= 255 and len(reply) == Host.encode(request_)[1]


@quick
@given(st.floats(width=32, allow_nan=False), st.integers(0, 255), st.integers(1, 8))
def test_a_float_read_round_trips(value, flags, length):
    request = Request(codec.ANGLEMOVED)
    reply = Device.reply(Device.answer(request, value), flags, length)
    assert len(reply) == length and reply[-1] == flags
    if length == 5:
        assert struct.pack("<f", Host.decode(request, reply).value) == struct.pack("<f", value)


def test_the_emulator_runs_a_bad_request_as_the_firmware_does():
    """An unknown register or a short command: blocking, BUSY until loop() runs it."""
    clock = [100.0]
    fw = JointFirmware(35.0, -3.0, 3.0, 0.0, clock=lambda: clock[0])
    fw.write(b"\x10\x01")  # SETUP without its currents
    assert fw.read(1)[0] & codec.BUSY and fw.flags & codec.NOTENABLED
    clock[0] += 0.05
    assert not fw.read(1)[0] & codec.BUSY


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


def joint_on(smbus):
    hw = load_profile("bioscara-arm").hardware[0]
    comp = hw.joints[0]
    return Joint(I2CBus(smbus, "i2c:///dev/i2c-1"), comp)


def firmware():
    return JointFirmware(35.0, -3.0, 3.0, 0.0, clock=lambda: 100.0)


def test_three_tries_50_us_apart_then_a_clear_message():
    joint = joint_on(Flaky({0x11: firmware()}, failures=2))
    assert joint.ping() == codec.INITIAL_FLAGS  # the third try
    assert joint.bus.stats == {"packets": 1, "errors": 2, "bytes": 15}  # bytes of each try
    joint = joint_on(Flaky({0x11: firmware()}, failures=3))
    with pytest.raises(NoAnswer, match=r"no answer from 0x11 on i2c:///dev/i2c-1 \(3 tries\)") \
            as silent:
        joint.ping()
    assert "wiring" in silent.value.hint
    assert joint.bus.stats["packets"] == 1 and joint.bus.stats["errors"] == 3


def test_an_adapter_failure_is_not_tried_again():
    joint = joint_on(Flaky({0x11: firmware()}, failures=1, code=errno.EINVAL))
    with pytest.raises(DeviceError, match="I2C transfer to 0x11 on i2c:///dev/i2c-1 failed"):
        joint.ping()
    assert joint.bus.stats["packets"] == 1 and joint.bus.stats["errors"] == 1


def test_a_joint_left_disabled_or_stalled_is_a_fault_with_its_code():
    fw = firmware()
    fw.flags &= ~codec.NOTHOMED  # homed, never enabled
    joint = joint_on(SimSMBus({0x11: fw}))
    joint.ping()
    with pytest.raises(DeviceFault, match="j1 is not enabled") as disabled:
        joint.set_position(0.0)
    assert disabled.value.code == codec.NOT_ENABLED

    profile = load_profile("bioscara-arm")
    url = "i2c:///dev/i2c-sim"
    links = Links()
    stalled = firmware()
    stalled.flags = codec.STALL
    links.open[url] = I2CBus(SimSMBus({0x11: stalled}), url)
    driver = BioscaraDriver(block_for(profile, profile.hardware[0], url, links=links))
    driver.configure()
    driver.read()
    with pytest.raises(DeviceFault, match="j1 stalled at") as stall:
        driver._stalled("j1")
    assert stall.value.code == codec.STALLED
