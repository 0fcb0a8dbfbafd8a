"""`deltoctl --robot ROBOT record FILE.mcap` writes FILE on the caller's computer, end to end
on loopback: `deltoctl agent --sim` processes serving simulated robots, `deltoctl --robot …`
processes recording them."""

from __future__ import annotations

import json
import signal
import time

import pytest

pytest.importorskip("zenoh")

from deltoctl.fleet import lab
from tests.conftest import eventually
from tests.fleet.test_fleet import Bench, deltoctl

LOCAL_KEYS = {"output", "messages", "link_losses", "loop"}  # a local record's report


@pytest.fixture(scope="module")
def hand(tmp_path_factory):
    b = Bench(tmp_path_factory.mktemp("agent"), "hand-rec", "dg-5f-right")
    yield b
    b.close()


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    b = Bench(tmp_path_factory.mktemp("agent-arm"), "arm-rec", "bioscara-dg-3f-m")
    yield b
    b.close()


def _read(path):
    """Every message of the recording through rosbags: (topic, log time, message)."""
    from rosbags.highlevel import AnyReader

    with AnyReader([path]) as reader:
        return [(c.topic, t, reader.deserialize(raw, c.msgtype))
                for c, t, raw in reader.messages()]


def _info(path) -> dict:
    result = deltoctl("info", str(path), "--json")
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout)["result"]


def test_a_remote_record_writes_the_file_on_the_callers_computer(hand, tmp_path):
    out = tmp_path / "here.mcap"
    before = time.time_ns()
    result = hand.remote("record", "here.mcap", "--duration", "1", "--rate", "100", "--json",
                         cwd=tmp_path)
    after = time.time_ns()
    assert result.returncode == 0, result.stderr
    assert out.stat().st_size > 0
    assert not (hand.workdir / "here.mcap").exists()  # not on the robot's side
    document = json.loads(result.stdout)
    report = document["result"]
    assert set(report) >= LOCAL_KEYS and report["robot"] == "hand-rec"
    assert document["profile"] == "dg-5f-right"  # the robot's, as a local record names it
    assert report["loop"]["cycles"] == report["loop"]["robot_cycles"] > 10
    assert report["messages"]["/joint_states"] == report["loop"]["cycles"]
    # `deltoctl info` sees the robot's profile and blocks, as in a recording made there
    summary = _info(out)
    assert summary["profile"]["name"] == "dg-5f-right"
    blocks = {b["name"]: b for b in summary["blocks"]}
    assert set(blocks) == {"DG5FRightHardware"}
    assert blocks["DG5FRightHardware"]["family"] == "delto"
    assert blocks["DG5FRightHardware"]["identity"]["firmware"] == "3.0"
    # the same topics as a local record against the same simulator
    local = hand.local("record", str(tmp_path / "local.mcap"), "--duration", "0.3", "--json")
    assert local.returncode == 0, local.stderr
    assert set(json.loads(local.stdout)["result"]["messages"]) == set(report["messages"])
    assert json.loads(local.stdout)["profile"] == document["profile"]
    # rosbags reads it; each message at the robot's cycle time, increasing, in the window
    messages = _read(out)
    stamps = [t for topic, t, _ in messages if topic == "/joint_states"]
    assert len(stamps) == report["loop"]["cycles"]
    assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)
    assert before <= stamps[0] and stamps[-1] <= after
    for topic, t, msg in messages:
        if topic == "/joint_states":
            assert msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec == t
            assert len(msg.name) == 20


