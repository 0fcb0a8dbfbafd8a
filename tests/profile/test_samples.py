"""Third-party URDF/xacro files import with the counts their MANIFEST gives."""

from __future__ import annotations

import json

import pytest

from deltoctl.profile.catalog import load_profile
from tests.conftest import SAMPLES, needs_samples

pytestmark = needs_samples

DEMO = "ros2_control_demo_description"
CASES = [
    # file, packages, xacro args, [(block, type, plugin or None, joints, sensors, gpios)]
    ("ros2_control_demo_example_1/urdf/rrbot.urdf.xacro", [DEMO, "ros2_control_demo_example_1"],
     {}, [("RRBot", "system", "ros2_control_demo_example_1/RRBotSystemPositionOnlyHardware",
           2, 0, 0)]),
    ("ros2_control_demo_example_4/urdf/rrbot_system_with_sensor.urdf.xacro",
     [DEMO, "ros2_control_demo_example_4"], {},
     [("RRBotSystemWithSensor", "system", None, 2, 1, 0)]),
    ("ros2_control_demo_example_5/urdf/rrbot_system_with_external_sensor.urdf.xacro",
     [DEMO, "ros2_control_demo_example_5"], {},
     [("RRBotSystemPositionOnly", "system", "mock_components/GenericSystem", 2, 0, 0),
      ("ExternalRRBotFTSensor", "sensor", None, 0, 1, 0)]),
    ("ros2_control_demo_example_10/urdf/rrbot.urdf.xacro", [DEMO, "ros2_control_demo_example_10"],
     {}, [("RRBot", "system", "ros2_control_demo_example_10/RRBotSystemWithGPIOHardware",
           2, 0, 2)]),
    ("ros2_control_demo_example_10/urdf/rrbot.urdf.xacro", [DEMO, "ros2_control_demo_example_10"],
     {"use_mock_hardware": "true"},
     [("RRBot", "system", "mock_components/GenericSystem", 2, 0, 2)]),
    ("dg5f_driver/urdf/dg5f_right_ros2_control.xacro", ["dg5f_description"], {},
     [("DG5FRightHardware", "system", "delto_hardware/SystemInterface", 20, 0, 0)]),
    ("dg5f_driver/urdf/dg5f_left_ros2_control.xacro", ["dg5f_description"], {},
     [("DG5FLeftHardware", "system", "delto_hardware/SystemInterface", 20, 0, 0)]),
    ("dg4f_driver/urdf/dg4f_ros2_control.xacro", ["dg4f_description"], {},
     [("dg4f_driver", "system", "delto_hardware/SystemInterface", 18, 4, 0)]),
    ("ros2_control_demo_example_2/urdf/diffbot.urdf.xacro", [DEMO, "ros2_control_demo_example_2"],
     {}, [("DiffBot", "system", "ros2_control_demo_example_2/DiffBotSystemHardware", 2, 0, 0)]),
    ("ur_robot_driver/urdf/ur.urdf.xacro", ["ur_robot_driver", "ur_description"],
     {"name": "ur", "ur_type": "ur5e"},
     [("ur", "system", "ur_robot_driver/URPositionHardwareInterface", 6, 2, 15)]),
    ("ur_description/urdf/ur_mocked.urdf.xacro", ["ur_description"],
     {"name": "ur", "ur_type": "ur5e"}, [("ur", "system", "mock_components/GenericSystem", 6, 2, 0)]),
    ("harness/bioscara_standalone.urdf.xacro", ["bioscara_arm_description"], {},
     [("bioscara_arm", "system", "bioscara_hardware_interfaces/BioscaraArmHardwareInterface",
       4, 0, 0)]),
]


def _packages(names):
    return {n: str(SAMPLES / n) for n in names}


@pytest.mark.parametrize("path,packages,args,blocks", CASES, ids=[c[0] for c in CASES])
def test_sample_imports_with_manifest_counts(path, packages, args, blocks):
    profile = load_profile(SAMPLES / path, args, _packages(packages))
    got = [(h.name, h.type, h.plugin, len(h.joints), len(h.sensors), len(h.gpios))
           for h in profile.hardware]
    want = [(n, t, p if p else g[2], j, s, gp) for (n, t, p, j, s, gp), g in zip(blocks, got)]
    assert got == want


