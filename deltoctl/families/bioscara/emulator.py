"""The Bioscara joint firmware (uStepper S32, reference §1.2-1.4) as an I2C device model.

Time runs lazily: each transaction first advances the joint to now in the firmware's 10 ms
loop ticks, so the deadman, stall detection and homing behave the same whether the joint is
asked every millisecond or once a second. The joint runs in motor degrees; its hard stops
are the profile's min and max, where homing ends (the driver then takes max or min as its
offset, so the joint reads true positions after homing).
"""

from __future__ import annotations

import math
import random
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

from deltoctl.core.serving import ServeContext
from deltoctl.families.bioscara import codec

if TYPE_CHECKING:
    from deltoctl.profile.model import Hardware

TICK = 0.01  # s, the firmware's loop period
DEADMAN = 0.05  # s without an I2C request while a velocity is set
HOME_PAUSE = 0.5  # s the firmware waits after stop(HARD) before homing
ORIENTATION_TIME = 0.2  # s a CHECKORIENTATION keeps the joint BUSY
STEPS_PER_DEG = 200 / 360
# stall detection (stall.h, filters.h): constants for every joint
STALL_SLOPE, STALL_B1, STALL_B2, STALL_WINDOW_OFFSET = 0.0, 12.0, 450.0, 90.0
SPIKE = 100.0
LPF_GAIN = TICK / 0.1  # Ts/τ with K = 1
# emulator assumption: the PID error counts motor degrees between command and encoder
ERROR_PER_DEG = 1.0
NO_OPS = frozenset({codec.SETBRAKEMODE, 0x12})  # brake mode is not modelled; GETDRIVERRPM


