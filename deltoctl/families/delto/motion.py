"""Current-bounded position moves on the effort interface.

A PD loop turns position error into an effort command, clamped to the profile's current cap;
the setpoint ramps at the requested velocity. The gripper has no moving flag: the move settles
once the ramp has reached every target and each joint then stays within tolerance (and
within a quarter of a smaller step, or POSITION_NOISE) and still (slower than SETTLE_SPEED) for
SETTLE_CYCLES reads in a row, or fails when its time runs out,
naming the joints that did not. The caller's System sets duty 0 after.
Each cycle's setpoints (the ramped position, the effort sent) go to the driver's ``on_cycle``
hook when a verb set one (``jog --record``); ``replay`` sends the recorded efforts again.
"""

from __future__ import annotations

import math
import time
from typing import Any, Protocol

from deltoctl.core.driver import CycleHook, MoveResult, Progress
from deltoctl.core.envelope import DEFAULT_TOLERANCE, DEFAULT_VELOCITY
from deltoctl.core.loop import CycleLoop
from deltoctl.errors import LinkLost, NoAnswer
from deltoctl.families.delto.models import KT

DEFAULT_CURRENT_CAP = 150.0  # mA
SETTLE_CYCLES = 10
SETTLE_SPEED = 0.05  # rad/s: slower than this counts as still
RATE = 200.0  # Hz
# Two counts of the 0.1° encoders: closer than this is within a still joint's reading noise
POSITION_NOISE = math.radians(0.2)
NAN = float("nan")


class EffortDriver(Protocol):
    """What a move needs of a driver (the Delto driver's, which knows nothing of moves but
    ``move`` calling ``move_to``)."""

    profile: Any
    hw: Any
    connected: bool
    halted: Any  # threading.Event
    on_cycle: CycleHook | None

    @property
    def stats(self) -> dict[str, int]: ...
    def read(self) -> dict[str, float]: ...
    def write_efforts(self, efforts: dict[str, float]) -> None: ...
    def stop(self) -> None: ...


def effort_cap(profile: Any) -> float:
    """The effort (N·m) the profile's current cap allows a motion command."""
    return (profile.safety.current_cap or DEFAULT_CURRENT_CAP) / 1000.0 * KT


def move_to(driver: EffortDriver, targets: dict[str, float], velocity: float | None = None,
            timeout: float | None = None, progress: Progress | None = None) -> MoveResult:
    max_effort = effort_cap(driver.profile)
    tolerance = driver.profile.safety.home_tolerance or DEFAULT_TOLERANCE
    speed = velocity or DEFAULT_VELOCITY
    kp = max_effort / tolerance  # full effort at one tolerance of error
    kd = kp * 0.02
    values = driver.read()
    if not driver.connected:
        raise NoAnswer(f"{driver.hw.name} is not answering")
    reconnects = driver.stats["reconnects"]
    setpoints = {j: values[f"{j}/position"] for j in targets}
    first_error = max((abs(targets[j] - setpoints[j]) for j in targets), default=0.0) or 1.0
    # where each joint counts as arrived: within tolerance, and past most of a step smaller
    # than it (a joint that starts within tolerance still goes the way)
    arrive = {j: min(tolerance, max(POSITION_NOISE, abs(targets[j] - setpoints[j]) / 4))
              for j in targets}
    if timeout is None:
        # the ramp's own time and home_timeout more (else 5 s), as every family's
        timeout = first_error / speed + (driver.profile.safety.home_timeout or 5.0)
    settled_for = 0
    elapsed = 0.0  # a move halted before its first cycle took none
    errors: dict[str, float] = {}
    loop = CycleLoop(RATE)
    step = speed / RATE
    for _ in loop:
        values = driver.read()
        if not driver.connected or driver.stats["reconnects"] != reconnects:
            # a move never resumes by itself after a lost link: a person decides
            driver.stop()
            raise LinkLost(f"the link to {driver.hw.name} was lost during the move; the "
                           "motion was stopped and does not resume by itself",
                           hint="check the link, then move again")
        if driver.halted.is_set():
            break
        efforts = {}
        moving = False  # still ramping, or a joint not yet still
        for joint, target in targets.items():
            sp = setpoints[joint]
            setpoints[joint] = (target if abs(target - sp) <= step
                                else sp + math.copysign(step, target - sp))
            pos = values[f"{joint}/position"]
            vel = values.get(f"{joint}/velocity", 0.0)
            effort = kp * (setpoints[joint] - pos) - kd * vel
            efforts[joint] = max(-max_effort, min(max_effort, effort))
            errors[joint] = abs(target - pos)
            moving = moving or abs(vel) > SETTLE_SPEED or setpoints[joint] != target
        driver.write_efforts(efforts)
        hook = driver.on_cycle
        if hook is not None:
            hook(time.time_ns(), values, {j: (setpoints[j], NAN, efforts[j]) for j in targets})
        worst = max(errors.values(), default=0.0)
        if progress:
            progress(max(0.0, 1.0 - worst / first_error))
        arrived = all(errors[j] <= arrive[j] for j in targets)
        settled_for = settled_for + 1 if arrived and not moving else 0
        elapsed = time.monotonic() - loop.stats.started
        if settled_for >= SETTLE_CYCLES or elapsed > timeout:
            break
    driver.stop()
    if settled_for >= SETTLE_CYCLES:
        return MoveResult(True, elapsed, errors, [])
    unsettled = [j for j, e in errors.items() if e > arrive[j]] or list(targets)
    return MoveResult(False, elapsed, errors, unsettled)
