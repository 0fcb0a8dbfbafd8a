"""The one fixed-rate cycle runner: every cycle reads the System once and hands the frame to
the sinks (live table, NDJSON, MCAP recorder, progress); once a second the sinks see the loop's
timing and the buses' communication statistics. Ctrl-C, SIGTERM and SIGHUP end it cleanly."""

from __future__ import annotations

import contextlib
import math
import signal
import time
from collections.abc import Callable, Iterator
from typing import Any

from deltoctl.core.loop import CommLoop, CycleLoop, LoopStats
from deltoctl.errors import InvalidInput

STATS_PERIOD = 1.0  # s between the sinks' statistics


def check_loop(rate: float, duration: float | None) -> None:
    """A loop's rate and duration: finite and positive."""
    if not (math.isfinite(rate) and 0 < rate <= 100_000):
        raise InvalidInput(f"--rate must be a positive number of Hz up to 100000, got {rate:g}")
    if duration is not None and not (math.isfinite(duration) and duration > 0):
        raise InvalidInput(f"--duration must be a positive number of seconds, got {duration:g}")


class Sink:
    """What the runner feeds; every method is optional."""

    def frame(self, t_ns: int, values: dict[str, float]) -> None:
        """One cycle's values (the dict is reused: copy what you keep)."""

    def periodic(self, t_ns: int, stats: LoopStats, comm_loops: list[CommLoop]) -> None:
        """Once a second: the loop's statistics and the buses' own loops."""

    def close(self, stats: LoopStats) -> None:
        """The loop has ended (also on Ctrl-C or an error)."""


@contextlib.contextmanager
def interrupted_by_signals() -> Iterator[None]:
    """SIGTERM (a supervisor) and SIGHUP (a closed terminal or SSH session) interrupt like
    Ctrl-C, so every way out runs the same clean-up; the old handlers come back after."""
    previous = {}
    for sig in (signal.SIGTERM, getattr(signal, "SIGHUP", None)):
        if sig is not None:
            with contextlib.suppress(ValueError):  # not the main thread
                previous[sig] = signal.signal(sig, signal.default_int_handler)
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


PRIORITY = 50  # SCHED_FIFO priority of a paced loop: ros2_control's controller manager's default


@contextlib.contextmanager
def realtime(rate: float) -> Iterator[bool]:
    """Run a paced loop at real-time priority where the system allows it (root, or
    CAP_SYS_NICE / an rtprio limit, as ros2_control asks of its control loop), so the devices'
    and the recorder's processes cannot delay a cycle; quietly as before where it does not.
    An unpaced loop never runs real-time: it would take a whole CPU from everything else."""
    import os

    if rate <= 0 or not hasattr(os, "sched_setscheduler"):
        yield False
        return
    try:
        before = os.sched_getscheduler(0), os.sched_getparam(0)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(PRIORITY))
    except (OSError, AttributeError):
        yield False
        return
    try:
        yield True
    finally:
        os.sched_setscheduler(0, before[0], before[1])


def run_cycles(system: Any, rate: float, duration: float | None, sinks: list[Sink],
               write: Callable[[dict[str, float]], None] | None = None) -> LoopStats:
    """Run until ``duration`` passes or an interrupt; returns the loop's statistics. ``write``
    sends each cycle's commands after the read. Sinks are closed whatever happens."""
    loop = CycleLoop(rate, duration)
    comm_loops = system.comm_loops()
    members = [m.driver for m in system.members]
    stats = loop.stats
    next_stats = time.monotonic() + STATS_PERIOD
    try:
        with interrupted_by_signals(), realtime(rate):
            for _ in loop:
                before = sum(d.stats["errors"] for d in members)
                values = system.read()
                if write is not None:
                    write(values)
                stats.packets += 1
                stats.errors += sum(d.stats["errors"] for d in members) - before
                t_ns = time.time_ns()
                for sink in sinks:
                    sink.frame(t_ns, values)
                if time.monotonic() >= next_stats:
                    next_stats += STATS_PERIOD
                    for sink in sinks:
                        sink.periodic(t_ns, stats, comm_loops)
    except KeyboardInterrupt:
        pass
    finally:
        if stats.ended is None:
            stats.ended = time.monotonic()
        failed: BaseException | None = None
        for sink in sinks:  # each one closes, even when another fails
            try:
                sink.close(stats)
            except BaseException as exc:
                failed = failed or exc
        if failed is not None:
            raise failed
    return stats
