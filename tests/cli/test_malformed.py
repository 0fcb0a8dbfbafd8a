"""Malformed profiles: each exits 2 with ``file:line`` and what was expected, never a traceback."""

from __future__ import annotations

import textwrap

import pytest

GOOD_JOINT = """\
      - name: j1
        limits: {lower: -1, upper: 1}
        command_interfaces: [position]
        state_interfaces: [position]
"""


def _yaml(body: str, joints: str = GOOD_JOINT, extra_top: str = "") -> str:
    return (f"name: broken\nfamily: generic\n{extra_top}ros2_control:\n"
            f"  - name: hw\n    type: system\n    plugin: mock_components/GenericSystem\n"
            f"{body}    joints:\n{joints}")


YAML_CASES = [
    # id, text, expected message part, expected line
    ("bad-syntax", "name: [unclosed\n", "not valid YAML", 2),
    ("not-a-mapping", "- just\n- a list\n", "must be a mapping", 1),
    ("empty", "", "empty", 1),
    ("unknown-top-key", "name: x\nfamilly: delto\nros2_control: []\n", "unknown key 'familly'", 2),
    ("no-blocks", "name: x\nfamily: generic\n", "at least one block", 1),
    ("duplicate-key", "name: x\nname: y\n", "duplicate key 'name'", 2),
    ("missing-plugin", "name: x\nros2_control:\n  - name: hw\n    type: system\n"
     "    joints:\n" + GOOD_JOINT, "missing <plugin>", 3),
    ("bad-hw-type", _yaml("").replace("type: system", "type: robot"), "type must be one of", 4),
    ("unknown-family", _yaml("", extra_top="").replace("family: generic", "family: kuka"),
     "unknown driver family 'kuka'", None),
    ("joint-no-interface", _yaml("", "      - name: j1\n"), "has no command or state interface", 8),
    ("fixed-with-interfaces", _yaml("", GOOD_JOINT.replace("name: j1", "name: j1\n        type: fixed")),
     "is fixed", 8),
    ("mimic-with-command", _yaml("", GOOD_JOINT.replace("name: j1", "name: j1\n        mimic: {joint: j0}")),
     "cannot have command interfaces", 8),
    ("duplicate-joint", _yaml("", GOOD_JOINT + GOOD_JOINT), "duplicate name 'j1'", 12),
    ("min-greater-than-max", _yaml("", GOOD_JOINT.replace(
        "[position]\n        state", "[{name: position, min: 2, max: 1}]\n        state", 1)),
     "min 2.0 is greater than max 1.0", 10),
    ("lower-above-upper", _yaml("", GOOD_JOINT.replace("lower: -1, upper: 1", "lower: 2, upper: 1")),
     "lower limit 2 is greater than upper limit 1", 8),
    ("bad-number", _yaml("", GOOD_JOINT.replace("lower: -1", "lower: left")),
     "expected a number", 9),
    ("unknown-joint-key", _yaml("", GOOD_JOINT.replace("limits:", "limts:")), "unknown key 'limts'", 9),
    ("unknown-bus", _yaml("    bus: can0\n"), "unknown bus 'can0'", 4),
    ("bad-bus-url", _yaml("", extra_top="buses: {main: 'http://x'}\n"), "not a target URL", None),
    ("duplicate-address", _yaml("", GOOD_JOINT.replace("name: j1", "name: j1\n        address: 3")
                                + GOOD_JOINT.replace("name: j1", "name: j2\n        address: 3")
                                ).replace("family: generic", "family: dynamixel"),
     "same address 3", 13),
    ("address-out-of-range", _yaml("", GOOD_JOINT.replace("name: j1", "name: j1\n        address: 300")
                                   ).replace("family: generic", "family: dynamixel"),
     "must be within 0..252", 8),
    ("bad-data-type", _yaml("", GOOD_JOINT.replace("state_interfaces: [position]",
                                                   "state_interfaces: [{name: position, data_type: float128}]")),
     "unknown data_type 'float128'", 11),
    ("home-pose-unknown-joint", _yaml("", extra_top="safety: {home_pose: {j9: 0}}\n"),
     "unknown joint 'j9'", None),
    ("home-pose-outside-limits", _yaml("", extra_top="safety: {home_pose: {j1: 5}}\n"),
     "outside its limits", None),
    ("param-not-scalar", _yaml("    params: {a: [1, 2]}\n"), "must be a single value", 7),
]

URDF_HEAD = '<?xml version="1.0"?>\n<robot name="r">\n  <link name="base"/><link name="l1"/>\n'
URDF_JOINT = ('  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>'
              '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>\n')


def _urdf(block: str, joint: str = URDF_JOINT) -> str:
    return URDF_HEAD + joint + block + "</robot>\n"


