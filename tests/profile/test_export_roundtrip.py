"""Every profile round-trips through export: URDF, xacro macro and YAML read back into the same
model, and validate without a warning of the export's own.

The sources are every catalog profile and every valid case of ros2_control's own parser tests
(tests/profile/test_conformance.py). Each is exported with deltoctl's exporter, written to a file, and
loaded back the way every verb loads a profile (the catalog's load_profile: the real loaders,
xacro included, and validation).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from deltoctl.errors import ProfileError
from deltoctl.profile.catalog import catalog_names, load_profile
from deltoctl.profile.exporter import profile_data, to_urdf, to_yaml
from deltoctl.profile.model import Profile
from tests.profile.test_conformance import VALID, _load

FORMATS = ("urdf", "xacro", "yaml")
CASES = {case.id: case for case in VALID}
SOURCES = [f"catalog:{name}" for name in catalog_names(plugins=False)] + [f"ros2_control:{c}" for c in CASES]

# What the model cannot give a URDF without making up a number. multimodal-gripper's profile
# states no velocity or effort limit for parallel_fingers (the position range comes from its
# interface), and urdfdom requires both on a prismatic joint's <limit>: the export leaves them
# out, says so in a comment, and loads back with the loader's warning about each.
MISSING_LIMITS = {"catalog:multimodal-gripper": [
    "the <limit> of joint 'parallel_fingers' has no effort attribute",
    "the <limit> of joint 'parallel_fingers' has no velocity attribute"]}
# The SDF model's wheels are revolute joints without position limits, which a URDF cannot say.
NOT_URDF = {"ros2_control:valid_sdf": "joint 'left_wheel_joint' is revolute without a lower"}
# deltoctl's own YAML form refuses what a URDF's loader only doubts (validate.py's rule).
YAML_REFUSES = {
    "ros2_control:system_with_size_and_data_type": "unknown data_type 'cv::Mat'",
    "ros2_control:system_with_bool_data_type_on_joint_sensor_and_gpio": "unknown data_type",
    "ros2_control:system_and_disabled_interfaces": "unknown data_type 'cv::Mat'",
    "ros2_control:gripper_mimic_true_valid_config": "missing <plugin>",
    "ros2_control:gripper_no_mimic_valid_config": "missing <plugin>",
    "ros2_control:gripper_mimic_false_valid_config": "missing <plugin>",
    "ros2_control:urdf_without_hardware_plugin": "missing <plugin>",
    "ros2_control:component_missing_plugin_name": "has no command or state interface",
    "ros2_control:component_plugin_name_empty": "has no command or state interface",
}


def _source(source: str, tmp_path: Path) -> Profile:
    kind, name = source.split(":", 1)
    if kind == "catalog":
        return load_profile(name)
    directory = tmp_path / "source"
    directory.mkdir(parents=True)
    return load_profile(_load(CASES[name], directory))


def _robot_around(macro: Path, profile: Profile, directory: Path) -> Path:
    """A robot xacro with the exported URDF's links and joints that includes the exported
    macro of ``profile`` and calls it, as a robot description uses such a macro."""
    urdf = to_urdf(profile)
    kinematics = urdf[urdf.index("<robot"):urdf.index("<ros2_control")].split(">", 1)[1]
    call = profile.name.replace("-", "_") + "_ros2_control"
    robot = directory / "robot.urdf.xacro"
    robot.write_text(f'<?xml version="1.0"?>\n<robot name="{profile.name}" '
                     'xmlns:xacro="http://www.ros.org/wiki/xacro">\n'
                     f'  <xacro:include filename="{macro.name}"/>\n{kinematics}'
                     f"  <xacro:{call}/>\n</robot>\n")
    return robot


def read_back(profile: Profile, fmt: str, directory: Path) -> Profile:
    """``profile`` exported as ``fmt`` into ``directory`` and loaded back."""
    directory.mkdir(exist_ok=True)
    if fmt == "yaml":
        path = directory / "exported.yaml"
        path.write_text(to_yaml(profile))
    elif fmt == "urdf":
        path = directory / "exported.urdf"
        path.write_text(to_urdf(profile))
    else:
        macro = directory / "exported.ros2_control.xacro"
        macro.write_text(to_urdf(profile, macro=True))
        path = _robot_around(macro, profile, directory)
    return load_profile(path)


def _messages(profile: Profile) -> list[str]:
    """The warnings, without where in the xacro output each one is."""
    return [re.sub(r" \(line \d+ of the xacro output\)$", "", w.message)
            for w in profile.warnings]


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("source", SOURCES)
def test_export_reads_back_into_the_same_profile(source: str, fmt: str, tmp_path: Path) -> None:
    """The model, its YAML data and its warnings come back: a catalog profile's export
    validates clean; a ros2_control test URDF's keeps at most the doubts of the URDF itself
    (an unknown data type, a block without <hardware>, a joint without interfaces)."""
    profile = _source(source, tmp_path)
    refused = NOT_URDF.get(source) if fmt != "yaml" else YAML_REFUSES.get(source)
    if refused is not None:
        with pytest.raises(ProfileError, match=re.escape(refused)):
            read_back(profile, fmt, tmp_path / fmt)
        return
    back = read_back(profile, fmt, tmp_path / fmt)
    assert profile_data(back) == profile_data(profile)
    assert back == profile
    expected = [] if fmt == "yaml" else MISSING_LIMITS.get(source, [])
    new = [m for m in _messages(back) if m not in _messages(profile)]
    assert len(new) == len(expected) and all(e in m for e, m in zip(expected, new)), new
    if source.startswith("catalog:"):
        assert _messages(profile) == []


def test_an_unbounded_revolute_joint_is_refused_not_locked(cli, tmp_path: Path) -> None:
    """A missing lower/upper reads as 0 in a URDF: the export refuses (exit 2, one line)
    rather than write a joint that ros2_control would hold at 0."""
    source = _load(CASES["valid_sdf"], tmp_path)
    result = cli("profile", "export", str(source), "--format", "urdf")
    assert result.exit_code == 2, result.output
    assert result.stdout == ""
    assert "Traceback" not in result.output
    assert "cannot be written as URDF: joint 'left_wheel_joint' is revolute" in result.stderr
    yaml_result = cli("profile", "export", str(source), "--format", "yaml")
    assert yaml_result.exit_code == 0, yaml_result.output


YAML_LIMITS = """\
name: limits-beyond-interfaces
family: generic
ros2_control:
  - name: arm
    plugin: mock_components/GenericSystem
    joints:
      - name: wrist
        type: continuous
        limits: {lower: -2, upper: 2, velocity: 1, effort: 3, acceleration: 4, jerk: 9}
        soft_limits: {lower: -3, upper: 1.5, k_position: 10, k_velocity: 2}
        command_interfaces: [position]
        state_interfaces: [position]
      - name: elbow
        limits: {lower: -1, upper: 1, velocity: 2, effort: 5}
        enable_limits: false
        state_interfaces: [position]
