"""A CiA 402 servo drive, as the emulator runs it: the state machine, profile position and
profile velocity, homing, the following error, and a fault to inject.

Pure: every call takes the time (s, monotonic), so tests drive it without sleeping. Positions
are in device units (increments), velocities in increments/s. The demand runs a trapezoidal
ramp to each target at the profile velocity, acceleration and deceleration (0x6081, 0x6083,
0x6084; homing at 0x6099 and 0x609A), and target reached (statusword bit 10) is set when it
ends, exactly at the target; the actual position follows the demand, unless the axis is
stalled (a fault the emulator injects): then the following error grows until it passes the
window (0x6065) and the drive faults with 0x8611, as a real one does.
"""

from __future__ import annotations

from collections.abc import Callable

from deltoctl_canopen.codec import (
    CW_HALT,
    CW_NEW_SETPOINT,
    CW_RELATIVE,
    MODE_HOMING,
    MODE_PROFILE_POSITION,
    MODE_PROFILE_VELOCITY,
    STATES,
    SW_HOMING_ATTAINED,
    SW_HOMING_ERROR,
    SW_SETPOINT_ACK,
    SW_TARGET_REACHED,
)
from deltoctl_canopen.ramp import Ramp

SOD, READY, SWITCHED_ON, ENABLED = ("SWITCH ON DISABLED", "READY TO SWITCH ON", "SWITCHED ON",
                                    "OPERATION ENABLED")
QUICK_STOP, FAULT = "QUICK STOP ACTIVE", "FAULT"
POWERED = (READY, SWITCHED_ON, ENABLED, QUICK_STOP)
FOLLOWING_ERROR = 0x8611  # EMCY / 0x603F: following error
# what the drive keeps: (index, sub) → value, with the EDS's defaults applied at start
PARAMS = {(0x605A, 0): 2, (0x6065, 0): 1000, (0x607A, 0): 0, (0x607C, 0): 0,
          (0x6081, 0): 20000, (0x6083, 0): 100000, (0x6084, 0): 100000, (0x6098, 0): 35,
          (0x6099, 1): 10000, (0x6099, 2): 2000, (0x609A, 0): 50000, (0x60FF, 0): 0,
          (0x607D, 1): -(1 << 31), (0x607D, 2): (1 << 31) - 1}
HOMING_METHODS = range(1, 38)