class JointFirmware:
    """One joint: flags, currents, motion in motor degrees, stall detection and homing."""

    def __init__(self, reduction: float, low: float, high: float, position: float,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.clock = clock
        stops = sorted((math.degrees(reduction * low), math.degrees(reduction * high)))
        self.stops = stops  # motor degrees of the hard stops
        self.angle = math.degrees(reduction * position)  # true motor angle
        self.command = self.angle  # where the closed loop wants the motor
        self.home_angle = self.angle + random.uniform(-90, 90)  # the encoder's zero, unknown
        self.flags = codec.INITIAL_FLAGS
        self.drive = self.hold = 0
        self.stallguard: float | None = None  # threshold, when enabled
        self.max_velocity = 10 / STEPS_PER_DEG  # deg/s, power-up MAXVEL 10 steps/s
        self.max_acceleration = 100 / STEPS_PER_DEG
        self.rpm = 0.0  # velocity mode set point (qd_set)
        self.target: float | None = None  # position mode set point, motor degrees
        self.speed = 0.0  # deg/s of the commanded profile
        self.measured = 0.0  # deg/s the encoder sees
        self.filtered = self.previous_error = 0.0
        self.home_offset = 0.0
        self.homing: dict | None = None
        self.busy_until = 0.0
        self.blocked = False  # fault: something holds the joint where it is
        self.payload = b""  # the reply before the flags byte
        self.now = self.last_request = clock()
        self.requests = 0

    # -- the I2C side ----------------------------------------------------------------------------
    def write(self, data: bytes) -> None:
        self._request()
        if not data:
            return
        self.payload = self._handle(data[0], data[1:])

    def read(self, length: int) -> bytes:
        """The last command's payload, then the flags (a one-byte read: the flags alone)."""
        self._request()
        payload = self.payload[:length - 1].ljust(length - 1, b"\0")
        return payload + bytes([self.flags])

    def _request(self) -> None:
        self.advance(self.clock())
        self.last_request = self.now
        self.requests += 1

    def _handle(self, register: int, p: bytes) -> bytes:
        """Runs one command (the ISR's non-blocking handler, or queues a blocking one); the
        return value is the payload before the flags."""
        f = codec.FLOAT.unpack_from
        if register == codec.PING:
            return bytes([codec.ACK])
        if register == codec.ANGLEMOVED:
            homed = not self.flags & codec.NOTHOMED
            return codec.FLOAT.pack(self.angle - self.home_angle if homed else 0.0)
        if register == codec.GETENCODERRPM:
            return codec.FLOAT.pack(self.measured / 6.0)
        if register == codec.HOMEOFFSET:
            if len(p) >= 4:
                self.home_offset = f(p)[0]
                return b""
            return codec.FLOAT.pack(self.home_offset)
        if register == codec.SETUP and len(p) >= 2:
            self.drive, self.hold = p[0], p[1]
            self._stop()
            self.flags &= ~(codec.STALL | codec.NOTENABLED)
            self.stallguard = None
        elif register == codec.SETRPM and len(p) >= 4:
            if not self.flags & codec.STALL:
                self.rpm, self.target = f(p)[0], None
        elif register == codec.MOVESTEPS and len(p) >= 4:
            self.rpm, self.target = 0.0, self.command + codec.INT32.unpack_from(p)[0] / \
                STEPS_PER_DEG
        elif register == codec.MOVETOANGLE and len(p) >= 4:
            if not self.flags & codec.STALL:
                self.rpm, self.target = 0.0, self.home_angle + f(p)[0]
        elif register in (codec.SETCURRENT, codec.SETHOLDCURRENT) and p:
            if register == codec.SETCURRENT:
                self.drive = p[0]
            else:
                self.hold = p[0]
            if p[0] == 0:
                self._disable()
        elif register == codec.SETMAXACCELERATION and len(p) >= 4:
            self.max_acceleration = abs(f(p)[0])
        elif register == codec.SETMAXVELOCITY and len(p) >= 4:
            self.max_velocity = abs(f(p)[0])
        elif register == codec.ENABLESTALLGUARD and p:
            self.stallguard = p[0] * 10.0
            self.flags &= ~codec.STALL
        elif register == codec.DISABLECLOSEDLOOP:
            self._disable()
        elif register == codec.STOP:
            self._stop()
            self.flags &= ~codec.BUSY
            if self.homing is not None:  # an aborted HOME leaves the joint not homed
                self._end_homing(homed=False)
        elif register == codec.HOME and len(p) >= 4:
            direction, rpm, sensitivity, current = p[:4]
            self._stop()
            self.flags |= codec.BUSY | codec.NOTHOMED
            self.homing = {"start": self.now + HOME_PAUSE, "rpm": rpm if direction else -rpm,
                           "sensitivity": sensitivity, "current": current,
                           "drive": self.drive}
        elif register not in NO_OPS:
            self.flags |= codec.BUSY  # blocking (or unknown): BUSY until loop() runs it
            self.busy_until = self.now + (ORIENTATION_TIME if register ==
                                          codec.CHECKORIENTATION else TICK)
        return b""

    # -- the firmware's loop ---------------------------------------------------------------------
    def _stop(self) -> None:
        self.rpm, self.target, self.speed, self.measured = 0.0, None, 0.0, 0.0
        self.command = self.angle

    def _disable(self) -> None:
        self._stop()
        self.flags |= codec.NOTENABLED

    def advance(self, now: float) -> None:
        while self.now + TICK <= now:
            self.now += TICK
            self._tick()

    def _tick(self) -> None:
        if (self.rpm and not self.flags & codec.NOTENABLED
                and self.now - self.last_request > DEADMAN):
            self._disable()  # the deadman: velocity commands stopped coming
        if self.busy_until and self.now >= self.busy_until and self.homing is None:
            self.flags &= ~codec.BUSY
            self.busy_until = 0.0
        self._move()
        error = abs(self.command - self.angle) * ERROR_PER_DEG
        if self.homing is not None:
            self._home_step(error)
        elif self.stallguard is not None and not self.flags & (codec.STALL | codec.NOTENABLED):
            self._stall_step(error)

    def _wanted_speed(self) -> float:
        if self.flags & codec.NOTENABLED:
            return 0.0
        if self.homing is not None:
            return self.homing["rpm"] * 6.0 if self.now >= self.homing["start"] else 0.0
        if self.target is None:
            return self.rpm * 6.0
        distance = self.target - self.command
        reach = math.sqrt(2 * self.max_acceleration * abs(distance))
        return math.copysign(min(self.max_velocity, reach), distance)

    def _move(self) -> None:
        wanted = self._wanted_speed()
        if self.homing is None:  # profiles ramp; homing starts at speed, as setRPM does
            step = self.max_acceleration * TICK
            wanted = min(max(wanted, self.speed - step), self.speed + step)
        self.speed = wanted
        self.command += wanted * TICK
        if self.target is not None and abs(self.target - self.command) < abs(wanted) * TICK:
            self.command, self.speed = self.target, 0.0
        low, high = (self.angle, self.angle) if self.blocked else self.stops
        before, self.angle = self.angle, min(max(self.command, low), high)
        self.measured = (self.angle - before) / TICK

    def _stall_step(self, error: float) -> None:
        if error - self.previous_error > SPIKE:
            error = self.previous_error  # spike rejection
        self.previous_error = error
        self.filtered = (1 - LPF_GAIN) * self.filtered + LPF_GAIN * error
        qd = abs(math.radians(self.measured))
        threshold = STALL_SLOPE * qd + self.stallguard
        if STALL_B1 <= qd <= STALL_B2:
            threshold += STALL_WINDOW_OFFSET
        if self.filtered > threshold:
            self.flags |= codec.STALL
            self._stop()
            self.filtered = self.previous_error = 0.0

    def _home_step(self, error: float) -> None:
        assert self.homing is not None
        if error > self.homing["sensitivity"]:  # ran into the hard stop: this is home
            self.home_angle = self.angle
            self._end_homing(homed=True)

    def _end_homing(self, homed: bool) -> None:
        assert self.homing is not None
        if homed:
            self.flags &= ~(codec.NOTHOMED | codec.STALL)
        else:
            self.flags |= codec.NOTHOMED
        self.drive = self.homing["drive"]
        self.homing = None
        self._stop()
        self.flags &= ~codec.BUSY


def joints_for_block(hw: Hardware, park: float = 0.5) -> dict[int, JointFirmware]:
    """A firmware per joint of the block, at its ``i2c_address``, each parked ``park`` seconds
    of homing travel from the hard stop it homes against."""
    joints = {}
    for joint in hw.joints:
        p = joint.params
        low, high = float(p["min"]), float(p["max"])
        home = joint.command("home")
        speed = float(home.params.get("speed", 0.0)) if home else 0.0
        stop = high if speed > 0 else low
        start = min(max(stop - speed * park, low), high)
        joints[int(str(p["i2c_address"]), 0)] = JointFirmware(
            float(p["reduction"]), low, high, start)
    return joints


def serve(ctx: ServeContext, blocks: list[Hardware]) -> dict[str, str]:
    """The joints on their block's simulated I2C bus (shared with other I2C devices)."""
    buses = {}
    for hw in blocks:
        bus, url = ctx.i2c_bus(hw.bus or "i2c")
        joints = joints_for_block(hw)
        missing = {int(str(j.params["i2c_address"]), 0) for j in ctx.named("missing", hw)}
        for j in ctx.named("stall", hw):
            joints[int(str(j.params["i2c_address"]), 0)].blocked = True
        bus.devices.update({a: d for a, d in joints.items() if a not in missing})
        buses[hw.bus or "i2c"] = url
    return buses
