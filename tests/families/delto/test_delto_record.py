"""record: MCAP in ROS 2 encoding that decodes, ends validly on SIGTERM, marks link losses."""

from __future__ import annotations

import collections
import json
import signal
import subprocess
import sys
import threading
import time

from mcap.reader import make_reader

from deltoctl.families.delto.emulator import DeltoServer, firmware_for_profile
from deltoctl.profile.catalog import load_profile
from tests.conftest import ros2_messages


def _topics(path):
    counts = collections.Counter()
    last = {}
    for topic, msg in ros2_messages(path):
        counts[topic] += 1
        last[topic] = msg
    return counts, last


def test_record_decodes_with_expected_counts(cli, tmp_path):
    out = tmp_path / "right.mcap"
    result = cli("--sim", "-p", "dg-5f-right", "record", str(out), "--duration", "0.5",
                 "--rate", "40", "--json")
    assert result.exit_code == 0, result.stderr
    report = json.loads(result.stdout)["result"]
    n = report["loop"]["cycles"]
    assert 15 <= n <= 21
    counts, last = _topics(out)
    assert counts["/joint_states"] == counts["/gpio"] == counts["/dynamic_joint_states"] == n
    for f in range(1, 6):
        assert counts[f"/right_fingertip_finger_{f}/wrench"] == n
    assert counts["/diagnostics"] >= 1
    js = last["/joint_states"]
    assert list(js.name) == [f"rj_dg_{f}_{j}" for f in range(1, 6) for j in range(1, 5)]
    dyn = last["/dynamic_joint_states"]
    assert list(dyn.interface_values[0].interface_names) == [
        "position", "velocity", "effort", "temperature"]
    assert 20 < dyn.interface_values[0].values[3] < 40  # °C
    gpio = last["/gpio"]
    block = load_profile("dg-5f-right").hardware[0].name
    assert list(gpio.interface_groups) == ["gpio", block, "system"]  # the block's link, all
    assert list(gpio.interface_values[1].values) == [1.0]
    assert list(gpio.interface_values[2].values) == [1.0]
    assert abs(last["/right_fingertip_finger_1/wrench"].wrench.force.z) < 10
    with out.open("rb") as f:
        reader = make_reader(f)
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        assert reader.get_summary().statistics.message_count == sum(counts.values())
    assert meta["profile"]["name"] == "dg-5f-right"
    assert "rj_dg_1_1" in meta["profile"]["yaml"]
    assert set(meta["identify"]) == {block}
    identity = json.loads(meta["identify"][block])
    assert identity["reported_model"] == "DG-5F-R (0x5f22)"
    assert identity["family"] == "delto" and identity["target"].startswith("tcp://")


def test_sigterm_leaves_a_valid_indexed_file(tmp_path):
    out = tmp_path / "term.mcap"
    proc = subprocess.Popen([sys.executable, "-m", "deltoctl", "--sim", "-p", "dg-4f", "record",
                             str(out), "--rate", "50"], stderr=subprocess.PIPE, text=True)
    time.sleep(1.5)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=10)
    assert proc.returncode == 0, err
    with out.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics.message_count > 0
    counts, _ = _topics(out)
    assert counts["/fingertip_finger_4/wrench"] == counts["/joint_states"] > 0


def test_link_loss_is_marked_and_the_recording_goes_on(cli, tmp_path):
    out = tmp_path / "lossy.mcap"
    with DeltoServer(firmware_for_profile(load_profile("dg-5f-right"))) as server:
        timer = threading.Timer(0.4, server.drop_connections)
        timer.start()
        result = cli("-p", "dg-5f-right", "-t", server.endpoint, "record", str(out),
                     "--duration", "3", "--rate", "50")
        timer.join()
    assert result.exit_code == 3, result.stderr
    assert "link was lost 1 time" in result.stderr
    messages = [m for _, m in ros2_messages(out, ["/diagnostics"])]
    events = [s.message for m in messages for s in m.status if s.name == "deltoctl/link"]
    assert events == ["link lost", "link restored"]
    statuses = [m.interface_values[-1].values[0] for _, m in ros2_messages(out, ["/gpio"])]
    assert statuses[0] == 1.0 and 0.0 in statuses and statuses[-1] == 1.0


def test_record_to_an_unwritable_path(cli):
    result = cli("--sim", "-p", "dg-4f", "record", "/nonexistent/dir/x.mcap", "-d", "0.1")
    assert result.exit_code == 2
    assert "cannot write" in result.stderr


def test_unreachable_device_leaves_no_file(cli, tmp_path):
    out = tmp_path / "never.mcap"
    result = cli("-p", "dg-4f", "-t", "tcp://127.0.0.1:9", "record", str(out), "-d", "0.1")
    assert result.exit_code == 4
    assert not out.exists()


def test_a_killed_recorder_still_leaves_a_valid_indexed_file(tmp_path):
    """The MCAP file is written by a child process that finishes it when the loop's process
    dies, even by SIGKILL."""
    from tests.conftest import eventually

    out = tmp_path / "killed.mcap"
    proc = subprocess.Popen([sys.executable, "-m", "deltoctl", "-p", "dg-5f-right", "--sim",
                             "record", str(out), "--duration", "60"], stderr=subprocess.PIPE)
    try:
        assert eventually(lambda: out.exists() and out.stat().st_size > 0, timeout=10)
        time.sleep(0.5)
    finally:
        proc.kill()
        proc.wait(timeout=5)

    def summary():
        try:
            with out.open("rb") as f:
                return make_reader(f).get_summary()
        except Exception:
            return None

    assert eventually(lambda: summary() is not None, timeout=5)
    stats = summary().statistics
    assert stats.message_count > 0 and stats.channel_count >= 4
