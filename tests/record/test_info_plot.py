"""`deltoctl info` and `deltoctl plot` on recordings made through the CLI against the
emulators: what they report, a link loss and a gap with their times, the values plot reads
(checked against mcap-ros2-support's decoding), and one clear error for a bad file."""

from __future__ import annotations

import json
import math

import pytest
from mcap.writer import Writer

from deltoctl.cli import main
from deltoctl.profile.catalog import load_profile
from deltoctl.record.cdr import CdrTemplate
from deltoctl.record.mcap_recorder import McapFile, McapRecorder
from deltoctl.record.reader import read_recording, series
from deltoctl.record.ros2_msgs import MSGDEFS
from tests.conftest import record_with_a_dropped_link, ros2_messages
from tests.record.test_recordings_rosbag2 import FAMILIES, family_recordings  # noqa: F401


@pytest.fixture(scope="module")
def right_hand(tmp_path_factory):
    from typer.testing import CliRunner

    out = tmp_path_factory.mktemp("right") / "right.mcap"
    result = CliRunner().invoke(main.app, ["-p", "dg-5f-right", "--sim", "-q", "record",
                                           str(out), "--rate", "100", "--duration", "1"])
    assert result.exit_code == 0, result.stderr
    return out


def _info(cli, path) -> dict:
    result = cli("info", str(path), "--json")
    assert result.exit_code == 0, result.stderr
    return json.loads(result.stdout)["result"]


# -- info ----------------------------------------------------------------------------------------

def test_info_reports_times_topics_blocks_and_the_loop(cli, right_hand):
    report = _info(cli, right_hand)
    counts = {}
    for topic, _ in ros2_messages(right_hand):
        counts[topic] = counts.get(topic, 0) + 1
    assert {t["topic"]: t["messages"] for t in report["topics"]} == counts
    assert report["messages"] == sum(counts.values())
    assert report["indexed"] and 0.9 < report["duration_s"] < 1.2
    assert (report["end_ns"] - report["start_ns"]) / 1e9 == pytest.approx(report["duration_s"])
    rates = {t["topic"]: t["rate_hz"] for t in report["topics"]}
    assert 85 < rates["/joint_states"] < 115
    assert report["profile"]["name"] == "dg-5f-right" and report["profile"]["model"] == "DG-5F-R"
    (block,) = report["blocks"]
    assert block["name"] == load_profile("dg-5f-right").hardware[0].name
    assert block["family"] == "delto" and block["target"].startswith("tcp://")
    assert block["identity"]["reported_model"] == "DG-5F-R (0x5f22)"
    loop = report["loop"]
    assert loop["requested_rate"] == 100 and loop["cycles"] == counts["/joint_states"]
    for key in ("lateness_p50_ms", "lateness_p99_ms", "period_jitter_p50_ms",
                "period_jitter_p99_ms"):
        assert loop[key] >= 0
    assert report["link_losses"] == [] and report["gaps"] == []
    assert report["rosbag2"] == {"version": 8, "storage_identifier": "mcap"}
    assert report["compression"] == ["lz4"]


def test_info_for_people(cli, right_hand):
    result = cli("info", str(right_hand))
    assert result.exit_code == 0, result.stderr
    out = result.stdout
    assert "profile dg-5f-right" in out and "/joint_states" in out
    assert "link losses: none" in out and "gaps: none" in out
    assert "lateness p50" in out and "period jitter" in out
    assert "reported_model=DG-5F-R (0x5f22)" in out


def test_info_of_every_family(cli, family_recordings):  # noqa: F811
    for name in FAMILIES:
        report = _info(cli, family_recordings[name])
        assert report["profile"]["name"] == name
        assert {t["topic"] for t in report["topics"]} >= {"/joint_states", "/gpio",
                                                           "/diagnostics"}
        assert report["blocks"] and report["loop"]["cycles"] > 0
    mh5 = _info(cli, family_recordings["mh5"])
    assert "/imu/data_raw" in {t["topic"] for t in mh5["topics"]}
    bimanual = _info(cli, family_recordings["dg-5f-bimanual"])
    assert len(bimanual["blocks"]) == 2


