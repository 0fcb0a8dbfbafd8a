"""``bench feetech``: its figures are there and hang together (no speed is asserted, only
what no machine can change: a paced read never beats the wire)."""

from __future__ import annotations

import importlib.util
import json

from deltoctl.benchmarks.feetech import wire_limit


def test_bench_feetech_reports_both_clients_against_the_wire(cli):
    result = cli("--json", "bench", "feetech", "--duration", "0.2")
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)["result"]
    assert report["wire_limit_hz"] == round(wire_limit(6, 1_000_000), 1)
    # 1 Mbps, 10 bits a byte: a 14-byte request and six 12-byte statuses
    assert report["wire_limit_hz"] == round(1e6 / (10 * (14 + 6 * 12)), 1)
    ours = report["deltoctl"]
    assert 0 < ours["paced_fraction_of_wire"] <= 1.0 and ours["cpu_us_per_read"] > 0
    # the pseudo-terminal's round trip taken out of each read: never less of the wire's limit
    assert report["pty_round_trip_us"] > 0
    less = ours["paced_fraction_less_pty"]
    assert less is None or less >= ours["paced_fraction_of_wire"]
    if importlib.util.find_spec("scservo_sdk") is not None:
        theirs = report["scservo_sdk"]
        assert 0 < theirs["paced_fraction_of_wire"] <= 1.0
        assert report["cpu_ratio"] == round(theirs["cpu_us_per_read"] / ours["cpu_us_per_read"],
                                            2)
    assert cli("bench", "feetech", "--servos", "0").exit_code == 2


def test_bench_feetech_shows_the_reads_less_the_pseudo_terminal_s_round_trip(cli):
    result = cli("bench", "feetech", "--duration", "0.2")
    assert result.exit_code == 0, result.output
    assert "the pseudo-terminal's own round trip" in result.stdout
