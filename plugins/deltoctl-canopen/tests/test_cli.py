"""Every verb on CANopen through the CLI, on emulated drives: in the command's process
(--sim) or in a `sim serve` process of its own (faults), over the local hub."""

import json
import os
import re
import signal
import subprocess
import time

import pytest
from conftest import DELTOCTL, PROFILE


def as_json(result):
    assert result.exit_code in (0, 3), result.output + result.stderr
    return json.loads(result.stdout)


def test_identify(cli):
    doc = as_json(cli("-p", PROFILE, "--sim", "--json", "identify"))
    nodes = doc["blocks"][0]["identity"]["nodes"]
    assert nodes["axis_1"]["node"] == 2 and nodes["axis_2"]["node"] == 3
    assert nodes["axis_1"]["vendor_id"] == 0xDE7 and nodes["axis_1"]["identity_match"]
    assert nodes["axis_1"]["device_name"] == "deltoctl generic CiA 402 drive"


def test_detect_missing_and_wrong_identity(cli, served):
    url = served("--missing", "axis_2", "--wrong-identity", "0x1234")
    result = cli("-p", PROFILE, "-t", url, "--json", "detect")
    assert result.exit_code == 1, result.output  # axis_2 does not answer
    checks = json.loads(result.stdout)["blocks"][0]["checks"]
    assert [c["device"] for c in checks] == ["wrong identity: product_code 0x1234", "missing"]


def test_detect_unexpected_node(cli, served):
    url = served()
    single = PROFILE.parent / "cia402-two-axis.yaml"
    result = cli("-p", single, "-t", url, "--hardware", "axes", "--json", "detect")
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["blocks"][0]["details"]["found"] == [2, 3]


def test_jog_and_home(cli):
    result = cli("-p", PROFILE, "--sim", "--json", "jog", "axis_1", "10deg", "--yes")
    assert result.exit_code == 0, result.output + result.stderr
    result = cli("-p", PROFILE, "--sim", "--json", "home", "--yes")
    assert result.exit_code == 0, result.output + result.stderr
    outcomes = {j: v["outcome"] for b in json.loads(result.stdout)["blocks"]
                for j, v in b["joints"].items()}
    assert outcomes == {"axis_1": "homed", "axis_2": "homed"}


def test_jog_beyond_the_envelope_is_refused(cli):
    result = cli("-p", PROFILE, "--sim", "jog", "axis_2", "100deg", "--yes")
    assert result.exit_code == 5


def test_a_stalled_axis_faults_and_the_jog_fails(cli, served):
    url = served("--stall", "axis_2")
    result = cli("-p", PROFILE, "-t", url, "jog", "axis_2", "20deg", "--yes")
    assert result.exit_code == 1
    assert "faulted during the move: error code 0x8611" in result.stderr


def test_a_drive_in_fault_is_reset_and_moves(cli, served):
    url = served("--drive-fault", "axis_1")
    result = cli("-p", PROFILE, "-t", url, "--json", "jog", "axis_1", "10deg", "--yes")
    assert result.exit_code == 0, result.output + result.stderr


def test_registers(cli):
    result = cli("-p", PROFILE, "--sim", "--json", "register", "get", "axis_1", "Statusword",
                 "0x1018:2", "6081")
    doc = as_json(result)
    text = json.dumps(doc)
    assert '"Identity object.Product code"' in text and "262657" in text
    result = cli("-p", PROFILE, "--sim", "--json", "register", "set", "axis_2",
                 "Profile velocity", "1234", "--yes")
    assert result.exit_code == 0, result.output + result.stderr
    assert "1234" in result.stdout
    bad = cli("-p", PROFILE, "--sim", "register", "get", "axis_1", "Statuswrd")
    assert bad.exit_code == 2 and "Statusword" in bad.stderr


def test_stream_reads_the_tpdos(cli):
    result = cli("-p", PROFILE, "--sim", "stream", "--rate", "100", "--duration", "0.3",
                 "--json")
    assert result.exit_code == 0, result.stderr
    rows = [json.loads(line) for line in result.stdout.splitlines() if '"values"' in line]
    last = rows[-1]["values"]
    assert last["axis_1/nmt_state"] == 5 and last["system/connection_status"] == 1
    assert int(last["axis_1/statusword"]) & 0x4F == 0x40  # switch on disabled


def test_record(cli, tmp_path):
    from mcap_ros2.reader import read_ros2_messages

    out = tmp_path / "axes.mcap"
    result = cli("-p", PROFILE, "--sim", "record", out, "--rate", "100", "--duration", "1.2")
    assert result.exit_code == 0, result.stderr
    topics = {m.channel.topic for m in read_ros2_messages(str(out))}
    assert {"/joint_states", "/diagnostics"} <= topics
    statuses = [s for m in read_ros2_messages(str(out), topics=["/diagnostics"])
                for s in m.ros_msg.status]
    values = {kv.key: kv.value for s in statuses if s.name.endswith("axes_sync") for kv in s.values}
    assert values["axis_1_nmt"] == "OPERATIONAL"