class Drive402:
    def __init__(self, now: float, on_fault: Callable[[int], None] | None = None) -> None:
        self.state = SOD
        self.mode = MODE_PROFILE_POSITION
        self.params = dict(PARAMS)
        self.controlword = 0
        self.error_code = 0
        self.on_fault = on_fault  # the emulator sends the EMCY
        self.stalled = False
        self.homed = False
        self.homing_error = False
        self._homing: float | None = None  # the home offset to take at the ramp's end
        self._ack = False
        self._ramp = Ramp.still(0.0, now)  # the demand's way to its target
        self._held: float | None = None  # a stalled axis's actual position

    # -- the object dictionary's view --------------------------------------------------------
    def write(self, index: int, sub: int, value: int, now: float) -> None:
        if index == 0x6040:
            self.command(value, now)
        elif index == 0x6060:
            self.mode = value
        elif (index, sub) in self.params:
            self.params[index, sub] = value
            if index == 0x60FF and self.mode == MODE_PROFILE_VELOCITY and self.state == ENABLED:
                self._velocity(now)

    def read(self, index: int, sub: int, now: float) -> int | None:
        """The drive's live value of an object, or None for one it does not own."""
        self.update(now)
        live = {0x6041: lambda: self.statusword(now), 0x6061: lambda: self.mode,
                0x6062: lambda: round(self.demand(now)), 0x6064: lambda: round(self.actual(now)),
                0x606C: lambda: round(self.velocity(now)),
                0x60F4: lambda: round(self.demand(now) - self.actual(now)),
                0x603F: lambda: self.error_code, 0x1001: lambda: 1 if self.error_code else 0,
                0x6077: lambda: 0}
        if index in live and sub == 0:
            return int(live[index]())
        return self.params.get((index, sub))

    # -- motion ------------------------------------------------------------------------------
    def demand(self, now: float) -> float:
        return self._ramp.at(now)[0]

    def actual(self, now: float) -> float:
        return self._held if self._held is not None else self.demand(now)

    def moving(self, now: float) -> bool:
        return now < self._ramp.end

    def velocity(self, now: float) -> float:
        return 0.0 if self._held is not None else self._ramp.at(now)[1]

    def _move(self, target: float, speed: float, now: float, homing: bool = False) -> None:
        """A ramp from where the demand is, at the speed it has, to ``target``."""
        here, moving_at = self._ramp.at(now)
        accel, decel = (self.params[0x609A, 0],) * 2 if homing else \
            (self.params[0x6083, 0], self.params[0x6084, 0])
        self._ramp = Ramp.plan(here, moving_at, target, speed, accel, decel, now)
        if self.stalled and self._held is None:
            self._held = here

    def _hold(self, now: float) -> None:
        """Stop where the demand is now."""
        self._ramp = Ramp.still(self.demand(now), now)

    def _velocity(self, now: float) -> None:
        """Profile velocity: a ramp far away at the target velocity, until the next command."""
        speed = self.params[0x60FF, 0]
        if speed == 0:
            self._hold(now)
        else:
            far = self.params[0x607D, 2 if speed > 0 else 1]
            self._move(float(far), speed, now)

    def update(self, now: float) -> None:
        """What time changes: a homing ramp that ended, a following error past the window."""
        if self._homing is not None and not self.moving(now) and self._held is None:
            self._ramp = self._ramp.shifted(self._homing - self.demand(now))
            self._homing = None
            self.homed = True
        if self.state == ENABLED and self._held is not None:
            error = abs(self.demand(now) - self._held)
            if error > self.params[0x6065, 0]:
                self.fault(FOLLOWING_ERROR, now)

    # -- the state machine (CiA 402 §6.3) ----------------------------------------------------
    def command(self, cw: int, now: float) -> None:
        self.update(now)
        rising = cw & ~self.controlword
        self.controlword = cw
        if self.state == FAULT:
            if rising & 0x80:
                self.state, self.error_code = SOD, 0
                self._held = None if not self.stalled else self.actual(now)
            return
        low = cw & 0x0F
        if not cw & 0x02:  # disable voltage
            self._disable(now)
        elif not cw & 0x04:  # quick stop
            if self.state == ENABLED:
                self._hold(now)
                keep = self.params[0x605A, 0] in (5, 6, 7, 8)
                self.state = QUICK_STOP if keep else SOD
            elif self.state in (READY, SWITCHED_ON):
                self.state = SOD
        elif low & 0x07 == 0x06:  # shutdown
            if self.state in (SOD, SWITCHED_ON, ENABLED):
                self._hold(now)
                self.state = READY
        elif low == 0x07:  # switch on / disable operation
            if self.state in (READY, ENABLED):
                self._hold(now)
                self.state = SWITCHED_ON
        elif low == 0x0F and self.state in (READY, SWITCHED_ON, QUICK_STOP):  # enable operation
            self.state = ENABLED
            self._hold(now)
        if self.state == ENABLED:
            self._operate(cw, rising, now)
        else:
            self._ack = False

    def _disable(self, now: float) -> None:
        if self.state in POWERED:
            self._hold(now)
            self.state = SOD

    def _operate(self, cw: int, rising: int, now: float) -> None:
        if cw & CW_HALT:
            self._hold(now)
            self._homing = None
            return
        if not cw & CW_NEW_SETPOINT:
            self._ack = False
            return
        if not rising & CW_NEW_SETPOINT:
            return
        self._ack = True
        if self.mode == MODE_PROFILE_POSITION:
            target = float(self.params[0x607A, 0])
            if cw & CW_RELATIVE:
                target += self._ramp.target
            low, high = self.params[0x607D, 1], self.params[0x607D, 2]
            self._move(min(max(target, low), high), self.params[0x6081, 0], now)
        elif self.mode == MODE_HOMING:
            self._home(now)
        elif self.mode == MODE_PROFILE_VELOCITY:
            self._velocity(now)

    def _home(self, now: float) -> None:
        method, offset = self.params[0x6098, 0], float(self.params[0x607C, 0])
        self.homing_error = method not in HOMING_METHODS
        if self.homing_error:
            return
        self.homed = False
        if method in (35, 37):  # the current position is home
            self._hold(now)
            self._homing = offset
            self.update(now)
        else:  # a search for the switch and the index, here at device zero
            self._homing = offset
            self._move(0.0, self.params[0x6099, 1], now, homing=True)

    def fault(self, code: int, now: float) -> None:
        """A drive fault: motion stops, Fault, the error code, an EMCY."""
        self._hold(now)
        if self._held is not None:
            self._held = self.actual(now)
            self._ramp = Ramp.still(self._held, now)
        self.state, self.error_code = FAULT, code
        self._homing = None
        if self.on_fault is not None:
            self.on_fault(code)

    def statusword(self, now: float) -> int:
        word = STATES[self.state][1] | 0x200  # remote
        if self.state in POWERED:
            word |= 0x10  # voltage enabled
        if self.state in (READY, SWITCHED_ON, ENABLED):
            word |= 0x20  # quick stop not active
        return word | self._mode_bits(now)

    def _mode_bits(self, now: float) -> int:
        still = not self.moving(now) and self._held is None
        bits = 0
        if self.mode == MODE_HOMING:
            if self.homing_error:
                bits |= SW_HOMING_ERROR
            elif self.homed and self._homing is None:
                bits |= SW_HOMING_ATTAINED | SW_TARGET_REACHED
            return bits
        if self._ack:
            bits |= SW_SETPOINT_ACK
        return bits | (SW_TARGET_REACHED if still else 0)
