"""``deltoctl calibrate joints`` from the command line: a ``--sim`` rehearsal whose range a hand
moves (``--hand``), its --json valid against its schema, and a ``deltoctl sim serve`` in its own
process whose servos are moved by ``hand`` and ``sweep`` lines on its standard input while the
command samples their range."""

from __future__ import annotations

import json
import queue
import subprocess
import sys
import threading
import time

import pytest

from deltoctl.app.joint_calibration import PERMISSIONS, calibration_file
from deltoctl.schemas_lookup import schema_file

ARM = ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper")
ALLOW = [a for p in PERMISSIONS for a in ("--allow", p)]


@pytest.fixture(autouse=True)
def _data_dirs(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    monkeypatch.setenv("HF_LEROBOT_CALIBRATION", str(tmp_path / "lerobot"))


def _valid(document: dict) -> None:
    jsonschema = pytest.importorskip("jsonschema")
    jsonschema.validate(document, json.loads(schema_file("calibrate joints").read_text()))


@pytest.mark.parametrize("profile", ["koch-arm", "so101-follower"])
def test_a_sim_rehearsal_moved_by_hand(cli, profile, tmp_path):
    hands = [a for j in ARM for angle in (-40, 40) for a in ("--hand", f"hand {j} {angle}")]
    result = cli("-p", profile, "--sim", "--yes", "--json", "calibrate", "joints",
                 "--range-seconds", "4", "--format", "lerobot", "--id", "rehearsal",
                 *ALLOW, *hands)
    assert result.exit_code == 3, result.output  # the range is short of the profile's limits
    document = json.loads(result.stdout)
    _valid(document)
    joints = document["result"]["joints"]
    assert [j["joint"] for j in joints] == list(ARM)
    for joint in joints:  # the middle pose reads 2047; the hand turned it 40° either way
        assert joint["written"] == "verified"
        assert abs(joint["range_min"] - (2047 - 455)) <= 2
        assert abs(joint["range_max"] - (2047 + 455)) <= 2
    assert document["result"]["file"] == str(calibration_file(profile, simulated=True,
                                                              name="rehearsal"))
    assert document["result"]["lerobot_file"].endswith("/rehearsal.json")
    assert any("the range moved" in w for w in document["warnings"])
    # a script is told when the middle pose is read and the range is to be moved
    assert "the middle pose is read: move each joint by hand through its range, within 4 s" \
        in result.stderr


def test_a_script_without_range_seconds_or_yes_is_told_what_to_pass(cli):
    result = cli("-p", "koch-arm", "--sim", "--yes", "calibrate", "joints")
    assert result.exit_code == 2
    assert "pass --range-seconds" in result.stderr
    result = cli("-p", "koch-arm", "--sim", "calibrate", "joints", "--range-seconds", "1")
    assert result.exit_code == 5
    assert "the torque off" in result.stderr and "--yes" in result.stderr
    result = cli("-p", "koch-arm", "--sim", "--yes", "calibrate", "joints", "--range-seconds",
                 "1", "--format", "csv")
    assert result.exit_code == 2 and "--format is deltoctl or lerobot" in result.stderr
    result = cli("-p", "koch-arm", "--sim", "--yes", "calibrate", "joints", "--range-seconds",
                 "1", "--hand", "hand gripper far")
    assert result.exit_code == 2 and "DEGREES must be degrees" in result.stderr
    result = cli("-p", "dg-4f", "--sim", "--yes", "calibrate", "joints", "--range-seconds", "1")
    assert result.exit_code == 2 and "no servo joints" in result.stderr


def test_options_and_blocks_that_cannot_be_calibrated_are_refused_before_anything(cli):
    for options, says in (
            (("--format", "lerobot", "--id", "../arm"), "--id '../arm' must be a plain name"),
            (("--id", "a/b"), "--id 'a/b' must be a plain name"),
            (("--allow", "homing-offset"), "also needs --allow min-position-limit"),
            (("--range-seconds", "0"), "--range-seconds must be above 0")):
        # no --yes: a check after the open would stop at the confirmation (exit 5)
        result = cli("-p", "koch-arm", "--sim", "calibrate", "joints", "--range-seconds", "1",
                     *options)
        assert result.exit_code in (2, 5) and says in result.stderr, result.output
        assert "the torque off" not in result.stderr
    assert not calibration_file("koch-arm", simulated=True).exists()
    result = cli("-p", "phantomx-arm", "--sim", "--yes", "calibrate", "joints",
                 "--range-seconds", "1", *ALLOW)
    assert result.exit_code == 2, result.output
    assert "cannot calibrate phantomx_arm: its servos have no homing offset register" \
        in result.stderr


def _reader(proc) -> queue.Queue:
    """The process's output lines, as they come."""
    lines: queue.Queue = queue.Queue()
    threading.Thread(target=lambda: [lines.put(line) for line in proc.stdout],
                     daemon=True).start()
    return lines


def _replies(lines: queue.Queue, count: int, timeout: float) -> list[dict]:
    """Up to ``count`` control replies within ``timeout`` seconds."""
    found = []
    deadline = time.monotonic() + timeout
    while len(found) < count and (left := deadline - time.monotonic()) > 0:
        try:
            found.append(json.loads(lines.get(timeout=left)))
        except queue.Empty:
            break
    return found


def _send(proc, line: str) -> None:
    proc.stdin.write(line + "\n")
    proc.stdin.flush()


def test_a_sim_serve_process_moved_by_lines_on_its_input(cli):
    """The command runs against `sim serve` by -t, as against a robot; the test moves the arm
    once the command has switched its torque off (a hand line is refused before)."""
    serve = subprocess.Popen([sys.executable, "-m", "deltoctl", "sim", "serve", "koch-arm",
                              "--json", "--private"], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    calibrate = None
    try:
        [url] = json.loads(serve.stdout.readline())["buses"].values()
        replies = _reader(serve)
        target = ("-p", "koch-arm", "-t", f"dxl={url}", "--yes")
        assert cli(*target, "torque", "on").exit_code == 0
        # a read after the torque's write (which has no reply) comes back once it took effect
        on = cli(*target, "--json", "register", "get", "gripper", "torque_enable")
        assert json.loads(on.stdout)["result"]["values"] == {"Torque Enable": 1}
        calibrate = subprocess.Popen([sys.executable, "-m", "deltoctl", *target, "--json",
                                      "calibrate", "joints", "--range-seconds", "6", *ALLOW],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:  # refused while the torque is on
            _send(serve, "hand gripper 0")
            if _replies(replies, 1, 0.2):
                break
        for joint in ARM:
            _send(serve, f"sweep {joint} -30 30 3")
        assert len(_replies(replies, len(ARM), 10)) == len(ARM)
        out, err = calibrate.communicate(timeout=60)
    finally:
        for proc in (calibrate, serve):
            if proc is not None and proc.poll() is None:
                proc.terminate()
                proc.wait(timeout=10)
    assert calibrate.returncode == 3, err  # the range is short of the profile's limits
    joints = json.loads(out)["result"]["joints"]
    assert all(j["written"] == "verified" and j["range_max"] > j["range_min"] for j in joints)
    saved = json.loads(calibration_file("koch-arm").read_text())["blocks"]["koch_arm"]
    assert saved["wrist_flex"]["homing_offset"] == joints[3]["homing_offset"]