def test_info_shows_a_link_lost_mid_recording_and_when(cli, tmp_path):
    """The Delto emulator drops its connections while recording: info names the loss, the
    block that went down, when, and when the link came back."""
    out = tmp_path / "lossy.mcap"
    result = record_with_a_dropped_link(cli, out)
    assert result.exit_code == 3, result.stderr
    report = _info(cli, out)
    (loss,) = report["link_losses"]
    assert report["start_ns"] < loss["lost_ns"] < loss["restored_ns"] <= report["end_ns"]
    assert loss["seconds"] == pytest.approx((loss["restored_ns"] - loss["lost_ns"]) / 1e9)
    assert loss["blocks"] == [load_profile("dg-5f-right").hardware[0].name]
    down = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
            for _, m in ros2_messages(out, ["/gpio"]) if m.interface_values[-1].values[0] == 0]
    assert down and down[0] == loss["lost_ns"]  # the first cycle /gpio shows the link down
    text = cli("info", str(out)).stdout
    assert "link losses" in text and "not restored" not in text


def _recording_with_a_stall(path) -> tuple[int, int]:
    profile = load_profile("dg-4f")
    out = McapFile(str(path))
    recorder = McapRecorder(out, profile, {})
    t = 1_700_000_000_000_000_000
    stall = None
    for i in range(300):
        if i == 200:
            stall = (t, t + 250_000_000)
            t += 250_000_000  # the loop stalled for a quarter of a second
        recorder.write({"j_dg_1_1/position": math.sin(i / 10), "system/connection_status": 1.0},
                       t)
        t += 10_000_000
    recorder.close({"cycles": 300}, t)
    out.close()
    return stall


def test_info_shows_each_bus_loop(cli, tmp_path):
    """The MH5's sync loops report to /diagnostics once a second; info shows their last."""
    path = tmp_path / "buses.mcap"
    out = McapFile(str(path))
    recorder = McapRecorder(out, load_profile("mh5"), {})
    recorder.write({"head_y/position": 0.0}, 1_000_000_000)
    recorder.diagnostics(1_000_000_000, [
        (0, "loop", "record loop", {"cycles": 1}),
        (0, "upper_body_pvl_reader", "bus loop", {"packets": 100, "errors": 2,
                                                  "real_rate": 99.5})])
    recorder.close({"cycles": 1}, 1_000_000_001)
    out.close()
    report = _info(cli, path)
    assert report["buses"] == {"upper_body_pvl_reader": {"packets": 100, "errors": 2,
                                                         "real_rate": 99.5}}
    assert "bus loop upper_body_pvl_reader: packets 100" in cli("info", str(path)).stdout


def test_info_shows_a_gap_in_the_cycles(cli, tmp_path):
    path = tmp_path / "stall.mcap"
    start, end = _recording_with_a_stall(path)
    (gap,) = _info(cli, path)["gaps"]
    assert gap == {"start_ns": start - 10_000_000, "end_ns": end, "seconds": 0.26}
    assert "gaps (no cycle)" in cli("info", str(path)).stdout


def test_info_reads_a_file_whose_recorder_was_killed(cli, tmp_path):
    """No summary (the whole process group got SIGKILL): read record by record, said so."""
    path = tmp_path / "killed.mcap"
    out = McapFile(str(path))
    recorder = McapRecorder(out, load_profile("dg-4f"), {})
    for i in range(50):
        recorder.write({"j_dg_1_1/position": i / 10, "system/connection_status": 1.0},
                       1_000_000_000 + i * 10_000_000)
    recorder.flush()
    out.close()  # no close(): the provisional end stays
    result = cli("info", str(path), "--json")
    assert result.exit_code == 0, result.stderr
    report = json.loads(result.stdout)["result"]
    assert not report["indexed"] and report["messages"] == 50 * len(recorder.topics)
    assert "has no index" in result.stderr
    plotted = json.loads(cli("plot", str(path), "j_dg_1_1/position", "--json").stdout)["result"]
    assert plotted["interfaces"][0]["count"] == 50


