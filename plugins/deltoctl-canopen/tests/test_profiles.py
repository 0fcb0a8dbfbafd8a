"""bus.yml in both layouts, a ros2_control URDF in ros2_canopen's conventions, and EDS files
as untrusted input."""

import json

import pytest
from deltoctl.errors import ProfileError

from deltoctl_canopen import eds
from deltoctl_canopen.busconfig import load_bus
from deltoctl_canopen.nodes import GENERIC_EDS, PROFILES

FLAT = """
options:
  dcf_path: "@BUS_CONFIG_PATH@"
master:
  node_id: 1
  sync_period: 10000
joint_1:
  node_id: 2
  dcf: "generic-cia402.eds"
  scale_pos_to_dev: 1000.0
  scale_pos_from_dev: 0.001
  sdo:
    - {index: 0x6081, sub_index: 0, value: 4000}
joint_2:
  node_id: 3
  dcf: "generic-cia402.eds"
"""

URDF = """<?xml version="1.0"?>
<robot name="arm">
  <link name="base"/><link name="l1"/><link name="l2"/>
  <joint name="joint1" type="revolute"><parent link="base"/><child link="l1"/>
    <limit lower="-1" upper="1" velocity="1" effort="1"/></joint>
  <joint name="joint2" type="revolute"><parent link="l1"/><child link="l2"/>
    <limit lower="-1" upper="1" velocity="1" effort="1"/></joint>
  <ros2_control name="arm" type="system">
    <hardware>
      <plugin>canopen_ros2_control/Cia402System</plugin>
      <param name="bus_config">bus.yml</param>
      <param name="can_interface_name">vcan0</param>
    </hardware>
    <joint name="joint1"><param name="device_name">joint_1</param>
      <command_interface name="position"/><state_interface name="position"/></joint>
    <joint name="joint2"><param name="node_id">3</param>
      <command_interface name="position"/><state_interface name="position"/></joint>
  </ros2_control>
</robot>
"""


def test_both_layouts():
    nested = load_bus(PROFILES / "cia402-two-axis.bus.yml")
    assert {n: c.node_id for n, c in nested.nodes.items()} == {"axis_1": 2, "axis_2": 3}
    assert nested.nodes["axis_2"].scales["scale_pos_to_dev"] == 10000.0  # from defaults:
    assert [w.index for w in nested.nodes["axis_2"].sdo][:2] == [0x6081, 0x6083]
    assert nested.nodes["axis_1"].tpdo[0].mapping == [(0x6041, 0), (0x6064, 0)]


def test_flat_layout_from_a_urdf(tmp_path, cli):
    (tmp_path / "bus.yml").write_text(FLAT)
    (tmp_path / "generic-cia402.eds").write_bytes(GENERIC_EDS.read_bytes())
    bus = load_bus(tmp_path / "bus.yml")
    assert bus.nodes["joint_1"].to_dev(0.5) == 500 and bus.nodes["joint_2"].node_id == 3
    urdf = tmp_path / "arm.urdf"
    urdf.write_text(URDF)
    shown = cli("profile", "show", "--json", urdf)
    assert shown.exit_code == 0, shown.stderr
    text = json.dumps(json.loads(shown.stdout))
    assert "can://socketcan/vcan0" in text and "canopen" in text
    identified = cli("-p", urdf, "--sim", "--json", "identify")
    assert identified.exit_code == 0, identified.stderr
    nodes = json.loads(identified.stdout)["blocks"][0]["identity"]["nodes"]
    assert (nodes["joint1"]["node"], nodes["joint2"]["node"]) == (2, 3)
    moved = cli("-p", urdf, "--sim", "--json", "jog", "joint1", "0.2", "--yes")
    assert moved.exit_code == 0, moved.stderr
    imported = cli("profile", "import", urdf)
    assert imported.exit_code == 0 and "bus_config" in imported.stdout


@pytest.mark.parametrize("text, words, line", [
    ("joint_1:\n  node_id: 200\n", "node_id must be 1 to 127", 2),
    ("joint_1:\n  node_id: 2\n  colour: red\n", "unknown key colour", 3),
    ("nodes:\n  a: {node_id: 2}\n  b: {node_id: 2}\n", "node_id 2 is a's too", 3),
    ("joint_1:\n  node_id: 2\n  sdo:\n    - {index: 0x6081, value: nope}\n", "sdo item 1", 4),
    ("joint_1:\n  node_id: 2\n  homing_timeout_seconds: -1\n",
     "homing_timeout_seconds must be an integer 0 to 3600", 3),
])
def test_bad_bus_files(tmp_path, text, words, line):
    path = tmp_path / "bus.yml"
    path.write_text(text)
    with pytest.raises(ProfileError) as caught:
        load_bus(path)
    assert words in caught.value.message and f"bus.yml:{line}" in str(caught.value)


def test_the_joints_whose_bus_file_gives_a_homing_method_home_by_the_drive(tmp_path):
    from deltoctl.profile.catalog import load_profile

    from deltoctl_canopen.nodes import homing_joints

    (tmp_path / "generic-cia402.eds").write_bytes(GENERIC_EDS.read_bytes())
    (tmp_path / "bus.yml").write_text(FLAT.replace(  # joint_1: method 0, "no homing"
        "value: 4000}", "value: 4000}\n    - {index: 0x6098, sub_index: 0, value: 0}")
        + "  homing_timeout_seconds: 7\n  sdo:\n    - {index: 0x6098, sub_index: 0, value: 17}\n")
    assert load_bus(tmp_path / "bus.yml").nodes["joint_2"].homing_timeout == 7
    urdf = tmp_path / "arm.urdf"
    urdf.write_text(URDF)
    profile = load_profile(str(urdf))
    assert homing_joints(profile, profile.hardware[0]) == ["joint2"]


@pytest.mark.parametrize("edit, words, line", [
    (lambda t: t.replace("DataType=0x0006\nAccessType=rw\nDefaultValue=0\nPDOMapping=1",
                         "DataType=zero\nAccessType=rw\nDefaultValue=0\nPDOMapping=1", 1),
     "DataType='zero' is not a number", None),
    (lambda t: t + "\n[1234Name]\nNrOfEntries=100000\n", "NrOfEntries=100000: at most 254", None),
    (lambda t: t + "\n[" + "A" * 5000 + "]\n", "a line of 5002 characters", None),
    (lambda t: t.replace("[6041]\nParameterName=Statusword\n", "[6041]\n"),
     "No option 'ParameterName'", "6041"),
    (lambda t: t.replace("[6040]", "[2040]"), "no 0x6040 Controlword", None),
])
def test_bad_eds_files(tmp_path, edit, words, line):
    path = tmp_path / "drive.eds"
    text = GENERIC_EDS.read_text()
    path.write_text(edit(text))
    with pytest.raises(ProfileError) as caught:
        eds.load(path, 2)
    assert words in caught.value.message, caught.value.message
    if line:
        number = next(i for i, s in enumerate(path.read_text().splitlines(), 1)
                      if s == f"[{line}]")
        assert f"drive.eds:{number}" in str(caught.value)


def test_a_huge_eds_is_refused_before_it_is_read(tmp_path):
    path = tmp_path / "big.eds"
    path.write_bytes(b";" * (eds.MAX_EDS_BYTES + 1))
    with pytest.raises(ProfileError, match="the limit for an EDS"):
        eds.load(path, 2)
