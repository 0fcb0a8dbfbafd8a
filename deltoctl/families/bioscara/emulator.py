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
from typing import TYPE_CHECKING, ClassVar

from deltoctl.core.emulator_contract import ServeContext
from deltoctl.errors import ProtocolError
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
NO_OPS = frozenset({codec.SETBRAKEMODE, codec.GETDRIVERRPM})  # brake mode is not modelled


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

    # -- the I2C side: requests through the device role of the codec ----------------------------
    def write(self, data: bytes) -> None:
        self._request()
        if not data:
            return
        try:
            request = codec.Device.parse(data)
        except ProtocolError:  # unknown, or not the command's arguments: a blocking no-op
            self._block(data[0])
            self.payload = b""
            return
        self.payload = codec.Device.answer(request, self._handle(request))

    def read(self, length: int) -> bytes:
        """The last command's payload, then the flags (a one-byte read: the flags alone)."""
        self._request()
        return codec.Device.reply(self.payload, self.flags, length)

    def _request(self) -> None:
        self.advance(self.clock())
        self.last_request = self.now
        self.requests += 1

    def _handle(self, request: codec.Request) -> float | None:
        """Runs one command (the ISR's non-blocking handler, or queues a blocking one); the
        value a read answers, None for a command."""
        run = self._HANDLERS.get(request.command)
        if run is None:
            self._block(request.command)
            return None
        return run(self, *request.args)

    def _block(self, command: int) -> None:
        """Blocking (or unknown): BUSY until loop() runs it."""
        if command in NO_OPS:
            return
        self.flags |= codec.BUSY
        self.busy_until = self.now + (ORIENTATION_TIME if command == codec.CHECKORIENTATION
                                      else TICK)

    def _nothing(self, *args: float) -> None:
        return None

    def _angle_moved(self) -> float:
        homed = not self.flags & codec.NOTHOMED
        return self.angle - self.home_angle if homed else 0.0

    def _encoder_rpm(self) -> float:
        return self.measured / 6.0

    def _home_offset(self, value: float | None = None) -> float | None:
        if value is None:
            return self.home_offset
        self.home_offset = value
        return None

    def _setup(self, drive: int, hold: int) -> None:
        self.drive, self.hold = drive, hold
        self._stop()
        self.flags &= ~(codec.STALL | codec.NOTENABLED)
        self.stallguard = None

    def _set_rpm(self, rpm: float) -> None:
        if not self.flags & codec.STALL:
            self.rpm, self.target = rpm, None

    def _move_steps(self, steps: int) -> None:
        self.rpm, self.target = 0.0, self.command + steps / STEPS_PER_DEG

    def _move_to_angle(self, angle: float) -> None:
        if not self.flags & codec.STALL:
            self.rpm, self.target = 0.0, self.home_angle + angle

    def _set_current(self, value: int) -> None:
        self.drive = value
        if value == 0:
            self._disable()

    def _set_hold_current(self, value: int) -> None:
        self.hold = value
        if value == 0:
            self._disable()

    def _set_max_acceleration(self, value: float) -> None:
        self.max_acceleration = abs(value)

    def _set_max_velocity(self, value: float) -> None:
        self.max_velocity = abs(value)

    def _enable_stallguard(self, threshold: int) -> None:
        self.stallguard = threshold * 10.0
        self.flags &= ~codec.STALL

    def _disable_closed_loop(self, _mode: int) -> None:
        self._disable()

    def _stop_command(self, _mode: int) -> None:
        self._stop()
        self.flags &= ~codec.BUSY
        if self.homing is not None:  # an aborted HOME leaves the joint not homed
            self._end_homing(homed=False)

    def _home(self, direction: int, rpm: int, sensitivity: int, current: int) -> None:
        self._stop()
        self.flags |= codec.BUSY | codec.NOTHOMED
        self.homing = {"start": self.now + HOME_PAUSE, "rpm": rpm if direction else -rpm,
                       "sensitivity": sensitivity, "current": current, "drive": self.drive}

    _HANDLERS: ClassVar[dict[int, Callable[..., float | None]]] = {
        codec.PING: _nothing, codec.ANGLEMOVED: _angle_moved,
        codec.GETENCODERRPM: _encoder_rpm, codec.HOMEOFFSET: _home_offset,
        codec.SETUP: _setup, codec.SETRPM: _set_rpm, codec.MOVESTEPS: _move_steps,
        codec.MOVETOANGLE: _move_to_angle, codec.SETCURRENT: _set_current,
        codec.SETHOLDCURRENT: _set_hold_current,
        codec.SETMAXACCELERATION: _set_max_acceleration,
        codec.SETMAXVELOCITY: _set_max_velocity, codec.ENABLESTALLGUARD: _enable_stallguard,
        codec.DISABLECLOSEDLOOP: _disable_closed_loop, codec.STOP: _stop_command,
        codec.HOME: _home,
    }

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
