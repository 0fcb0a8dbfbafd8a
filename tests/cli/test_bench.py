"""The shipped benchmarks run and report their figures (their numbers are not asserted)."""

from __future__ import annotations

import json

import pytest


def test_bench_loop_reports_stages(cli):
    result = cli("bench", "loop", "--rate", "200", "--duration", "0.3", "--unpaced", "0.2",
                 "--json")
    assert result.exit_code == 0, result.stderr
    report = json.loads(result.stdout)["result"]
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
    report = json.loads(result.stdout)["result"]
    assert report["deltoctl_hz"] > 0 and report["deltoctl_errors"] == 0
    assert "ratio" in report  # dynamixel-sdk is a test dependency


def test_bench_i2c_sets_the_tool_against_the_wire(cli):
    result = cli("bench", "i2c", "--cycles", "20", "--json")
    assert result.exit_code == 0, result.stderr
    report = json.loads(result.stdout)["result"]
    assert report["transactions_per_cycle"] == 8 and report["wire_bits_per_transaction"] == 72
    assert report["wire_us"] == 180.0  # 72 bits at 400 kHz
    assert report["deltoctl_us"] > 0 and report["smbus2_loop_us"] > 0
    assert "goal_overhead_le_25pct" in report


def test_bench_loop_reports_its_own_cost_per_hand(cli):
    """The loop thread's CPU per cycle and per hand, its wake-ups, and (strace there) its
    system calls per cycle: each hand's GET_DATA and SET_DUTY are one send each."""
    import shutil

    result = cli("bench", "loop", "--hands", "2", "--rate", "200", "--duration", "0.5",
                 "--unpaced", "0", "--json")
    assert result.exit_code == 0, result.stderr
    doc = json.loads(result.stdout)["result"]
    paced = doc.get("result", doc)["hands"]["2"]["paced"]
    assert paced["loop_thread_cpu_us_per_cycle"] > 0
    assert paced["loop_cpu_us_per_hand_cycle"] == \
        pytest.approx(paced["loop_thread_cpu_us_per_cycle"] / 2, abs=0.1)
    assert paced["loop_wakeups_per_cycle"] >= 0.5  # at 200 Hz the loop sleeps between cycles
    # the recorder process's CPU: starting and finishing the file, and its cycles'
    assert paced["recorder_process_setup_cpu_ms"] > 0
    assert 0 < paced["recorder_process_cycles_cpu_us_per_cycle"] < \
        paced["recorder_process_cpu_us_per_cycle"]
    assert "its cycles'" in cli("bench", "loop", "--hands", "1", "--rate", "200", "--duration",
                                "0.3", "--unpaced", "0").stdout
    calls = doc.get("result", doc)["hands"]["2"]["syscalls"]
    if shutil.which("strace") is None:
        assert calls is None
        return
    assert calls["cycles"] > 0 and calls["per_cycle"] >= 4
    sends = sum(n for name, n in calls["by_call"].items() if name.startswith("send"))
    assert sends == pytest.approx(4, abs=0.05)  # 2 hands × 2 sends
    # a send, or a reply already there, is one call: a poll() only waits for a reply not
    # there yet, at most once a hand
    assert calls["by_call"].get("poll", 0) <= 2


def test_bench_scan_sets_the_scan_beside_the_sdks(cli, monkeypatch):
    """One rate for each SDK way (the servos sit at it): each case's deltoctl scan and SDK
    ways find its servo; the factory-new arm's bus is found colliding."""
    from deltoctl.benchmarks import scan
    from deltoctl.render.bench import scan_lines

    for rates in ("FIND_DYNAMIXEL", "FEETECH_TABLE", "LEROBOT_SCAN"):
        monkeypatch.setattr(scan, rates, (1_000_000,))
    cases = ["xl430-1m", "ax12a-1m-id1", "sts3215-1m", "so101-factory-new"]
    result = cli("bench", "scan", "--runs", "1", "--sdk-runs", "1", "--case", ",".join(cases),
                 "--json")
    assert result.exit_code == 0, result.stderr
    report = json.loads(result.stdout)["result"]
    assert list(report["cases"]) == cases and report["goal_bus_s"] == 1.0
    sdks = {"xl430-1m": {"dynamixel_sdk broadcastPing"},
            "ax12a-1m-id1": {"dynamixel_sdk ping sweep"},
            "sts3215-1m": {"scservo_sdk ping sweep", "scservo_sdk broadcast ping (LeRobot's)"},
            "so101-factory-new": {"scservo_sdk broadcast ping (LeRobot's)"}}
    for name, row in report["cases"].items():
        ours = row["deltoctl"]
        assert ours["found_it"], (name, ours)
        assert ours["bus_s"] > 0 and ours["wall_s"] >= ours["bus_s"]
        assert len(ours["bus_runs_s"]) == len(ours["wall_runs_s"]) == 1
        assert set(row["sdks"]) == sdks[name]
        assert all(len(sdk["runs_s"]) == 1 and sdk["rates_tried"] == 1
                   for sdk in row["sdks"].values())
    assert all(sdk["found_it"] for name in cases[:3]
               for sdk in report["cases"][name]["sdks"].values())
    arm = report["cases"]["so101-factory-new"]["deltoctl"]
    assert arm["exit_code"] == 3 and {f["id"] for f in arm["found"]} <= {1, None}
    lines = scan_lines(report)
    assert len(lines) == 1 + len(cases) + sum(map(len, sdks.values()))
    assert cli("bench", "scan", "--case", "xl430-2m").exit_code == 2
