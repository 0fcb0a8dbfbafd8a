"""ros2_control descriptions written for the two public Dynamixel plugins load as profiles and
run on the emulated bus unchanged: dynamixel-community's ``dynamixel_hardware`` (a param ``id``
per joint) and ROBOTIS' ``dynamixel_hardware_interface`` (a ``<gpio>`` per servo)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

import deltoctl
from deltoctl.families.dynamixel.ros2_control import servo_ids
from deltoctl.profile.catalog import load_profile
from tests.conftest import block_of, eventually

LINKS = """
  <link name="base"/><link name="l1"/><link name="l2"/>
  <joint name="joint1" type="revolute"><parent link="base"/><child link="l1"/>
    <limit lower="-3.14" upper="3.14" velocity="4.8" effort="2"/></joint>
  <joint name="joint2" type="revolute"><parent link="l1"/><child link="l2"/>
    <limit lower="-1.5" upper="1.5" velocity="4.8" effort="2"/></joint>
"""
JOINT = """
    <joint name="{name}">{extra}
      <command_interface name="position"/>
      <state_interface name="position"/><state_interface name="velocity"/>
      <state_interface name="effort"/>
    </joint>"""
COMMUNITY = """<?xml version="1.0"?>
<robot name="pan_tilt">{links}
  <ros2_control name="pan_tilt" type="system">
    <hardware>
      <plugin>dynamixel_hardware/DynamixelHardware</plugin>
      <param name="usb_port">/dev/ttyUSB0</param>
      <param name="baud_rate">57600</param>{dummy}
    </hardware>{joints}
  </ros2_control>
</robot>
"""
ROBOTIS = """<?xml version="1.0"?>
<robot name="two_axis">{links}
  <ros2_control name="two_axis" type="system">
    <hardware>
      <plugin>dynamixel_hardware_interface/DynamixelHardware</plugin>
      <param name="port_name">/dev/ttyUSB0</param>
      <param name="baud_rate">1000000</param>
      <param name="dynamixel_model_folder">/param/dxl_model</param>
      <param name="number_of_joints">2</param>
      <param name="number_of_transmissions">2</param>
      <param name="transmission_to_joint_matrix">{matrix}</param>
    </hardware>{joints}{gpios}
  </ros2_control>
