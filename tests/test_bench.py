"""The shipped benchmarks run and report their figures (their numbers are not asserted)."""

from __future__ import annotations

import json


def test_bench_loop_reports_stages(cli):
    result = cli("bench", "loop", "--rate", "200", "--duration", "0.3", "--unpaced", "0.2",
                 "--json")
    assert result.exit_code == 0, result.stderr
    report = json.loads(result.stdout)
    assert set(report["hands"]) == {"1"}  # one hand by default
    one = report["hands"]["1"]
    assert set(one["paced"]["stage_us_per_cycle"]) == {"codec", "socket", "write",
                                                       "recording"}
    assert one["paced"]["cycles"] > 0 and one["unpaced"]["cycles"] > 0
    assert 0 < report["idle_loop"]["achieved_fraction"] <= 1.01  # the machine's own floor
    assert set(report["goals"]) == {"1_hands_rate_ge_99_5_percent",
                                    "1_hands_p99_lateness_le_0_5_ms", "unpaced_1_hand_ge_5_khz"}


def test_bench_dynamixel_compares_with_the_sdk(cli):
    result = cli("bench", "dynamixel", "--duration", "0.3", "--json")
    assert result.exit_code == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["deltoctl_hz"] > 0 and report["deltoctl_errors"] == 0
    assert "ratio" in report  # dynamixel-sdk is a test dependency


def test_bench_i2c_sets_the_tool_against_the_wire(cli):
    result = cli("bench", "i2c", "--cycles", "20", "--json")
    assert result.exit_code == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["transactions_per_cycle"] == 8 and report["wire_bits_per_transaction"] == 72
    assert report["wire_us"] == 180.0  # 72 bits at 400 kHz
    assert report["deltoctl_us"] > 0 and report["smbus2_loop_us"] > 0
    assert "goal_overhead_le_25pct" in report