@pytest.mark.parametrize("content, says", [
    (None, "no such file"),
    (b"", "is empty"),
    (b"name: dg-5f-right\nfamily: delto\n", "is not an MCAP file"),
    ("cut", "is truncated"),
])
def test_a_bad_file_is_one_clear_error(cli, tmp_path, right_hand, content, says):
    path = tmp_path / "bad.mcap"
    if content == "cut":
        path.write_bytes(right_hand.read_bytes()[:5000])
    elif content is not None:
        path.write_bytes(content)
    for verb in ("info", "plot"):
        result = cli(verb, str(path))
        assert result.exit_code == 2, result.output
        assert says in result.stderr and "Traceback" not in result.stderr
        assert result.stderr.count("error:") == 1 and result.stdout == ""
    error = json.loads(cli("info", str(path), "--json").stderr)["error"]
    assert says in error["message"] and error["exit_code"] == 2


# -- plot ----------------------------------------------------------------------------------------

def test_plot_values_are_those_recorded(right_hand):
    rec = read_recording(right_hand, keep=None)
    wanted = ["rj_dg_2_3/position", "rj_dg_2_3/temperature", "right_fingertip_finger_4/torque.y",
              "system/connection_status"]
    got = series(rec, wanted)
    decoded = {name: [] for name in wanted}
    for topic, msg in ros2_messages(right_hand):
        if topic == "/joint_states":
            decoded["rj_dg_2_3/position"].append(msg.position[msg.name.index("rj_dg_2_3")])
        elif topic == "/dynamic_joint_states":
            values = msg.interface_values[msg.joint_names.index("rj_dg_2_3")]
            decoded["rj_dg_2_3/temperature"].append(
                values.values[values.interface_names.index("temperature")])
        elif topic == "/right_fingertip_finger_4/wrench":
            decoded["right_fingertip_finger_4/torque.y"].append(msg.wrench.torque.y)
        elif topic == "/gpio":
            decoded["system/connection_status"].append(msg.interface_values[-1].values[0])
    for name in wanted:
        times, values = got[name]
        assert values.tolist() == decoded[name], name
        assert (times[1:] > times[:-1]).all()


def test_plot_reads_messages_whose_layout_changes(tmp_path):
    """A channel whose messages change shape inside one chunk (another file's): each message
    of another length is decoded on its own."""
    path = tmp_path / "shapes.mcap"
    with path.open("wb") as f:
        writer = Writer(f)
        writer.start(profile="ros2", library="test")
        schema = writer.register_schema("sensor_msgs/msg/JointState", "ros2msg",
                                        MSGDEFS["sensor_msgs/msg/JointState"].encode())
        channel = writer.register_channel("/joint_states", "cdr", schema)
        for i, names in enumerate([["a"], ["a"], ["long_name", "a"], ["a"]]):
            template = CdrTemplate().header().const_strings(names)
            template.var_doubles([f"{n}/position" for n in names]).var_doubles([])
            template.var_doubles([]).done()
            row = {f"{n}/position": float(i * 10 + k) for k, n in enumerate(names)}
            row.update({"@sec": 1, "@nanosec": i})
            data = template.layout.pack(*[row.get(x, x) if isinstance(x, str) else x
                                          for x in template.fields])
            writer.add_message(channel, log_time=1_000_000_000 + i, data=data,
                               publish_time=1_000_000_000 + i)
        writer.finish()
    got = series(read_recording(path, keep=None), ["a/position"])
    assert got["a/position"][1].tolist() == [0.0, 10.0, 21.0, 30.0]


