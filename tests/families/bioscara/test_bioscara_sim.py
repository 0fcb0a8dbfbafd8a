"""The joint firmware emulator on a hand-driven clock: homing, stall detection, the deadman."""

from __future__ import annotations

import struct

import pytest

from deltoctl.families.bioscara import codec
from deltoctl.families.bioscara.emulator import JointFirmware


class Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def joint(position=0.0):
    clock = Clock()
    return JointFirmware(35.0, -3.0, 3.0, position, clock=clock), clock


def ask(fw, request, length=1):
    fw.write(request)
    return fw.read(length)


def test_power_up_flags_and_ping():
    fw, _ = joint()
    assert ask(fw, b"\x0f", 2) == b"O" + bytes([codec.NOTHOMED | codec.NOTENABLED])
    assert ask(fw, b"\x18", 5)[:4] == struct.pack("<f", 0.0)  # not homed: reads 0.0


def test_homing_runs_into_the_hard_stop_and_zeroes_the_encoder():
    fw, clock = joint(position=2.95)
    ask(fw, codec.setup(20, 20))
    flags = ask(fw, codec.home(10.0, 30, 15))[0]
    assert flags & codec.BUSY and flags & codec.NOTHOMED
    for _ in range(400):
        clock.t += 0.01
        if not ask(fw, b"\x0f", 2)[1] & codec.BUSY:
            break
    assert not fw.flags & (codec.NOTHOMED | codec.BUSY)
    assert fw.angle == pytest.approx(fw.stops[1])  # the positive hard stop
    assert codec.decode_float(ask(fw, b"\x18", 5))[0] == pytest.approx(0.0)


def test_stop_aborts_homing():
    fw, clock = joint(position=0.0)
    ask(fw, codec.setup(20, 20))
    ask(fw, codec.home(10.0, 30, 15))
    clock.t += 1.0
    flags = ask(fw, codec.write_u8(codec.STOP, 0))[0]
    assert not flags & codec.BUSY and flags & codec.NOTHOMED


def test_a_blocked_joint_stalls_and_stops():
    fw, clock = joint()
    fw.flags &= ~codec.NOTHOMED
    ask(fw, codec.setup(20, 20))
    ask(fw, codec.write_u8(codec.ENABLESTALLGUARD, 6))
    ask(fw, codec.write_float(codec.SETMAXVELOCITY, 2000.0))
    ask(fw, codec.write_float(codec.SETMAXACCELERATION, 4000.0))
    fw.blocked = True
    ask(fw, codec.write_float(codec.MOVETOANGLE, 200.0))
    for _ in range(100):
        clock.t += 0.01
        if ask(fw, b"\x0f", 2)[1] & codec.STALL:
            break
    assert fw.flags & codec.STALL and fw.speed == 0.0
    assert ask(fw, codec.write_float(codec.MOVETOANGLE, -50.0))[0] & codec.STALL  # ignored
    assert fw.target is None
    assert not ask(fw, codec.setup(20, 20))[0] & codec.STALL  # enabling clears it


def test_the_deadman_stops_a_velocity_command_after_50_ms():
    fw, clock = joint()
    ask(fw, codec.setup(20, 20))
    ask(fw, codec.write_float(codec.SETRPM, 5.0))
    for _ in range(10):  # commands every 40 ms keep it running
        clock.t += 0.04
        ask(fw, codec.write_float(codec.SETRPM, 5.0))
    assert not fw.flags & codec.NOTENABLED and fw.speed == pytest.approx(30.0)
    clock.t += 0.08
    flags = ask(fw, b"\x0f", 2)[1]
    assert flags & codec.NOTENABLED and fw.speed == 0.0 and fw.rpm == 0.0


def test_home_offset_is_kept_while_powered():
    fw, _ = joint()
    ask(fw, codec.write_float(codec.HOMEOFFSET, 3.04647))
    assert codec.decode_float(ask(fw, b"\x2e", 5))[0] == pytest.approx(3.04647)
