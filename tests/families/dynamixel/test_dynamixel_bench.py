"""``bench dynamixel``'s mixed bus: its figures are there and hang together (their speed is
not asserted, only what no machine can change: a paced read never beats its wire time)."""

from __future__ import annotations

import importlib.util

import pytest

from deltoctl.benchmarks.dynamixel import measure_mixed_bus


def test_the_mixed_bus_paced_less_its_pty_and_unpaced_against_the_sdk():
    report = measure_mixed_bus(0.1)
    wire = report["wire_ms"]["sync_read"]
    sync = report["reads"]["sync_read"]
    assert all(way["short_reads"] == 0 for way in report["reads"].values())
    assert sync["median_ms"] >= wire  # the emulator never delivers before the wire would
    pty = report["pty_round_trip_ms"]
    assert pty["median"] > 0 and pty["mean"] > 0
    assert report["sync_read_less_pty_over_wire"] == pytest.approx(
        (sync["mean_ms"] - pty["mean"]) / wire, abs=0.002)
    assert report["flat_out_wire_limit_hz"]["sync_read"] == pytest.approx(1e3 / wire, abs=0.1)
    unpaced = report["unpaced"]
    assert min(unpaced[f"deltoctl_{k}_hz"] for k in ("sync_read", "bulk_read",
                                                      "fast_sync_read")) > 0
    assert all(us > 0 for us in unpaced["cpu_us_per_read"].values())
    assert set(unpaced["emulator_cpu_us_per_read"]) == set(unpaced["cpu_us_per_read"])
    assert all(us is None or us >= 0 for us in unpaced["emulator_cpu_us_per_read"].values())
    if importlib.util.find_spec("dynamixel_sdk") is not None:
        assert unpaced["ratio_to_sdk"] == pytest.approx(
            unpaced["deltoctl_sync_read_hz"] / unpaced["dynamixel_sdk_bulk_read_hz"], abs=0.01)
        assert set(unpaced["ratios_to_sdk"]) == {"sync_read", "bulk_read", "fast_sync_read"}
        assert unpaced["dynamixel_sdk_sync_read_hz"] > 0


def test_the_protocol_1_bus_read_in_turn_never_beats_its_wire_time():
    from deltoctl.benchmarks.dynamixel import measure_protocol1

    report = measure_protocol1(0.1)
    assert report["wire_ms"] == pytest.approx(5 * (8 + 14) * 10 / 1e6 * 1e3)
    paced = report["paced"]
    assert 0 < paced["fraction_of_wire"] <= 1.0
    assert report["unpaced"]["deltoctl_hz"] > 0
    if importlib.util.find_spec("dynamixel_sdk") is not None:
        assert paced["ratio_to_sdk"] == pytest.approx(
            paced["deltoctl_hz"] / paced["dynamixel_sdk_hz"], abs=0.01)
