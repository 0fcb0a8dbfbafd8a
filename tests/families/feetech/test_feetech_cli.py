"""Every verb of a Feetech bus from the CLI, on the SO-101 follower's emulated servos."""

from __future__ import annotations

import json

import pytest

from tests.conftest import block_of

SO101 = ("-p", "so101-follower", "--sim")


def _json(result):
    assert result.exit_code in (0, 3), (result.exit_code, result.output, result.stderr)
    return json.loads(result.stdout)


def test_every_verb_runs_on_the_so101_follower(cli, tmp_path):
    assert cli(*SO101, "connect").exit_code == 0
    servos = block_of(_json(cli(*SO101, "--json", "identify")))["identity"]["servos"]
    assert [s["id"] for s in servos.values()] == [1, 2, 3, 4, 5, 6]
    assert {(s["model"], s["firmware"]) for s in servos.values()} == {("STS3215", "3.10")}
    report = _json(cli(*SO101, "--json", "detect"))
    assert "6 servos answer (0 missing" in json.dumps(report)
    assert cli(*SO101, "--yes", "jog", "shoulder_pan", "10deg").exit_code == 0
    assert cli(*SO101, "--yes", "home").exit_code == 0
    assert cli(*SO101, "--yes", "torque", "off", "all").exit_code == 0
    got = cli(*SO101, "register", "get", "gripper", "present_position", "homing_offset")
    assert got.exit_code == 0 and "Present_Position" in got.stdout and "2048" in got.stdout
    got = cli(*SO101, "--yes", "register", "set", "gripper", "max_torque_limit", "500")
    assert got.exit_code == 0 and "500" in got.stdout
    snap = tmp_path / "snap.yaml"
    assert cli(*SO101, "config", "snapshot", "-o", str(snap)).exit_code == 0
    assert cli(*SO101, "config", "diff", str(snap)).exit_code == 0
    text = snap.read_text().replace("value: 20\n", "value: 21\n", 1)  # a DTs or a default
    snap.write_text(text)
    assert cli(*SO101, "--yes", "config", "restore", str(snap)).exit_code in (0, 3)
    lines = cli(*SO101, "--json", "stream", "--duration", "0.2").stdout.splitlines()
    assert "gripper/voltage" in json.loads(lines[-1])["values"]
    assert cli(*SO101, "record", str(tmp_path / "so.mcap"), "--duration", "0.2").exit_code == 0
    assert (tmp_path / "so.mcap").stat().st_size > 0


def test_identify_warns_of_mixed_firmware(cli):
    result = cli(*SO101, "--sim-option", "old_firmware=gripper", "identify")
    assert result.exit_code == 3
    assert "different firmware" in result.stderr and "gripper 3.9" in result.stderr


@pytest.mark.parametrize(("fault", "said"), [
    ("duplicate=wrist_roll", "replies collide at ID 5"),
    ("wrong_baud=gripper", "gripper (500000)"),
    ("missing=gripper", "1 missing"),
])
def test_detect_names_the_bus_faults(cli, fault, said):
    result = cli(*SO101, "--sim-option", fault, "--json", "detect")
    assert said in result.stdout


def test_a_latched_overload_is_a_named_fault_that_says_to_cycle_the_power(cli):
    result = cli(*SO101, "--sim-option", "overload=gripper", "--yes", "jog", "gripper", "5deg")
    assert result.exit_code == 1
    assert "overload protection latched" in result.stderr
    assert "power is cycled" in result.stderr


def test_a_voltage_error_is_named_with_what_to_do(cli):
    result = cli(*SO101, "--sim-option", "voltage=elbow_flex", "register", "get", "elbow_flex",
                 "present_voltage")
    assert "160" in result.stdout
    assert "input voltage error" in result.stderr and "variant" in result.stderr


def test_restore_writes_a_safety_item_only_when_allowed(cli, tmp_path):
    snap = tmp_path / "snap.yaml"
    assert cli(*SO101, "config", "snapshot", "-o", str(snap)).exit_code == 0
    text = snap.read_text()
    at = text.index("value: 0", text.index("Homing_Offset"))
    snap.write_text(text[:at] + "value: 100" + text[at + len("value: 0"):])
    refused = cli(*SO101, "--yes", "config", "restore", str(snap))
    assert refused.exit_code == 5 and "--allow homing-offset" in refused.stderr
    done = cli(*SO101, "--yes", "config", "restore", str(snap), "--allow", "homing_offset")
    assert done.exit_code == 0 and "verified" in done.stdout
    beyond = text[:at] + "value: 2114" + text[at + len("value: 0"):]  # LeRobot's bad offset
    snap.write_text(beyond)
    bad = cli(*SO101, "--yes", "config", "restore", str(snap), "--allow", "homing_offset")
    assert bad.exit_code == 2 and "Homing_Offset" in bad.stderr


MIXED = """
name: mixed
buses:
  b: serial:///dev/ttyUSB0?baud=1000000
safety:
  max_jog_step: 20deg
ros2_control:
  - name: mixed
    type: system
    plugin: feetech_sts_hardware/FeetechSTSHardware
    family: feetech
    bus: b
    joints:
      - name: sts
        limits: {lower: -3, upper: 3, velocity: 5, effort: 3}
        command_interfaces: [position]
        state_interfaces: [position, velocity, effort]
        params: {id: 1, model: STS3215}
      - name: scs
        limits: {lower: -2, upper: 2, velocity: 5, effort: 1}
        command_interfaces: [position]
        state_interfaces: [position, velocity, effort]
        params: {id: 2, model: SCS0009}
"""


def test_a_bus_of_little_and_big_endian_servos(cli, tmp_path):
    path = tmp_path / "mixed.yaml"
    path.write_text(MIXED)
    mixed = ("-p", str(path), "--sim")
    servos = block_of(_json(cli(*mixed, "--json", "identify")))["identity"]["servos"]
    assert {n: (s["model"], s["byte_order"]) for n, s in servos.items()} == {
        "sts": ("STS3215", "little-endian"), "scs": ("SCS0009", "big-endian")}
    lines = cli(*mixed, "--json", "stream", "--duration", "0.1").stdout.splitlines()
    values = json.loads(lines[-1])["values"]
    assert values["sts/position"] == 0.0 and values["scs/position"] == 0.0  # mid-turn each
    assert cli(*mixed, "--yes", "jog", "scs", "10deg").exit_code == 0
    got = cli(*mixed, "register", "get", "scs", "lock", "present_position")
    assert "48" in got.stdout and "512" in got.stdout  # SCS: Lock at 48, 1024 steps a turn
