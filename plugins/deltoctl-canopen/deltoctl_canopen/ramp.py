"""A trapezoidal move, as a CiA 402 drive's profile generator runs one: from where the axis is,
at the speed it has, to a target — accelerating at the profile acceleration (0x6083), never
faster than the profile velocity (0x6081), braking at the profile deceleration (0x6084) — and
stopping exactly there. An axis moving away from the target, or too fast to stop before it,
brakes first, then comes back.

Pure: a plan is phases of constant acceleration from a start; ``at(t)`` is the position and
velocity at any time. The emulator's drive runs it; the driver asks it how long a move takes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

Phase = tuple[float, float]  # (seconds, acceleration), in the direction of the target


@dataclass(frozen=True)
class Ramp:
    t0: float
    p0: float
    v0: float
    target: float
    phases: tuple[Phase, ...] = ()

    @classmethod
    def still(cls, position: float, now: float) -> Ramp:
        return cls(now, position, 0.0, position)

    @classmethod
    def plan(cls, position: float, velocity: float, target: float, speed: float,
             accel: float, decel: float, now: float) -> Ramp:
        """The move from ``position`` at ``velocity`` to ``target``; ``speed``, ``accel`` and
        ``decel`` are magnitudes (each at least 1 unit, a drive's smallest)."""
        sign = 1.0 if target >= position else -1.0
        phases = _phases(abs(target - position), sign * velocity, max(1.0, abs(speed)),
                         max(1.0, abs(accel)), max(1.0, abs(decel)))
        return cls(now, position, velocity, target,
                   tuple((t, sign * a) for t, a in phases if t > 0))

    @property
    def seconds(self) -> float:
        return sum(t for t, _ in self.phases)

    @property
    def end(self) -> float:
        return self.t0 + self.seconds

    def at(self, now: float) -> tuple[float, float]:
        """(position, velocity) at ``now``: the target, at rest, once the move is over."""
        if now >= self.end:
            return self.target, 0.0
        p, v, left = self.p0, self.v0, max(0.0, now - self.t0)
        for seconds, accel in self.phases:
            dt = min(seconds, left)
            p += v * dt + accel * dt * dt / 2
            v += accel * dt
            left -= dt
            if left <= 0:
                break
        return p, v

    def shifted(self, offset: float) -> Ramp:
        """The same move with every position moved by ``offset`` (a new home)."""
        return Ramp(self.t0, self.p0 + offset, self.v0, self.target + offset, self.phases)


def _phases(distance: float, v: float, speed: float, accel: float, decel: float) -> list[Phase]:
    """The phases of a move of ``distance`` (≥ 0) that starts at velocity ``v`` (positive
    towards the target), in the target's direction."""
    phases: list[Phase] = []
    if v < 0:  # moving away: stop first
        phases.append((-v / decel, decel))
        distance += v * v / (2 * decel)
        v = 0.0
    if v > speed:  # faster than the profile: slow down to it
        phases.append(((v - speed) / decel, -decel))
        distance -= (v * v - speed * speed) / (2 * decel)
        v = speed
    braking = v * v / (2 * decel)
    if braking > distance:  # too fast to stop in time: stop past the target, then come back
        phases.append((v / decel, -decel))
        back = _phases(braking - distance, 0.0, speed, accel, decel)
        return [*phases, *((t, -a) for t, a in back)]
    peak = min(speed, math.sqrt((2 * accel * decel * distance + decel * v * v) / (accel + decel)))
    rising = (peak * peak - v * v) / (2 * accel)
    falling = peak * peak / (2 * decel)
    cruise = (distance - rising - falling) / peak if peak > 0 else 0.0
    return [*phases, ((peak - v) / accel, accel), (max(0.0, cruise), 0.0),
            (peak / decel, -decel)]
