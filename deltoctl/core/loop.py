"""The fixed-rate cycle loop: deadlines, lateness and period-jitter percentiles, and
communication statistics."""

from __future__ import annotations

import gc
import math
import time
from collections.abc import Iterator
from dataclasses import dataclass, field


class Histogram:
    """Durations in log-spaced bins, each 1 % wider than the last from 1 µs up: constant
    memory and cost however long a loop runs (a recording of hours keeps its percentiles
    without a growing list to sort). A percentile is its bin's upper edge — at most 1 % high,
    never low — and never above the largest value seen."""

    FLOOR = 1e-6  # s: the upper edge of the first bin
    GROWTH = 1.01
    BINS = 2000  # up to FLOOR · GROWTH**BINS ≈ 440 s; longer lands in the last bin

    def __init__(self) -> None:
        self.counts = [0] * self.BINS
        self.total = 0
        self.max = 0.0
        self._scale = 1 / math.log(self.GROWTH)
        self._per_floor = 1 / self.FLOOR

    def add(self, value: float) -> None:  # once a cycle: ~0.5 µs
        self.total += 1
        if value > self.max:
            self.max = value
        if value > self.FLOOR:
            i = int(math.log(value * self._per_floor) * self._scale) + 1
            self.counts[i if i < self.BINS else -1] += 1
        else:
            self.counts[0] += 1

    def percentile(self, q: float) -> float:
        """The value below which ``q`` % of them lie (0 when there are none)."""
        if not self.total:
            return 0.0
        rank = min(self.total - 1, int(q / 100 * self.total))
        seen = 0
        for i, n in enumerate(self.counts[:-1]):
            seen += n
            if seen > rank:
                return min(self.FLOOR * self.GROWTH ** i, self.max)
        return self.max  # the last bin holds everything longer


@dataclass
class LoopStats:
    rate: float  # requested, Hz
    cycles: int = 0
    deadline_misses: int = 0  # a cycle that started a whole period late
    lateness: Histogram = field(default_factory=Histogram)  # s, actual − scheduled start
    jitter: Histogram = field(default_factory=Histogram)  # s, |actual period − period|
    started: float = field(default_factory=time.monotonic)
    ended: float | None = None  # when the loop stopped; None while it runs
    packets: int = 0
    errors: int = 0

    def summary(self) -> dict[str, float | int]:
        elapsed = max((self.ended or time.monotonic()) - self.started, 1e-9)
        return {
            "requested_rate": self.rate,
            "real_rate": round(self.cycles / elapsed, 2),
            "cycles": self.cycles,
            "deadline_misses": self.deadline_misses,
            "lateness_p50_ms": round(self.lateness.percentile(50) * 1e3, 4),
            "lateness_p99_ms": round(self.lateness.percentile(99) * 1e3, 4),
            "period_jitter_p50_ms": round(self.jitter.percentile(50) * 1e3, 4),
            "period_jitter_p99_ms": round(self.jitter.percentile(99) * 1e3, 4),
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

    def __iter__(self) -> Iterator[float]:
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

    def _cycles(self) -> Iterator[float]:
        period = 1.0 / self.rate if self.rate > 0 else 0.0
        start = time.monotonic()
        self.stats.started = start
        scheduled = start
        end = None if self.duration is None else start + self.duration
        previous = None  # the last cycle's actual start
        while end is None or scheduled < end:
            now = time.monotonic()
            if period:
                wait = scheduled - now
                if wait > 0:
                    time.sleep(wait)
                    now = time.monotonic()
                late = now - scheduled
                self.stats.lateness.add(late)
                if previous is not None:
                    self.stats.jitter.add(abs(now - previous - period))
                previous = now
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
