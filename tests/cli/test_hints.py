"""Hints that name the fix: the URL a near-miss target meant, the package a profile's family
comes in, an interface name one letter off a standard one, and a root help that shows the
verbs by stage of a bring-up."""

from __future__ import annotations

import re

import pytest

from deltoctl import registry, verbs
from tests.conftest import REPO

CANOPEN = REPO / "plugins" / "deltoctl-canopen" / "deltoctl_canopen" / "profiles"


@pytest.mark.parametrize("args, meant", [
    (["-p", "dg-5f-right", "-t", "127.0.0.1:502"], "tcp://127.0.0.1:502"),
    (["-p", "mh5", "--hardware", "upper_body", "-t", "/dev/ttyUSB0"], "serial:///dev/ttyUSB0"),
    (["-p", "mh5", "--hardware", "i2c", "-t", "/dev/i2c-1"], "i2c:///dev/i2c-1"),
])
def test_a_target_without_its_scheme_suggests_the_url(cli, args, meant):
    result = cli(*args, "identify")
    assert result.exit_code == 2, result.output
    assert f"did you mean {meant}?" in result.stderr


def test_a_path_for_a_tcp_device_suggests_no_url(cli):
    result = cli("-p", "dg-5f-right", "-t", "/dev/ttyUSB0", "identify")
    assert result.exit_code == 2 and "did you mean" not in result.stderr
    assert "tcp://" in result.stderr


@pytest.fixture
def without_canopen(monkeypatch):
    """This computer without the deltoctl-canopen package: its family is not found."""
    found = {n: f for n, f in registry.families().items() if n != "canopen"}
    monkeypatch.setattr(registry, "_families", found)


def test_a_canopen_profile_without_its_package_names_it(cli, without_canopen, tmp_path):
    text = (CANOPEN / "cia402-two-axis.yaml").read_text()
    for args in (["-p", str(CANOPEN / "cia402-two-axis.yaml"), "--sim", "identify"],
                 ["profile", "validate", str(CANOPEN / "cia402-two-axis.yaml")]):
        result = cli(*args)
        assert result.exit_code == 2, result.output
        assert "pip install deltoctl-canopen" in result.stderr
        assert "plugins/deltoctl-canopen" in result.stderr
    # a block that names only its plugin, on a bus deltoctl knows
    plugin_only = tmp_path / "plugin-only.yaml"
    plugin_only.write_text(re.sub(r"(?m)^family: canopen\n", "", text).replace(
        "can://socketcan/can0?bitrate=1000000", "tcp://127.0.0.1:9"))
    result = cli("-p", str(plugin_only), "-t", "tcp://127.0.0.1:9", "connect")
    assert "canopen_ros2_control/Cia402System" in result.stderr
    assert "pip install deltoctl-canopen" in result.stderr


def test_with_the_package_installed_no_hint():
    assert registry.install_hint("canopen") == ""
    assert registry.install_hint("dynamixel", "dynamixel_hardware/DynamixelHardware") == ""


def test_an_interface_one_letter_off_a_standard_name_is_a_warning(cli, tmp_path):
    text = (REPO / "profiles" / "rrbot-gpio.yaml").read_text()
    assert "state_interfaces: [position]" in text
    typo = tmp_path / "typo.yaml"
    typo.write_text(text.replace("state_interfaces: [position]", "state_interfaces: [positon]",
                                 1))
    result = cli("profile", "validate", str(typo))
    assert result.exit_code == 3, result.output
    assert "joint1/positon: did you mean joint1/position?" in result.stderr
    assert cli("profile", "validate", str(typo), "--strict").exit_code == 2
    assert cli("profile", "validate", "rrbot-gpio").exit_code == 0


def test_one_letter_off():
    from deltoctl.profile.validate import one_letter_off

    for typed in ("positon", "postion", "psoition", "positionn", "efort", "velocty"):
        assert any(one_letter_off(typed, n) for n in ("position", "effort", "velocity")), typed
    for typed in ("position", "force.x", "output_1", "psotion", "pos"):
        assert not any(one_letter_off(typed, n) for n in ("position", "force", "current"))


def _panels(text: str) -> dict[str, list[str]]:
    """The root help's panels: title → the verbs listed in it."""
    panels: dict[str, list[str]] = {}
    title = None
    for line in text.splitlines():
        head = re.match(r"╭─ (.*?) ─", line)
        if head:
            title = head.group(1)
            panels[title] = []
        elif title and (word := re.match(r"│ (\w+)\s{2,}", line)):
            panels[title].append(word.group(1))
    return panels


def test_the_root_help_shows_the_verbs_by_stage(cli):
    panels = _panels(cli("--help").stdout)
    for stage in verbs.STAGES:
        assert panels[verbs.TITLES[stage]] == [
            name for name, entry in verbs.TABLE.items() if entry.stage == stage]
    assert "Commands" not in panels  # every verb has its stage
    assert list(panels)[-5:] == [verbs.TITLES[s] for s in verbs.STAGES]


def test_square_brackets_in_a_help_are_kept(cli):
    assert "'deltoctl[plot]'" in " ".join(cli("plot", "--help").stdout.split())
