"""The fixed-rate cycle loop: deadlines, lateness percentiles and communication statistics."""

from __future__ import annotations

import gc
import time
from dataclasses import dataclass, field


@dataclass
class LoopStats:
    rate: float  # requested, Hz
    cycles: int = 0
    deadline_misses: int = 0  # a cycle that started a whole period late
    lateness: list[float] = field(default_factory=list)  # s, actual − scheduled start
    started: float = field(default_factory=time.monotonic)
    ended: float | None = None  # when the loop stopped; None while it runs
    packets: int = 0
    errors: int = 0

    def percentile(self, q: float) -> float:
        if not self.lateness:
            return 0.0
        ordered = sorted(self.lateness)
        return ordered[min(len(ordered) - 1, int(q / 100 * len(ordered)))]

    def summary(self) -> dict[str, float | int]:
        elapsed = max((self.ended or time.monotonic()) - self.started, 1e-9)
        return {
            "requested_rate": self.rate,
            "real_rate": round(self.cycles / elapsed, 2),
            "cycles": self.cycles,
            "deadline_misses": self.deadline_misses,
            "lateness_p50_ms": round(self.percentile(50) * 1e3, 4),
            "lateness_p99_ms": round(self.percentile(99) * 1e3, 4),
            "packets": self.packets,
            "errors": self.errors,
            "error_rate_perc": round(100 * self.errors / self.packets, 3) if self.packets else 0.0,
        }


class CycleLoop:
    """``for t in CycleLoop(rate, duration): ...`` yields each cycle's scheduled start.

    A cycle late by a whole period is counted as a deadline miss and the schedule restarts
    from now, so one stall does not cause a burst of catch-up cycles. ``rate=0``: unpaced.
    """

    def __init__(self, rate: float, duration: float | None = None) -> None:
        self.rate = rate
        self.duration = duration
        self.stats = LoopStats(rate)

    def __iter__(self):  # type: ignore[no-untyped-def]
        # The garbage collector's pauses land at random in a cycle; the loop allocates little
        # that lives, so it is paused for the run and catches up afterwards.
        gc_was_enabled = gc.isenabled()
        gc.disable()
        try:
            yield from self._cycles()
        finally:
            if self.stats.ended is None:  # stopped early (Ctrl-C): it ends now
                self.stats.ended = time.monotonic()
            if gc_was_enabled:
                gc.enable()

    def _cycles(self):  # type: ignore[no-untyped-def]
        period = 1.0 / self.rate if self.rate > 0 else 0.0
        start = time.monotonic()
        self.stats.started = start
        scheduled = start
        end = None if self.duration is None else start + self.duration
        while end is None or scheduled < end:
            now = time.monotonic()
            if period:
                wait = scheduled - now
                if wait > 0:
                    time.sleep(wait)
                    now = time.monotonic()
                late = now - scheduled
                self.stats.lateness.append(late)
                if late > period:
                    self.stats.deadline_misses += 1
                    scheduled = now
            self.stats.cycles += 1
            yield scheduled
            scheduled = scheduled + period if period else time.monotonic()
        # the last cycle's period ends where the next one would start
        self.stats.ended = max(time.monotonic(), scheduled)


class CommLoop:
    """One bus loop inside a faster cycle (the MH5's LoopWithCommunicationStats): ``due()``
    is true at most once per period, and the loop counts its packets and errors, short-term
    (cleared by each ``report``) and in total. ``rate=0``: every cycle."""

    EARLY = 0.1  # of a period: a cycle that comes a little early still runs

    def __init__(self, name: str, rate: float) -> None:
        self.name = name
        self.period = 1.0 / rate if rate > 0 else 0.0
        self.next = 0.0  # when the loop is next due; the schedule advances by whole periods
        self.packets = self.errors = self.total_packets = self.total_errors = 0
        self.since: float | None = None  # start of the short-term count

    def due(self) -> bool:
        if not self.period:
            return True
        now = time.monotonic()
        if now < self.next - self.EARLY * self.period:
            return False
        self.next += self.period
        if self.next < now:  # the first run, or after a stall: no burst to catch up
            self.next = now + self.period
        return True

    def count(self, ok: bool) -> None:
        if self.since is None:
            self.since = time.monotonic()
        self.packets += 1
        self.total_packets += 1
        if not ok:
            self.errors += 1
            self.total_errors += 1

    def report(self) -> dict[str, float | int]:
        """The MH5 communication statistics' keys; clears the short-term counters."""
        now = time.monotonic()

        def rate(errors: int, packets: int) -> float:
            return round(100 * errors / packets, 3) if packets else 0.0

        values = {"packets": self.packets, "errors": self.errors,
                  "error_rate_perc": rate(self.errors, self.packets),
                  "total_packets": self.total_packets, "total_errors": self.total_errors,
                  "total_error_rate_perc": rate(self.total_errors, self.total_packets),
                  "real_rate": round(self.packets / max(now - (self.since or now), 1e-9), 2)}
        self.packets = self.errors = 0
        self.since = now
        return values