def test_plot_in_the_terminal(cli, right_hand):
    result = cli("plot", str(right_hand), "rj_dg_1_*/temperature", "system/*")
    assert result.exit_code == 0, result.stderr
    for name in ("rj_dg_1_1/temperature", "rj_dg_1_4/temperature", "system/connection_status"):
        assert name in result.stdout
    assert "\x1b[" not in result.stdout  # no colour codes when not on a terminal


def test_plot_to_png_and_json(cli, right_hand, tmp_path):
    png = tmp_path / "plot.png"
    result = cli("plot", str(right_hand), "right_fingertip_finger_1/force.*", "--out", str(png),
                 "--json")
    assert result.exit_code == 0, result.stderr
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    report = json.loads(result.stdout)["result"]
    assert report["out"] == str(png)
    assert [i["interface"] for i in report["interfaces"]] == [
        f"right_fingertip_finger_1/force.{a}" for a in "xyz"]
    cycles = _info(cli, right_hand)["loop"]["cycles"]
    for entry in report["interfaces"]:
        assert entry["topic"] == "/right_fingertip_finger_1/wrench"
        assert entry["count"] == cycles and entry["missing"] == 0


def test_plot_a_time_window(cli, right_hand):
    whole = json.loads(cli("plot", str(right_hand), "rj_dg_1_1/position", "--json").stdout)["result"]
    part = json.loads(cli("plot", str(right_hand), "rj_dg_1_1/position", "--start", "0.25",
                          "--end", "0.5", "--json").stdout)["result"]
    (w,), (p,) = whole["interfaces"], part["interfaces"]
    assert 20 <= p["count"] <= 30 < w["count"]
    assert p["first_ns"] >= w["first_ns"] + 250_000_000


def test_plot_names_the_interfaces_when_none_match(cli, right_hand):
    result = cli("plot", str(right_hand), "rj_dg_1_1/postion")
    assert result.exit_code == 2
    assert "no interface" in result.stderr and "rj_dg_1_1/position" in result.stderr


def test_plot_without_its_extra_says_how_to_install_it(cli, right_hand, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "plotext", None)  # not installed
    result = cli("plot", str(right_hand))
    assert result.exit_code == 1
    assert "pip install 'deltoctl[plot]'" in result.stderr
    assert "Traceback" not in result.stderr


def test_info_costs_no_numpy(right_hand):
    """info runs on a plain install (numpy comes with the plot extra)."""
    import subprocess
    import sys

    code = ("import sys; sys.modules['numpy'] = None; from deltoctl.record.reader import "
            f"describe; from pathlib import Path; print(describe(Path({str(right_hand)!r}))"
            "['messages'])")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 0, done.stderr
    assert int(done.stdout) > 0


def test_diagnostics_are_chunks_of_their_own(right_hand):
    """What lets info skip the cycles' chunks: each /diagnostics message is alone in one."""
    rec = read_recording(right_hand)
    diagnostics = rec.channel("/diagnostics").id
    holding = [c for c in rec.chunks if diagnostics in c.message_index_offsets]
    assert holding and all(list(c.message_index_offsets) == [diagnostics] for c in holding)


@pytest.mark.parametrize("period_ns", [1_000_000, 100_000_000])  # 1 kHz, 10 Hz
def test_a_steady_loop_has_no_gap_whatever_its_rate(period_ns):
    """The usual period is learnt from the first cycles (one quick pair among them does not
    fool it); a late cycle is no gap, a tenfold one (20 ms at least) is."""
    import io

    recorder = McapRecorder(io.BytesIO(), load_profile("dg-4f"), {})
    t = 1_000_000_000
    for i in range(300):
        recorder.write({"j_dg_1_1/position": 0.0}, t)
        t += 1000 if i == 1 else period_ns + (period_ns // 2 if i % 7 == 0 else 0)
    assert recorder.gaps == 0
    recorder.write({"j_dg_1_1/position": 0.0}, t + max(12 * period_ns, 30_000_000))
    assert recorder.gaps == 1
