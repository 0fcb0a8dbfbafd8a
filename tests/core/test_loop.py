"""The cycle loop's statistics: lateness percentiles in constant memory, deadline misses."""

from __future__ import annotations

import itertools
import random
import time

import pytest

from deltoctl.core.loop import CycleLoop, Histogram


def test_histogram_percentiles_are_within_one_percent_and_never_low():
    rng = random.Random(7)
    values = [rng.lognormvariate(-9, 1.5) for _ in range(20_000)]  # ~120 µs, long tail
    hist = Histogram()
    for v in values:
        hist.add(v)
    ordered = sorted(values)
    for q in (0, 50, 90, 99, 99.9, 100):
        exact = ordered[min(len(ordered) - 1, int(q / 100 * len(ordered)))]
        assert exact <= hist.percentile(q) <= exact * 1.01 + Histogram.FLOOR, q
    assert hist.percentile(100) == max(values)
    assert len(hist.counts) == Histogram.BINS  # however many values went in


def test_histogram_edges():
    hist = Histogram()
    assert hist.percentile(99) == 0.0
    for v in (0.0, 5e-7, 1e6):  # below the first bin's edge, and past the last bin
        hist.add(v)
    assert hist.percentile(0) == pytest.approx(Histogram.FLOOR)
    assert hist.percentile(100) == 1e6


def test_a_stalled_cycle_is_one_deadline_miss_and_no_burst_follows():
    loop = CycleLoop(100.0, duration=0.2)
    starts = []
    for scheduled in loop:
        starts.append(scheduled)
        if len(starts) == 3:
            time.sleep(0.035)  # three and a half periods
    summary = loop.stats.summary()
    assert summary["deadline_misses"] >= 1
    assert summary["cycles"] == len(starts) < 20
    assert summary["lateness_p99_ms"] >= 25  # the stalled cycle's lateness is kept
    assert summary["period_jitter_p99_ms"] >= 25  # and the long period it made
    gaps = [b - a for a, b in itertools.pairwise(starts)]
    assert min(gaps) >= 0.0099  # the schedule restarts after the stall instead of catching up