def test_sample_details():
    ex10 = load_profile(SAMPLES / "ros2_control_demo_example_10/urdf/rrbot.urdf.xacro", {},
                        _packages([DEMO, "ros2_control_demo_example_10"]))
    vacuum = ex10.component("flange_vacuum")
    assert vacuum.state("vacuum").initial_value == "1.0"
    assert ex10.component("joint1").command("position").min == -1
    ex1 = load_profile(SAMPLES / "ros2_control_demo_example_1/urdf/rrbot.urdf.xacro", {},
                       _packages([DEMO, "ros2_control_demo_example_1"]))
    # continuous joint: the command interface's min/max become its position limits
    assert (ex1.component("joint1").limits.lower, ex1.component("joint1").limits.upper) == (-1, 1)
    right = load_profile(SAMPLES / "dg5f_driver/urdf/dg5f_right_ros2_control.xacro",
                         {"fingertip_sensor": "true", "io": "true"},
                         _packages(["dg5f_description"]))
    params = right.hardware[0].params
    assert (params["delto_model"], params["fingertip_sensor"], params["IO"]) == \
        ("24354", "true", "true")
    assert right.family_of(right.hardware[0]) == "delto"
    assert right.buses == {"gripper": "tcp://169.254.186.72:502"}
    ur = load_profile(SAMPLES / "ur_robot_driver/urdf/ur.urdf.xacro",
                      {"name": "ur", "ur_type": "ur5e"}, _packages(["ur_robot_driver",
                                                                    "ur_description"]))
    assert "rw_rate" in ur.hardware[0].attributes
    arm = load_profile(SAMPLES / "harness/bioscara_standalone.urdf.xacro", {},
                       _packages(["bioscara_arm_description"]))
    assert arm.component("j1").params["i2c_address"] == "0x11"
    assert arm.component("j2").command("home").params["speed"] == "0.003"


def test_urdf_without_ros2_control_is_a_clear_error(cli):
    result = cli("--package-path", f"ur_description={SAMPLES / 'ur_description'}",
                 "--arg", "name:=ur", "--arg", "ur_type:=ur5e",
                 "profile", "show", str(SAMPLES / "ur_description/urdf/ur.urdf.xacro"))
    assert result.exit_code == 2
    assert "no <ros2_control> block" in result.stderr
    assert "12 joints" in result.stderr


def test_missing_package_path_names_the_package(cli, monkeypatch):
    monkeypatch.delenv("DELTOCTL_PACKAGE_PATH", raising=False)
    result = cli("profile", "show", str(SAMPLES / "harness/bioscara_standalone.urdf.xacro"))
    assert result.exit_code == 2
    assert "bioscara_arm_description" in result.stderr
    assert "--package-path" in result.stderr


def test_package_path_from_environment(cli, monkeypatch):
    monkeypatch.setenv("DELTOCTL_PACKAGE_PATH",
                       f"bioscara_arm_description={SAMPLES / 'bioscara_arm_description'}")
    result = cli("profile", "show", "--json",
                 str(SAMPLES / "harness/bioscara_standalone.urdf.xacro"))
    assert result.exit_code == 0, result.stderr
    assert json.loads(result.stdout)["result"]["joints"] == 4


def test_import_writes_a_yaml_profile_that_loads(cli, tmp_path):
    out = tmp_path / "dg4f.yaml"
    result = cli("--package-path", f"dg4f_description={SAMPLES / 'dg4f_description'}",
                 "profile", "import", str(SAMPLES / "dg4f_driver/urdf/dg4f_ros2_control.xacro"),
                 "-o", str(out))
    assert result.exit_code == 0, result.stderr
    profile = load_profile(out)
    assert len(profile.joints()) == 18
    assert [s.name for s in profile.hardware[0].sensors] == [
        f"fingertip_finger_{n}" for n in range(1, 5)]