</robot>
"""
GPIO = """
    <gpio name="dxl{k}">
      <param name="type">dxl</param>
      <param name="ID">{id}</param>
      <command_interface name="Goal Position"/>
      <state_interface name="Present Position"/><state_interface name="Present Current"/>
      <param name="Operating Mode">3</param>
      <param name="Position P Gain">800</param>
    </gpio>"""


def community(tmp_path, dummy: bool = False):
    joints = "".join(JOINT.format(name=n, extra=f'\n      <param name="id">{i}</param>')
                     for n, i in (("joint1", 1), ("joint2", 2)))
    path = tmp_path / "pan_tilt.urdf"
    path.write_text(COMMUNITY.format(links=LINKS, joints=joints, dummy=(
        '\n      <param name="use_dummy">true</param>' if dummy else "")))
    return path


def robotis(tmp_path, matrix: str = "0, 1, -1, 0", ids: tuple[str, ...] = ("21", "22")):
    joints = "".join(JOINT.format(name=n, extra="") for n in ("joint1", "joint2"))
    gpios = "".join(GPIO.format(k=k, id=i) for k, i in enumerate(ids, 1))
    path = tmp_path / "two_axis.urdf"
    path.write_text(ROBOTIS.format(links=LINKS, joints=joints, gpios=gpios, matrix=matrix))
    return path


def test_dynamixel_hardware_ids_and_port_become_the_bus(tmp_path, cli):
    path = community(tmp_path)
    profile = load_profile(path)
    hw = profile.hardware[0]
    assert profile.family_of(hw) == "dynamixel"
    assert profile.buses[hw.bus] == "serial:///dev/ttyUSB0?baud=57600"
    run = cli("--sim", "-p", str(path), "identify", "--json")
    assert run.exit_code == 0, run.stderr
    doc = json.loads(run.stdout)
    servos = block_of(doc.get("result", doc))["identity"]["servos"]
    assert {j: s["id"] for j, s in servos.items()} == {"joint1": 1, "joint2": 2}
    jog = cli("--sim", "-p", str(path), "jog", "joint2", "5deg", "--yes")
    assert jog.exit_code == 0, jog.stderr


def test_dynamixel_hardware_use_dummy_runs_on_the_emulator(tmp_path, cli):
    run = cli("-p", str(community(tmp_path, dummy=True)), "identify")
    assert run.exit_code == 0, run.stderr
    assert "simulated" in run.stderr


def test_dynamixel_hardware_interface_servo_gpios_drive_the_joints(tmp_path, cli):
    path = robotis(tmp_path)
    profile = load_profile(path)
    hw = profile.hardware[0]
    assert [g.name for g in hw.gpios] == ["dxl1", "dxl2"]  # kept, as ros2_control has them
    joints = servo_ids(profile, hw)
    # transmission_to_joint_matrix 0 1 / -1 0: joint1 is servo 22, joint2 is servo 21 reversed
    assert (joints[22].name, joints[22].inverse) == ("joint1", False)
    assert (joints[21].name, joints[21].inverse) == ("joint2", True)
    assert joints[22].params["Position P Gain"] == "800"
    assert [j.address for j in hw.joints] == [None, None]  # the profile's own, untouched
    assert profile.buses[hw.bus] == "serial:///dev/ttyUSB0?baud=1000000"
    run = cli("--sim", "-p", str(path), "identify", "--json")
    assert run.exit_code == 0, run.stderr
    jog = cli("--sim", "-p", str(path), "jog", "joint1", "5deg", "--yes", "--json")
    assert jog.exit_code == 0, jog.stderr


@pytest.mark.parametrize(("matrix", "ids", "says"), [
    ("1, 1, 0, 1", ("21", "22"), "takes 2 servos' motion"),
    ("0.5, 0, 0, 1", ("21", "22"), "its factor 1 or -1"),
    ("1, 0, 0", ("21", "22"), "2 × 2 finite numbers"),
    ("1, 0, 0, nan", ("21", "22"), "2 × 2 finite numbers"),
    ("1, 0, 0, 1", ("21", "x"), "no ID param"),
    ("1, 0, 0, 1", ("21", "21"), "ID 21 is given to 2 servo gpios"),
    ("1, 0, 0, 1", ("21", "253"), "ID 253 is not a Dynamixel ID"),
    ("1, 0, 1, 0", ("21", "22"), "both take servo 'dxl1'"),
])
def test_a_description_deltoctl_cannot_drive_is_one_clear_error(tmp_path, cli, matrix, ids,
                                                                says):
    run = cli("-p", str(robotis(tmp_path, matrix, ids)), "profile", "validate")
    assert run.exit_code == 2, run.stderr
    assert says in run.stderr and "Traceback" not in run.stderr


# -- a ROBOTIS-style arm description: its servo gpios kept as ros2_control parses them ----------

ARM = Path(__file__).parent / "assets" / "robotis_arm.urdf"
SERVO_STATES = ["Present Position", "Present Velocity", "Present Current"]


def _gpios(hw) -> list[tuple]:
    return [(g.name, [i.name for i in g.command_interfaces],
             [i.name for i in g.state_interfaces], g.params) for g in hw.gpios]


def test_profile_show_lists_the_servo_gpios_as_ros2_control_parses_them(cli):
    run = cli("-p", str(ARM), "profile", "show", "--json")
    assert run.exit_code == 0, run.stderr
    doc = json.loads(run.stdout)["result"]
    servos = [f"dxl{k}" for k in range(1, 6)]
    assert doc["gpios"] == 5 and doc["joints"] == 5
    assert [n for n in doc["state_interfaces"] if n.startswith("dxl")] == [
        f"{g}/{s}" for g in servos for s in SERVO_STATES]
    assert [n for n in doc["command_interfaces"] if n.startswith("dxl")] == [
        f"{g}/Goal Position" for g in servos]
    [block] = doc["profile"]["ros2_control"]
    gpio = block["gpios"][0]
    assert (gpio["name"], gpio["command_interfaces"], gpio["state_interfaces"]) == (
        "dxl1", ["Goal Position"], SERVO_STATES)
    assert gpio["params"] == {"type": "dxl", "ID": "11", "Operating Mode": "3",
                              "Position P Gain": "800", "Position I Gain": "100",
                              "Position D Gain": "100", "Profile Velocity": "20",
                              "Profile Acceleration": "10", "Drive Mode": "4",
                              "Return Delay Time": "0"}
    assert all("address" not in j for j in block["joints"])  # the servos are the gpios'


@pytest.mark.parametrize("fmt", ["urdf", "yaml"])
def test_export_and_import_keep_the_servo_gpios(cli, tmp_path, fmt):
    original = load_profile(ARM)
    out = tmp_path / f"arm.{fmt}"
    run = cli("-p", str(ARM), "profile", "export", "--format", fmt, "-o", str(out))
    assert run.exit_code == 0, run.stderr
    again = load_profile(out)
    assert _gpios(again.hardware[0]) == _gpios(original.hardware[0])
    assert [j.address for j in again.hardware[0].joints] == [None] * 5
    assert {i: j.name for i, j in servo_ids(again, again.hardware[0]).items()} == {
        11: "joint1", 12: "joint2", 13: "joint3", 14: "joint4", 15: "gripper_joint"}
    if fmt == "urdf":  # and once more: the export of the export is the same text
        twice = tmp_path / "twice.urdf"
        assert cli("-p", str(out), "profile", "export", "-o", str(twice)).exit_code == 0
        assert twice.read_text() == out.read_text()


def test_the_emulated_arm_detects_jogs_and_streams_its_servo_gpios(cli):
    detect = cli("--sim", "-p", str(ARM), "detect", "--json")
    assert detect.exit_code == 0, detect.stderr
    checks = block_of(json.loads(detect.stdout))["checks"]
    assert [c["what"] for c in checks] == [f"joint{i} (ID {10 + i})" for i in range(1, 5)] + [
        "gripper_joint (ID 15)"]
    assert all(c["match"] and not c["missing"] for c in checks)
    jog = cli("--sim", "-p", str(ARM), "jog", "joint2", "5deg", "--yes", "--json")
    assert jog.exit_code == 0, jog.stderr
    with deltoctl.open_robot(ARM, sim=True) as robot:
        robot.jog({"joint2": 0.1})

        def moved() -> bool:
            values = robot.read()
            return values["joint2/position"] == pytest.approx(0.1, abs=0.01)

        assert eventually(moved)
        values = robot.read()
        # the servo gpio's states are the servo's readings, in SI units
        assert values["dxl2/Present Position"] == pytest.approx(values["joint2/position"])
        assert values["dxl1/Present Velocity"] == pytest.approx(0.0)
        # none: the emulator's servo, an XL430 (the description names no model), has no
        # current sensor
        current = values.get("dxl1/Present Current")
        assert current is None or math.isnan(current)
