"""The generic family: mock_components/GenericSystem behaviour, and the verbs on it."""

from __future__ import annotations

import json
import time

import pytest

from deltoctl.errors import InvalidInput
from deltoctl.families.generic.driver import GenericDriver
from deltoctl.profile.catalog import load_profile
from deltoctl.profile.model import Interface
from tests.conftest import block_for, block_of


def _driver(name: str, **params: str) -> GenericDriver:
    profile = load_profile(name)
    for hw in profile.hardware:
        hw.params.update(params)
    (hw,) = profile.hardware  # one block: its driver holds every interface
    driver = GenericDriver(block_for(profile, hw))
    driver.configure()
    return driver


def test_initial_values_and_mirroring():
    d = _driver("rrbot-gpio")
    assert d.read()["flange_analog_IOs/analog_output1"] == 3.1
    assert d.read()["joint1/position"] == 0.0
    d.set_command("joint1/position", 0.4)
    d.set_command("flange_vacuum/vacuum", 1.0)
    assert d.read()["joint1/position"] == 0.4
    assert d.read()["flange_vacuum/vacuum"] == 1.0


def test_mock_gpio_and_sensor_commands_inject_readings():
    d = _driver("rrbot-gpio")
    d.set_command("flange_digital_IOs/digital_input1", 1.0)  # a state-only interface
    assert d.read()["flange_digital_IOs/digital_input1"] == 1.0
    without = _driver("rrbot-gpio", mock_gpio_commands="false")
    with pytest.raises(InvalidInput):
        without.set_command("flange_digital_IOs/digital_input1", 1.0)
    fts = _driver("fts-2d")
    fts.set_command("tcp_fts_sensor/fx", 12.5)
    assert fts.read()["tcp_fts_sensor/fx"] == 12.5


def test_disable_commands_offset_and_dynamics():
    d = _driver("rrbot-gpio", disable_commands="true")
    d.set_command("joint1/position", 0.4)
    assert d.read()["joint1/position"] == 0.0
    d = _driver("rrbot-gpio", position_state_following_offset="0.1")
    d.set_command("joint2/position", 0.2)
    assert d.read()["joint2/position"] == pytest.approx(0.3)
    profile = load_profile("rrbot-gpio")
    joint = profile.component("joint1")
    joint.state_interfaces.append(Interface("velocity"))
    profile.hardware[0].params["calculate_dynamics"] = "true"
    d = GenericDriver(block_for(profile, profile.hardware[0]))
    d.configure()
    d.set_command("joint1/position", 0.0)
    time.sleep(0.05)
    d.set_command("joint1/position", 0.1)
    assert 0.5 < d.read()["joint1/velocity"] < 2.5


@pytest.mark.parametrize("name", ["rrbot-gpio", "multimodal-gripper", "fts-2d"])
def test_verbs_on_generic_profiles(cli, name, tmp_path):
    for verb in (["connect"], ["identify"], ["detect"], ["stream", "-d", "0.05"]):
        result = cli("-p", name, *verb, "--json")
        assert result.exit_code == 0, (verb, result.stderr)
    assert json.loads(cli("-p", name, "gpio", "get", "--json").stdout)["result"]
    out = tmp_path / f"{name}.mcap"
    assert cli("-p", name, "record", str(out), "-d", "0.2").exit_code == 0
    assert out.stat().st_size > 0


def test_gpio_and_jog_on_rrbot(cli):
    result = cli("--yes", "-p", "rrbot-gpio", "gpio", "set", "flange_analog_IOs/analog_output1", "2.5",
                 "--json")
    assert result.exit_code == 0
    assert json.loads(result.stdout)["result"]["flange_analog_IOs/analog_output1"] == 2.5
    result = cli("-p", "rrbot-gpio", "jog", "joint1", "--to", "0.4", "--yes", "--json")
    assert block_of(json.loads(result.stdout))["joints"]["joint1"]["position"] == 0.4
    assert cli("-p", "rrbot-gpio", "jog", "joint1", "--to", "1.5", "--yes").exit_code == 5
    assert cli("-p", "multimodal-gripper", "home", "--yes").exit_code == 0