def test_a_remote_record_of_a_robot_of_two_blocks(arm, tmp_path):
    result = arm.remote("record", "arm.mcap", "--duration", "0.5", "--rate", "50", "--json",
                        cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    document = json.loads(result.stdout)
    report = document["result"]
    assert document["profile"] == "bioscara-dg-3f-m"
    summary = _info(tmp_path / "arm.mcap")
    assert summary["profile"]["name"] == "bioscara-dg-3f-m"
    local = arm.local("record", str(tmp_path / "local.mcap"), "--duration", "0.3", "--json")
    assert local.returncode == 0, local.stderr
    local_summary = _info(tmp_path / "local.mcap")
    names = [b["name"] for b in summary["blocks"]]
    assert len(names) == 2 and names == [b["name"] for b in local_summary["blocks"]]
    assert all(b["family"] for b in summary["blocks"])
    assert set(json.loads(local.stdout)["result"]["messages"]) == set(report["messages"])
    # every block's link status and the arm's joint flags (the driver's extra states) too
    messages = _read(tmp_path / "arm.mcap")
    gpio = next(m for topic, _, m in messages if topic == "/gpio")
    assert set(names) <= set(gpio.joint_names if hasattr(gpio, "joint_names")
                             else gpio.interface_groups)
    dyn = next(m for topic, _, m in messages if topic == "/dynamic_joint_states")
    local_dyn = next(m for topic, _, m in _read(tmp_path / "local.mcap")
                     if topic == "/dynamic_joint_states")
    assert [v.interface_names for v in dyn.interface_values] == \
        [v.interface_names for v in local_dyn.interface_values]
    assert list(dyn.joint_names) == list(local_dyn.joint_names)
    # --hardware: the blocks the robot streams are the ones the file holds
    one = arm.remote("--hardware", "dg3f_m_driver", "record", "one.mcap", "--duration", "0.3",
                     cwd=tmp_path)
    assert one.returncode == 0, one.stderr
    assert [b["name"] for b in _info(tmp_path / "one.mcap")["blocks"]] == ["dg3f_m_driver"]
    # {serial}: filled from the robot's block, and the file named as written
    named = arm.remote("--hardware", "dg3f_m_driver", "record", "arm-{serial}.mcap",
                       "--duration", "0.3", cwd=tmp_path)
    assert named.returncode == 0, named.stderr
    [written] = tmp_path.glob("arm-*.mcap")
    assert "{serial}" not in written.name and f"wrote {written.name}:" in named.stderr


def test_ctrl_c_on_the_caller_stops_the_stream_and_leaves_a_valid_file(hand, tmp_path):
    out = tmp_path / "stopped.mcap"
    caller = lab_popen(hand, tmp_path, "record", "stopped.mcap", "--rate", "200", "--json")
    try:
        assert eventually(lambda: out.exists() and out.stat().st_size > 0, timeout=30)
        assert hand.state() == "busy"
        time.sleep(0.3)
        caller.send_signal(signal.SIGINT)
        stdout, stderr = caller.communicate(timeout=30)
    finally:
        if caller.poll() is None:
            caller.kill()
    # on a loaded machine a cycle may not arrive: then the one warning says so (exit 3)
    assert caller.returncode in (0, 3), stderr
    assert caller.returncode == 0 or stderr.count("warning:") == stderr.count("did not arrive")
    report = json.loads(stdout)["result"]
    assert 0 < report["loop"]["cycles"] <= report["loop"]["robot_cycles"]
    assert _info(out)["messages"] == sum(report["messages"].values())
    assert sum(1 for topic, _, _ in _read(out) if topic == "/joint_states") == \
        report["loop"]["cycles"]
    assert eventually(lambda: hand.state() == "idle", timeout=10)  # the stream stopped there


def test_a_killed_caller_leaves_a_valid_file_and_the_stream_stops(hand, tmp_path):
    out = tmp_path / "killed.mcap"
    caller = lab_popen(hand, tmp_path, "record", "killed.mcap", "--rate", "100")
    try:
        assert eventually(lambda: out.exists() and out.stat().st_size > 0, timeout=30)
        time.sleep(0.3)
        caller.kill()  # no clean-up at all: the recorder process finishes the file
        caller.wait(10)
    finally:
        if caller.poll() is None:
            caller.kill()
    assert eventually(lambda: hand.state() == "idle", timeout=15)  # its token went
    assert eventually(lambda: deltoctl("info", str(out), "--json").returncode == 0,
                      timeout=10)
    assert _info(out)["profile"]["name"] == "dg-5f-right"
    assert any(topic == "/joint_states" for topic, _, _ in _read(out))


def test_a_robot_lost_mid_recording_leaves_a_valid_file_and_exit_4(tmp_path):
    b = Bench(tmp_path, "hand-lost", "dg-5f-right")
    try:
        out = tmp_path / "lost.mcap"
        caller = lab_popen(b, tmp_path, "record", "lost.mcap", "--rate", "100")
        try:
            assert eventually(lambda: out.exists() and out.stat().st_size > 0, timeout=30)
            time.sleep(0.3)
            b.agent.proc.kill()  # the robot's computer is gone
            stdout, stderr = caller.communicate(timeout=30)
        finally:
            if caller.poll() is None:
                caller.kill()
        assert caller.returncode == 4 and stdout == ""  # data only on stdout: none here
        assert "robot hand-lost" in stderr and "Traceback" not in stderr
        summary = _info(out)
        assert summary["profile"]["name"] == "dg-5f-right" and summary["messages"] > 0
        assert _read(out)
    finally:
        b.close()


def test_remote_record_options_are_checked_here(hand, tmp_path):
    for args, words in ((["--foxglove"], "--foxglove is not taken remotely"),
                        (["--rate", "-5"], "--rate"), (["--gpio-type", "x"], "--gpio-type"),
                        (["--bogus"], "--bogus")):
        result = hand.remote("record", "x.mcap", *args, cwd=tmp_path)
        assert result.returncode == 2, args
        assert words in result.stderr and "Traceback" not in result.stderr
    result = hand.remote("record", "no/such/dir/x.mcap", "--json", cwd=tmp_path)
    assert result.returncode == 2 and json.loads(result.stderr)["error"]["robot"] == "hand-rec"
    gone = deltoctl("--zenoh-config", str(hand.config), "--robot", "nobody", "record",
                    "x.mcap", "--duration", "0.2", cwd=tmp_path)
    assert gone.returncode == 4 and "robot nobody" in gone.stderr
    assert not list(tmp_path.glob("*.mcap"))  # nothing recorded, no empty file


def lab_popen(bench, cwd, *args):
    import os
    import subprocess

    env = {k: v for k, v in os.environ.items() if not k.startswith("DELTOCTL_")}
    return subprocess.Popen([*lab.deltoctl_command(), "--zenoh-config", str(bench.config),
                             "--robot", bench.robot, *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env, cwd=str(cwd),
                            stdin=subprocess.DEVNULL)
