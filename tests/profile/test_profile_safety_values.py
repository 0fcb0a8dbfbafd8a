"""Unsafe values are invalid: every number that bounds motion or timing in a profile is finite
and in its range, or the profile exits 2 naming the field at ``file:line``.

NaN, infinity or a negative number used to validate and then switch the check off (a NaN
current cap meant full duty); each is refused here, in the YAML form and in a URDF.
"""

from __future__ import annotations

import pytest

SAFETY = "safety: {max_jog_step: 10deg, current_cap: 100, home_tolerance: 1deg, home_timeout: 5}"
YAML = f"""\
name: unsafe
family: generic
{SAFETY}
ros2_control:
  - name: hw
    type: system
    plugin: mock_components/GenericSystem
    attributes: {{rw_rate: 100}}
    params: {{loop_rate: 100}}
    joints:
      - name: j1
        limits: {{lower: -1, upper: 1, velocity: 2, effort: 3}}
        command_interfaces: [position]
        state_interfaces: [position]
        params: {{max_velocity: 2}}
"""
SAFETY_LINE, BLOCK_LINE, JOINT_LINE = 3, 5, 11

YAML_CASES = [
    # id, (text to replace, replacement), what the message names, line
    ("lower-nan", ("lower: -1", "lower: .nan"), "lower limit must be a finite number", JOINT_LINE),
    ("lower-minus-inf", ("lower: -1", "lower: -.inf"), "lower limit must be a finite number",
     JOINT_LINE),
    ("upper-inf", ("upper: 1", "upper: .inf"), "upper limit must be a finite number", JOINT_LINE),
    ("velocity-negative", ("velocity: 2", "velocity: -2"), "velocity limit", JOINT_LINE),
    ("velocity-nan", ("velocity: 2", "velocity: .nan"), "velocity limit", JOINT_LINE),
    ("velocity-inf", ("velocity: 2", "velocity: .inf"), "velocity limit", JOINT_LINE),
    ("effort-negative", ("effort: 3", "effort: -3"), "effort limit", JOINT_LINE),
    ("effort-inf", ("effort: 3", "effort: .inf"), "effort limit", JOINT_LINE),
    ("jog-step-nan", ("max_jog_step: 10deg", "max_jog_step: .nan"), "safety.max_jog_step",
     SAFETY_LINE),
    ("jog-step-inf", ("max_jog_step: 10deg", "max_jog_step: .inf"), "safety.max_jog_step",
     SAFETY_LINE),
    ("jog-step-negative", ("max_jog_step: 10deg", "max_jog_step: -10deg"),
     "safety.max_jog_step", SAFETY_LINE),
    ("jog-step-zero", ("max_jog_step: 10deg", "max_jog_step: 0"), "safety.max_jog_step",
     SAFETY_LINE),
    ("current-cap-nan", ("current_cap: 100", "current_cap: .nan"), "safety.current_cap",
     SAFETY_LINE),
    ("current-cap-inf", ("current_cap: 100", "current_cap: .inf"), "safety.current_cap",
     SAFETY_LINE),
    ("current-cap-negative", ("current_cap: 100", "current_cap: -100"), "safety.current_cap",
     SAFETY_LINE),
    ("current-cap-zero", ("current_cap: 100", "current_cap: 0"), "safety.current_cap",
     SAFETY_LINE),
    ("home-tolerance-negative", ("home_tolerance: 1deg", "home_tolerance: -1deg"),
     "safety.home_tolerance", SAFETY_LINE),
    ("home-tolerance-nan", ("home_tolerance: 1deg", "home_tolerance: .nan"),
     "safety.home_tolerance", SAFETY_LINE),
    ("home-timeout-zero", ("home_timeout: 5", "home_timeout: 0"), "safety.home_timeout",
     SAFETY_LINE),
    ("home-timeout-inf", ("home_timeout: 5", "home_timeout: .inf"), "safety.home_timeout",
     SAFETY_LINE),
    ("home-pose-nan", ("home_timeout: 5}", "home_timeout: 5, home_pose: {j1: .nan}}"),
     "safety.home_pose of 'j1' must be a finite number", SAFETY_LINE),
    ("interface-min-nan", ("command_interfaces: [position]",
                           "command_interfaces: [{name: position, min: .nan, max: 1}]"),
     "j1/position: min must be a finite number", JOINT_LINE + 2),
    ("interface-max-inf", ("command_interfaces: [position]",
                           "command_interfaces: [{name: position, min: -1, max: .inf}]"),
     "j1/position: max must be a finite number", JOINT_LINE + 2),
    ("rw-rate-negative", ("rw_rate: 100", "rw_rate: -5"), "rw_rate", BLOCK_LINE),
    ("rw-rate-text", ("rw_rate: 100", "rw_rate: fast"), "rw_rate", BLOCK_LINE),
    ("rate-param-nan", ("loop_rate: 100", "loop_rate: .nan"), "param 'loop_rate'", BLOCK_LINE),
    ("rate-param-inf", ("loop_rate: 100", "loop_rate: .inf"), "param 'loop_rate'", BLOCK_LINE),
    ("rate-param-negative", ("loop_rate: 100", "loop_rate: -1"), "param 'loop_rate'",
     BLOCK_LINE),
    ("velocity-param-negative", ("max_velocity: 2", "max_velocity: -2"),
     "param 'max_velocity'", JOINT_LINE),
    ("velocity-param-nan", ("max_velocity: 2", "max_velocity: .nan"), "param 'max_velocity'",
     JOINT_LINE),
]