def test_a_heartbeat_that_stops_is_a_lost_link(cli, served, tmp_path):
    url = served("--heartbeat-stops", "axis_2", "--heartbeat-stops-after", "1")
    result = cli("-p", PROFILE, "-t", url, "record", tmp_path / "lost.mcap", "--rate", "50",
                 "--duration", "2.5")
    assert result.exit_code == 4, result.output + result.stderr


def test_config_snapshot_diff_restore(cli, tmp_path):
    snap = tmp_path / "axes.yaml"
    assert cli("-p", PROFILE, "--sim", "config", "snapshot", "-o", snap).exit_code == 0
    text = snap.read_text()
    assert "0x6081:00 Profile velocity: {value: 10000" in text  # the bus file's sdo: list
    changed = tmp_path / "changed.yaml"
    changed.write_text(text.replace("Following error window: {value: 1000",
                                    "Following error window: {value: 1500")
                       .replace("Home offset: {value: 0", "Home offset: {value: 5"))
    diff = cli("-p", PROFILE, "--sim", "config", "diff", changed)
    assert diff.exit_code == 3 and "Following error window" in diff.stdout
    refused = cli("-p", PROFILE, "--sim", "config", "restore", changed, "--yes")
    assert refused.exit_code == 5 and "--allow homing" in refused.stderr
    done = cli("-p", PROFILE, "--sim", "config", "restore", changed, "--yes", "--allow",
               "homing")
    assert done.exit_code == 0, done.output + done.stderr
    assert "4 verified" in done.stdout


def test_trace_names_canopen_frames(cli, tmp_path):
    log = tmp_path / "trace.ndjson"
    result = cli("-p", PROFILE, "--sim", "--log-file", log, "identify")
    assert result.exit_code == 0
    frames = [json.loads(line).get("frame", "") for line in log.read_text().splitlines()]
    assert "SDO request to node 2: read 0x1000:00" in frames
    assert any(re.fullmatch(r"SDO reply from node 3: read 0x1018:02 = 01020400", f)
               for f in frames)
    assert "NMT enter pre-operational node 2" in frames and "NMT start node 3" in frames


def test_a_bad_target_is_one_clear_error(cli):
    for url, words in (("can://nosuch/can0", "no interface 'nosuch'"),
                       ("can://socketcan/can0?bitrate=12", "not a CANopen bit rate"),
                       ("can://localhub/10.0.0.1:5000", "loopback"),
                       ("can://socketcan/can0?channel=x", "unknown option")):
        result = cli("-p", PROFILE, "-t", url, "identify")
        assert result.exit_code == 2 and words in result.stderr, result.stderr


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT, signal.SIGHUP])
def test_a_signal_leaves_the_axis_stopped(served, sig):
    """A long jog ended by a signal: the axis is in Quick Stop or Switch On Disabled,
    read back by canopen's own client on the bus."""
    import canopen

    from deltoctl_canopen.hub import HubBus
    from deltoctl_canopen.nodes import GENERIC_EDS

    url = served()
    jog = subprocess.Popen([*DELTOCTL, "-p", str(PROFILE), "-t", url, "jog", "axis_1", "25deg",
                            "--velocity", "1deg", "--yes"], stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True, start_new_session=True)
    network = canopen.Network(HubBus(channel=url.split("/")[3].split("?")[0]))
    network.connect()
    seen = []  # TPDO1 of node 2 (statusword, position), as deltoctl's SYNCs ask for it
    network.subscribe(0x182, lambda cid, data, t: seen.append(
        (int.from_bytes(data[:2], "little"), int.from_bytes(data[2:6], "little", signed=True))))
    try:
        deadline = time.monotonic() + 20
        while not (seen and seen[-1][0] & 0x6F == 0x27 and seen[-1][1] > 20):
            if time.monotonic() > deadline:
                raise AssertionError("the jog did not start: " + jog.stderr.read())
            time.sleep(0.02)
        os.kill(jog.pid, sig)
        jog.wait(10)
        node = network.add_node(2, str(GENERIC_EDS))  # deltoctl is gone: SDO is ours
        word = node.sdo[0x6041].raw
        assert word & 0x4F == 0x40 or word & 0x6F == 0x07, hex(word)
        moved = node.sdo[0x6064].raw
        time.sleep(0.1)
        assert node.sdo[0x6064].raw == moved  # it stays where it stopped
        assert moved < 4000  # well short of 25° (4363 increments)
    finally:
        network.disconnect()
        if jog.poll() is None:
            jog.kill()