"""


@pytest.mark.parametrize("fmt", FORMATS)
def test_limits_no_urdf_limit_holds_come_back(fmt: str, tmp_path: Path) -> None:
    """deltoctl's YAML gives a continuous joint a position range and an acceleration and jerk
    limit without interfaces to carry them: the URDF carries them as deltoctl params; soft
    limits are clamped into the range; switched-off limits stay off."""
    source = tmp_path / "limits.yaml"
    source.write_text(YAML_LIMITS)
    profile = load_profile(source)
    wrist, elbow = profile.joints()
    assert (wrist.limits.lower, wrist.limits.acceleration, wrist.limits.jerk) == (-2, 4, 9)
    assert (wrist.soft_limits.lower, wrist.soft_limits.upper) == (-2, 1.5)
    assert elbow.limits is None and not elbow.enable_limits
    back = read_back(profile, fmt, tmp_path / fmt)
    assert back == profile
    assert _messages(back) == []


@pytest.mark.parametrize("case", ["minimal_robot_urdf", "async_components"])
def test_text_of_transmissions_and_async_properties_is_escaped(case: str, tmp_path: Path) -> None:
    """XML's special characters and xacro's ``$`` in the elements an export now carries come
    back as they were, in a URDF and through xacro."""
    nasty = "a<b>&\"c' ${x} $(env HOME) $$ ]]> --"
    profile = _source(f"ros2_control:{case}", tmp_path)
    hw = profile.hardware[0]
    for transmission in hw.transmissions:
        transmission.type = "ns<x>/" + nasty
        transmission.params["note"] = nasty
        transmission.joints[0].role = nasty
    if hw.async_properties:
        hw.async_properties["scheduling_policy"] = nasty
    for fmt in FORMATS:
        assert read_back(profile, fmt, tmp_path / fmt) == profile