def _validate(cli, tmp_path, name: str, text: str):
    path = tmp_path / name
    path.write_text(text)
    return path, cli("profile", "validate", str(path))


def test_the_base_profile_is_valid(cli, tmp_path):
    _, result = _validate(cli, tmp_path, "base.yaml", YAML)
    assert result.exit_code == 0, result.stderr


@pytest.mark.parametrize("name,change,expect,line", YAML_CASES, ids=[c[0] for c in YAML_CASES])
def test_unsafe_yaml_value_is_refused(cli, tmp_path, name, change, expect, line):
    old, new = change
    assert old in YAML
    path, result = _validate(cli, tmp_path, f"{name}.yaml", YAML.replace(old, new, 1))
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert f"{path}:{line}: " in result.stderr, result.stderr
    assert expect in result.stderr, result.stderr


URDF = """\
<?xml version="1.0"?>
<robot name="unsafe">
  <link name="base"/><link name="l1"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <limit lower="-1" upper="1" effort="3" velocity="2"/>
    <safety_controller soft_lower_limit="-0.9" soft_upper_limit="0.9" k_position="10" k_velocity="5"/>
  </joint>
  <ros2_control name="hw" type="system" rw_rate="100">
    <hardware>
      <plugin>mock_components/GenericSystem</plugin>
      <param name="pvl_reader_rate">100</param>
      <param name="deltoctl.profile.family">generic</param>
      <param name="deltoctl.profile.safety.max_jog_step">0.1</param>
      <param name="deltoctl.profile.safety.current_cap">100</param>
    </hardware>
    <joint name="j1">
      <command_interface name="position"><param name="max">0.5</param></command_interface>
      <state_interface name="position"/>
    </joint>
  </ros2_control>
</robot>
"""

URDF_CASES = [
    ("limit-nan", ('lower="-1"', 'lower="nan"'), "lower of joint 'j1' must be a number", 5),
    ("limit-inf", ('upper="1"', 'upper="inf"'), "upper of joint 'j1' must be a number", 5),
    ("soft-gain-negative", ('k_velocity="5"', 'k_velocity="-5"'), "k_velocity", 16),
    ("jog-step-nan", (">0.1<", ">nan<"), "safety.max_jog_step", 13),
    ("current-cap-inf", (">100</param>\n    </hardware>", ">inf</param>\n    </hardware>"),
     "safety.current_cap", 14),
    ("interface-max-inf", (">0.5<", ">inf<"), "max of j1/position must be a finite number", 17),
    ("rw-rate-negative", ('rw_rate="100"', 'rw_rate="-1"'), "rw_rate", 8),
    ("rate-param-negative", ('"pvl_reader_rate">100', '"pvl_reader_rate">-100'),
     "param 'pvl_reader_rate'", 8),
]


def test_the_base_urdf_is_valid(cli, tmp_path):
    _, result = _validate(cli, tmp_path, "base.urdf", URDF)
    assert result.exit_code == 0, result.stderr


