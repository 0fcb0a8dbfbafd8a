"""A plugin's own mock mode (Bioscara's ``use_mock_hardware``): the block runs on its family's
emulator without --sim, and every output says it is simulated."""

from __future__ import annotations

import json

import pytest

from tests.conftest import REPO, block_of


def mock_copy(tmp_path, name: str, value: str = "true"):
    """A catalog profile (YAML or URDF) with use_mock_hardware set to ``value``."""
    if name.endswith(".urdf"):
        text = (REPO / "urdf" / name).read_text()
        text = text.replace('<param name="use_mock_hardware">false</param>',
                            f'<param name="use_mock_hardware">{value}</param>')
    else:
        text = (REPO / "profiles" / f"{name}.yaml").read_text()
        text = text.replace("use_mock_hardware: false", f"use_mock_hardware: {value}")
    path = tmp_path / ("mock-" + name if name.endswith(".urdf") else f"mock-{name}.yaml")
    path.write_text(text)
    return path


@pytest.mark.parametrize("source", ["bioscara-arm", "bioscara-arm.urdf"])
@pytest.mark.parametrize("value", ["true", "True"])
def test_mock_profile_runs_on_the_emulator_without_sim(cli, tmp_path, source, value):
    path = mock_copy(tmp_path, source, value)
    result = cli("-p", str(path), "--json", "connect", "-n", "3")
    assert result.exit_code == 0, result.output
    block = block_of(json.loads(result.stdout), "bioscara_arm")
    assert block["simulated"] is True
    assert block["target"].startswith("i2c+tcp://127.0.0.1:")  # the emulator, not /dev/i2c-1
    shown = value if source.endswith(".urdf") else "true"  # YAML reads True as a boolean
    assert result.stderr.splitlines()[0] == (
        f"bioscara_arm: simulated (use_mock_hardware: {shown}): no hardware is driven")


def test_connect_says_it_is_simulated_first(cli, tmp_path):
    result = cli("-p", str(mock_copy(tmp_path, "bioscara-arm")), "connect", "-n", "2")
    assert result.exit_code == 0, result.output
    assert "simulated" in result.stderr.splitlines()[0]
    assert "bioscara_arm: connected to its simulator at i2c+tcp://" in result.stdout
    assert "(use_mock_hardware: true)" in result.stdout


def test_mock_arm_keeps_the_safety_rules(cli, tmp_path):
    path = str(mock_copy(tmp_path, "bioscara-arm"))
    result = cli("-p", path, "--json", "jog", "j1", "0.1", "--yes")
    # the emulator starts unhomed: refused for safety exactly as the real arm
    assert result.exit_code == 5, result.output
    result = cli("-p", path, "--json", "identify")
    assert result.exit_code == 0, result.output
    assert block_of(json.loads(result.stdout))["simulated"] is True


def test_false_still_means_hardware(cli, tmp_path):
    result = cli("-p", str(mock_copy(tmp_path, "bioscara-arm", "false")), "connect")
    assert result.exit_code in (2, 4), result.output  # /dev/i2c-1 is not here
    assert "simulated" not in result.stderr


def test_mixed_robot_mock_arm_and_simulated_gripper(cli, tmp_path):
    """The arm mocked by its param; the gripper, which has no such param, needs --sim or
    hardware: with --hardware the arm runs alone, with --sim both are simulated."""
    path = str(mock_copy(tmp_path, "bioscara-dg-3f-m"))
    result = cli("-p", path, "--json", "--hardware", "bioscara_arm", "connect", "-n", "2")
    assert result.exit_code == 0, result.output
    assert block_of(json.loads(result.stdout))["simulated"] is True
    result = cli("-p", path, "--json", "--sim", "connect", "-n", "2")
    assert result.exit_code == 0, result.output
    assert all(b["simulated"] for b in json.loads(result.stdout)["blocks"])


def test_real_block_beside_a_mock_on_one_bus_is_refused(cli, tmp_path):
    text = mock_copy(tmp_path, "bioscara-arm").read_text()
    imu = """  - name: imu_block
    type: sensor
    plugin: mh5_hardware/MH5I2CInterface
    family: lsm6ds3
    bus: i2c
    sensors:
      - name: imu
        address: 0x6A
        state_interfaces: [angular_velocity.x, angular_velocity.y, angular_velocity.z,
                           linear_acceleration.x, linear_acceleration.y, linear_acceleration.z]
"""
    path = tmp_path / "shared-bus.yaml"
    path.write_text(text.rstrip("\n") + "\n" + imu)
    result = cli("-p", str(path), "connect")
    assert result.exit_code == 2, result.output
    assert "simulated whole or not at all" in result.stderr
    assert "Traceback" not in result.output
