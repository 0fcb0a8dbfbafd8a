"""The catalog: every profile validates, round-trips, and matches its shipped URDF."""

from __future__ import annotations

import json
import math

import pytest

from deltoctl.profile.catalog import catalog_names, load_profile
from deltoctl.profile.exporter import to_urdf, to_yaml
from tests.conftest import REPO

NAMES = catalog_names(plugins=False)  # deltoctl's own catalog
DELTO = ["dg-3f-b", "dg-3f-m", "dg-4f", "dg-5f-left", "dg-5f-right", "dg-5f-s-left",
         "dg-5f-s-right", "dg-5f-s15-left", "dg-5f-s15-right"]


def test_catalog_has_every_device():
    assert set(DELTO + ["mh5", "bioscara-arm", "rrbot-gpio", "multimodal-gripper",
                        "fts-2d"]) <= set(NAMES)


@pytest.mark.parametrize("name", NAMES)
def test_yaml_urdf_yaml_round_trip(name, tmp_path):
    profile = load_profile(name)
    urdf = tmp_path / f"{name}.urdf"
    urdf.write_text(to_urdf(profile))
    from_urdf = load_profile(urdf)
    assert from_urdf == profile
    yaml_file = tmp_path / f"{name}.yaml"
    yaml_file.write_text(to_yaml(from_urdf))
    assert load_profile(yaml_file) == profile


@pytest.mark.parametrize("name", NAMES)
def test_shipped_urdf_is_in_sync(name):
    shipped = REPO / "urdf" / f"{name}.urdf"
    assert shipped.read_text() == to_urdf(load_profile(name)), \
        f"urdf/{name}.urdf is stale: run `deltoctl profile export {name} -o urdf/{name}.urdf`"


def test_xacro_macro_export_loads_through_xacro(tmp_path):
    profile = load_profile("rrbot-gpio")
    macro = tmp_path / "rrbot_gpio.ros2_control.xacro"
    macro.write_text(to_urdf(profile, macro=True))
    # The macro holds the blocks; the kinematics come from the robot's own URDF.
    kin = to_urdf(profile).split("<ros2_control")[0].split("\n", 2)[2]
    robot = tmp_path / "robot.urdf.xacro"
    robot.write_text(
        '<?xml version="1.0"?>\n<robot name="rrbot-gpio" '
        'xmlns:xacro="http://www.ros.org/wiki/xacro">\n'
        f'<xacro:include filename="{macro}"/>\n' + kin.split(">", 1)[1] +
        "<xacro:rrbot_gpio_ros2_control/>\n</robot>\n")
    assert load_profile(robot) == profile


def test_delto_facts():
    right = load_profile("dg-5f-right")
    hw = right.hardware[0]
    assert hw.params["delto_model"] == "24354"  # 0x5F22
    assert [j.name for j in hw.joints][:5] == [
        "rj_dg_1_1", "rj_dg_1_2", "rj_dg_1_3", "rj_dg_1_4", "rj_dg_2_1"]
    j = right.component("rj_dg_1_1")
    assert math.isclose(j.limits.lower, math.radians(-22))
    assert math.isclose(j.limits.upper, math.radians(51))
    assert right.component("right_fingertip_finger_5").state_interfaces[2].name == "force.z"
    assert "gpio/input_1" in right.state_interfaces()
    assert right.buses == {"gripper": "tcp://169.254.186.72:502"}
    assert load_profile("dg-5f-left").buses["gripper"] == "tcp://169.254.186.73:502"
    assert load_profile("dg-3f-b").status == "discontinued"
    assert len(load_profile("dg-5f-s15-right").joints()) == 15
    assert len(load_profile("dg-4f").joints()) == 18


def test_mh5_and_bioscara_facts():
    mh5 = load_profile("mh5")
    assert len(mh5.joints()) == 22
    knee = mh5.component("l_kne_p")
    assert (knee.address, knee.inverse, knee.offset) == (14, True, 1.570796326794897)
    assert mh5.component("imu").address == 0x6A
    assert set(mh5.buses) == {"upper_body", "lower_body", "i2c"}
    arm = load_profile("bioscara-arm")
    j2 = arm.component("j2")
    assert j2.joint_type == "prismatic"
    assert j2.params["reduction"] == "-1570.79632679"
    assert j2.command("home").params == {
        "speed": "0.003", "threshold": "50", "current": "30", "acceleration": "0.001"}
    assert arm.safety.homing_order == ["j2", "j1", "j4", "j3"]