HW = "    <hardware><plugin>mock_components/GenericSystem</plugin></hardware>\n"
J1 = ('    <joint name="j1"><command_interface name="position"/>'
      '<state_interface name="position"/></joint>\n')

URDF_CASES = [
    ("xml-syntax", URDF_HEAD + "  <joint name='j1'>\n</robot>\n", "not well-formed XML", 5),
    ("wrong-root", '<?xml version="1.0"?>\n<sdf>\n</sdf>\n', "root element must be <robot>", 2),
    ("no-block", _urdf(""), "no <ros2_control> block", None),
    ("invalid-tag", _urdf('  <ros2_control name="a" type="system">\n' + HW +
                          "    <actuator name='x'/>\n  </ros2_control>\n"), "invalid tag name <actuator>", 7),
    ("missing-plugin", _urdf('  <ros2_control name="a" type="system">\n    <hardware>\n'
                             '    </hardware>\n' + J1 + "  </ros2_control>\n"), "missing <plugin>", 6),
    ("missing-type", _urdf('  <ros2_control name="a">\n' + HW + J1 + "  </ros2_control>\n"),
     "needs a type attribute", 5),
    ("joint-not-in-urdf", _urdf('  <ros2_control name="a" type="system">\n' + HW +
                                J1.replace("j1", "j7") + "  </ros2_control>\n"),
     "joint 'j7' not found in the URDF", 7),
    ("fixed-joint", _urdf('  <ros2_control name="a" type="system">\n' + HW + J1 + "  </ros2_control>\n",
                          URDF_JOINT.replace("revolute", "fixed")), "is fixed in the URDF", 7),
    ("mimic-with-command", _urdf('  <ros2_control name="a" type="system">\n' + HW + J1 +
                                 "  </ros2_control>\n",
                                 URDF_JOINT.replace("</joint>", '<mimic joint="j0"/></joint>')),
     "cannot have command interfaces", 7),
    ("bad-limit-number", _urdf('  <ros2_control name="a" type="system">\n' + HW + J1 +
                               "  </ros2_control>\n", URDF_JOINT.replace('lower="-1"', 'lower="low"')),
     "must be a number", 4),
    ("min-greater-than-max", _urdf('  <ros2_control name="a" type="system">\n' + HW +
                                   '    <joint name="j1">\n      <command_interface name="position">'
                                   '<param name="min">3</param><param name="max">2</param>'
                                   '</command_interface>\n    </joint>\n  </ros2_control>\n'),
     "min 3.0 is greater than max 2.0", 8),
    ("unknown-family", _urdf('  <ros2_control name="a" type="system">\n' + HW.replace(
        "</plugin>", '</plugin><param name="deltoctl.family">kuka</param>') + J1 +
        "  </ros2_control>\n"), "unknown driver family 'kuka'", 5),
]


def _check(cli, tmp_path, name, suffix, text, expect, line):
    path = tmp_path / f"{name}{suffix}"
    path.write_text(textwrap.dedent(text))
    result = cli("profile", "validate", str(path))
    assert result.exit_code == 2, (result.stdout, result.stderr)
    assert "Traceback" not in result.stderr + result.stdout
    assert expect in result.stderr, result.stderr
    where = f"{path}:{line}:" if line else f"{path}:"
    assert where in result.stderr, result.stderr


@pytest.mark.parametrize("name,text,expect,line", YAML_CASES, ids=[c[0] for c in YAML_CASES])
def test_malformed_yaml(cli, tmp_path, name, text, expect, line):
    _check(cli, tmp_path, name, ".yaml", text, expect, line)


@pytest.mark.parametrize("name,text,expect,line", URDF_CASES, ids=[c[0] for c in URDF_CASES])
def test_malformed_urdf(cli, tmp_path, name, text, expect, line):
    _check(cli, tmp_path, name, ".urdf", text, expect, line)


def test_missing_file_and_unknown_name(cli):
    result = cli("profile", "show", "/nonexistent/robot.yaml")
    assert result.exit_code == 2
    assert "does not exist" in result.stderr
    result = cli("profile", "show", "dg-5f-rigth")
    assert result.exit_code == 2
    assert "dg-5f-right" in result.stderr


def test_xacro_missing_argument(cli, tmp_path):
    path = tmp_path / "needs_arg.urdf.xacro"
    path.write_text('<?xml version="1.0"?>\n<robot name="$(arg name)" '
                    'xmlns:xacro="http://www.ros.org/wiki/xacro"/>\n')
    result = cli("profile", "validate", str(path))
    assert result.exit_code == 2
    assert "--arg name:=VALUE" in result.stderr
    assert "Traceback" not in result.stderr