@pytest.mark.parametrize("name,change,expect,line", URDF_CASES, ids=[c[0] for c in URDF_CASES])
def test_unsafe_urdf_value_is_refused(cli, tmp_path, name, change, expect, line):
    old, new = change
    assert old in URDF
    path, result = _validate(cli, tmp_path, f"{name}.urdf", URDF.replace(old, new, 1))
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert f"{path}:{line}: " in result.stderr, result.stderr
    assert expect in result.stderr, result.stderr


def test_a_soft_limit_is_not_looser_than_the_hard_one(tmp_path):
    """Soft limits are kept apart and lie inside the hard range, as ros2_control clamps them."""
    from deltoctl.profile.catalog import load_profile

    path = tmp_path / "soft.urdf"
    path.write_text(URDF.replace('soft_upper_limit="0.9"', 'soft_upper_limit="2"'))
    j1 = load_profile(path).component("j1")
    assert (j1.limits.lower, j1.limits.upper) == (-1, 0.5)  # the interface's max is stricter
    assert (j1.soft_limits.lower, j1.soft_limits.upper) == (-0.9, 0.5)
    assert (j1.soft_limits.k_position, j1.soft_limits.k_velocity) == (10, 5)


def test_a_velocity_limit_honours_the_interface_min(tmp_path):
    """min -0.05 with max 0.1 bounds the speed at 0.05 either way: the stricter wins."""
    from deltoctl.profile.catalog import load_profile

    path = tmp_path / "velocity.urdf"
    path.write_text(URDF.replace(
        '<state_interface name="position"/>\n    </joint>',
        '<command_interface name="velocity"><param name="min">-0.05</param>'
        '<param name="max">0.1</param></command_interface>\n'
        '      <state_interface name="position"/>\n    </joint>'))
    assert load_profile(path).component("j1").limits.velocity == 0.05


def test_the_catalog_still_validates(cli):
    from deltoctl.profile.catalog import catalog_names

    result = cli("profile", "validate", *catalog_names())
    assert result.exit_code == 0, result.stderr


UNIT_CASES = [
    # the joint's type, the limits line, what the message names
    ("prismatic", "limits: {lower: -1, upper: 20deg, velocity: 2}", "limits.upper of joint 'j1'"),
    ("prismatic", "limits: {lower: -1, upper: 1, velocity: 30deg/s}",
     "limits.velocity of joint 'j1'"),
    ("revolute", "limits: {lower: -1, upper: 5mm, velocity: 2}", "limits.upper of joint 'j1'"),
    ("revolute", "limits: {lower: -1rad/s, upper: 1, velocity: 2}", "limits.lower of joint 'j1'"),
    ("revolute", "limits: {lower: -1, upper: 1, velocity: 2m/s}",
     "limits.velocity of joint 'j1'"),
    ("prismatic", "limits: {lower: -1, upper: 1, velocity: 2}\n"
                  "        soft_limits: {lower: -10deg, upper: 0.5}",
     "soft_limits.lower of joint 'j1'"),
]


@pytest.mark.parametrize("joint_type,limits,expect", UNIT_CASES)
def test_a_limit_in_another_unit_than_its_joints_is_refused(cli, tmp_path, joint_type, limits,
                                                              expect):
    """20deg on a prismatic joint would be 0.349 m; a /s unit is no position."""
    text = YAML.replace("        limits: {lower: -1, upper: 1, velocity: 2, effort: 3}",
                        f"        type: {joint_type}\n        {limits}")
    path, result = _validate(cli, tmp_path, "units.yaml", text)
    assert result.exit_code == 2, result.output
    assert f"{path}:{JOINT_LINE + 2 + limits.count(chr(10))}: " in result.stderr, result.stderr
    assert expect in result.stderr and f"is a {joint_type} joint" in result.stderr


def test_limits_in_their_joints_unit_are_valid(cli, tmp_path):
    text = YAML.replace("        limits: {lower: -1, upper: 1, velocity: 2, effort: 3}",
                        "        type: prismatic\n"
                        "        limits: {lower: -10mm, upper: 0.02, velocity: 30mm/s}")
    text = text.replace("10deg", "5mm").replace("1deg", "1mm")
    _, result = _validate(cli, tmp_path, "units.yaml", text)
    assert result.exit_code == 0, result.stderr
