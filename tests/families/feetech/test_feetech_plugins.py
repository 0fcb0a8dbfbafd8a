"""ros2_control descriptions written for the public Feetech plugins (reference §4) load as
profiles unchanged, each with its own params, and run on the emulated bus."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from deltoctl.profile.catalog import load_profile
from tests.conftest import block_of

LINKS = """
  <link name="base"/><link name="l1"/><link name="l2"/>
  <joint name="{a}" type="revolute"><parent link="base"/><child link="l1"/>
    <limit lower="-1.9" upper="1.9" velocity="10" effort="10"/></joint>
  <joint name="{b}" type="revolute"><parent link="l1"/><child link="l2"/>
    <limit lower="-1.7" upper="1.7" velocity="10" effort="10"/></joint>
"""
JOINT = """
    <joint name="{name}">{params}
      <command_interface name="position"/>
      <state_interface name="position"/><state_interface name="velocity"/>
    </joint>"""
ROBOT = """<?xml version="1.0"?>
<robot name="arm">{links}
  <ros2_control name="arm" type="system">
    <hardware>
      <plugin>{plugin}</plugin>{hardware}
    </hardware>{joints}
  </ros2_control>
</robot>
"""


def _param(name: str, value: object) -> str:
    return f'\n      <param name="{name}">{value}</param>'


# plugin, its hardware params, the joints with their own params (name → params)
DESCRIPTIONS = {
    "feetech_ros2_driver": (
        "feetech_ros2_driver/FeetechHardwareInterface", {"usb_port": "/dev/ttyACM0"},
        {"shoulder_pan_joint": {"id": 1, "offset": 2048, "p_cofficient": 8},
         "shoulder_lift_joint": {"id": 2, "offset": 2125, "p_cofficient": 16}}),
    "so_arm101_ros2_control": (
        "so_arm101_ros2_control/SoArm101HardwareInterface",
        {"serial_port": "/dev/ttyACM0", "serial_baudrate": 1000000, "enable_torque": "true",
         "calibration_file": "follower.json"},
        {"shoulder_pan": {}, "shoulder_lift": {}}),
    "sts_hardware_interface": (
        "sts_hardware_interface/STSHardwareInterface",
        {"serial_port": "/dev/ttySERVO", "baud_rate": 500000, "use_sync_write": "true"},
        {"joint_a": {"motor_id": 11, "operating_mode": 0, "min_position": 0,
                     "max_position": 4095},
         "joint_b": {"motor_id": 12, "operating_mode": 0}}),
    "feetech_sts_hardware": (
        "feetech_sts_hardware/FeetechSTSHardware",
        {"port_name": "/dev/ttyUSB0", "baud_rate": 1000000, "default_zero_offset": 1800},
        {"0_coxa_joint": {"id": 21, "zero_offset": 2048}, "0_femur_joint": {"id": 22}}),
}
CALIBRATION = {"shoulder_pan": {"id": 7, "drive_mode": 0, "homing_offset": 0,
                                "range_min": 1048, "range_max": 3048},
               "shoulder_lift": {"id": 8, "drive_mode": 0, "homing_offset": 0,
                                 "range_min": 0, "range_max": 4095}}


def _write(tmp_path: Path, key: str) -> Path:
    plugin, hardware, joints = DESCRIPTIONS[key]
    a, b = joints
    text = ROBOT.format(
        links=LINKS.format(a=a, b=b), plugin=plugin,
        hardware="".join(_param(k, v) for k, v in hardware.items()),
        joints="".join(JOINT.format(name=n, params="".join(
            _param(k, v) for k, v in p.items()).replace("\n      ", "\n        "))
            for n, p in joints.items()))
    (tmp_path / "follower.json").write_text(json.dumps(CALIBRATION))
    path = tmp_path / f"{key}.urdf"
    path.write_text(text)
    return path


@pytest.mark.parametrize(("key", "ids", "url"), [
    ("feetech_ros2_driver", [1, 2], "serial:///dev/ttyACM0?baud=1000000"),
    ("so_arm101_ros2_control", [7, 8], "serial:///dev/ttyACM0?baud=1000000"),
    ("sts_hardware_interface", [11, 12], "serial:///dev/ttySERVO?baud=500000"),
    ("feetech_sts_hardware", [21, 22], "serial:///dev/ttyUSB0?baud=1000000"),
])
def test_each_plugins_description_loads_with_its_own_params(tmp_path, key, ids, url):
    profile = load_profile(str(_write(tmp_path, key)))
    [hw] = profile.hardware
    assert profile.family_of(hw) == "feetech"
    assert [j.address for j in hw.joints] == ids
    assert profile.buses[hw.bus] == url


@pytest.mark.parametrize("key", list(DESCRIPTIONS))
def test_each_plugins_description_runs_on_the_emulator(cli, tmp_path, key):
    path = str(_write(tmp_path, key))
    result = cli("-p", path, "--sim", "--json", "identify")
    assert result.exit_code == 0, result.output
    servos = block_of(json.loads(result.stdout))["identity"]["servos"]
    assert {s["model"] for s in servos.values()} == {"STS3215"}
    lines = cli("-p", path, "--sim", "--json", "stream", "--duration", "0.1").stdout
    values = json.loads(lines.splitlines()[-1])["values"]
    _, _, joints = DESCRIPTIONS[key]
    first, second = joints
    # each plugin's zero: its offset param, the calibration's middle, or mid-turn
    expected = {"feetech_ros2_driver": (0.0, (2048 - 2125) * 2 * math.pi / 4096),
                "so_arm101_ros2_control": (math.radians((2048 - 2048) * 360 / 4095),
                                           math.radians((2048 - 2047.5) * 360 / 4095)),
                "sts_hardware_interface": (0.0, 0.0),
                "feetech_sts_hardware": (0.0, (2048 - 1800) * 2 * math.pi / 4096)}[key]
    assert values[f"{first}/position"] == pytest.approx(expected[0])
    assert values[f"{second}/position"] == pytest.approx(expected[1])
    assert cli("-p", path, "--sim", "--yes", "jog", first, "5deg").exit_code == 0