def test_profile_list_json(cli):
    result = cli("profile", "list", "--json")
    assert result.exit_code == 0, result.output
    rows = json.loads(result.stdout)["result"]
    assert sorted(r["name"] for r in rows) == catalog_names()  # installed packages' too
    assert set(NAMES) <= {r["name"] for r in rows}
    delto = {r["name"]: r for r in rows}
    assert delto["dg-5f-right"]["joints"] == 20
    assert delto["dg-3f-b"]["status"] == "discontinued"


def test_wheel_ships_the_data_directories(tmp_path):
    """A non-editable install must find every built-in profile: check the wheel's contents."""
    import subprocess
    import sys
    import zipfile

    build = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path), str(REPO)],
        capture_output=True, text=True)
    if build.returncode != 0:
        pytest.skip(f"cannot build a wheel here: {build.stderr.strip()[-200:]}")
    wheel = next(tmp_path.glob("deltoctl-*.whl"))
    names = set(zipfile.ZipFile(wheel).namelist())
    for name in NAMES:
        assert f"deltoctl/_data/profiles/{name}.yaml" in names
        assert f"deltoctl/_data/urdf/{name}.urdf" in names
    assert "deltoctl/_data/completions/deltoctl.bash" in names


def test_profile_list_uses_the_cache_and_notices_changes(cli, monkeypatch, tmp_path):
    import deltoctl.profile.catalog as catalog

    first = cli("profile", "list", "--json")
    assert first.exit_code == 0

    def no_loading(*args, **kwargs):
        raise AssertionError("the catalog should come from the cache")

    real_load = catalog.load_profile
    monkeypatch.setattr(catalog, "load_profile", no_loading)
    assert cli("profile", "list", "--json").stdout == first.stdout
    # a new or changed profile file is loaded again
    (tmp_path / "fts-2d.yaml").write_text((REPO / "profiles" / "fts-2d.yaml").read_text())
    monkeypatch.setattr(catalog, "load_profile", real_load)
    monkeypatch.setattr(catalog, "catalog_dir", lambda: tmp_path)
    monkeypatch.setattr(catalog, "_plugin_dirs", list)
    rows = json.loads(cli("profile", "list", "--json").stdout)["result"]
    assert [r["name"] for r in rows] == ["fts-2d"]


def test_a_package_adds_its_profiles_to_the_catalog(tmp_path, monkeypatch):
    """The deltoctl.profiles entry-point group: a package's folder of profiles joins the
    catalog by name, never replacing one of deltoctl's own."""
    import shutil
    import sys

    from deltoctl import entry_points
    from deltoctl.profile import catalog

    package = tmp_path / "robots_pkg"
    (package / "profiles").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    shutil.copy(catalog.catalog_dir() / "rrbot-gpio.yaml", package / "profiles" / "my-rrbot.yaml")
    shutil.copy(catalog.catalog_dir() / "mh5.yaml", package / "profiles" / "dg-5f-right.yaml")
    monkeypatch.syspath_prepend(str(tmp_path))
    real = entry_points.declared
    monkeypatch.setattr(entry_points, "declared",
                        lambda group: [("robots", "robots_pkg:profiles")]
                        if group == catalog.PROFILES_GROUP else real(group))
    assert "my-rrbot" in catalog.catalog_names()
    assert "my-rrbot" not in catalog.catalog_names(plugins=False)
    assert catalog.resolve("my-rrbot") == package / "profiles" / "my-rrbot.yaml"
    assert catalog.load_profile("my-rrbot").joints()
    assert catalog.resolve("dg-5f-right") == catalog.catalog_dir() / "dg-5f-right.yaml"
    assert "robots_pkg" not in sys.modules  # found without importing the package
