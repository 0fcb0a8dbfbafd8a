"""A family defined only in the tests (tests/toyfamily/: descriptor, driver, emulator) runs
connect, identify, stream and record through the registry's public API, with no change to
deltoctl; and reading the registry imports no family's driver or emulator."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from deltoctl import registry
from tests.conftest import ros2_messages


def test_a_registered_family_runs_the_verbs(cli, toy, tmp_path):
    result = cli("-p", toy, "--sim", "--json", "connect", "-n", "3")
    assert result.exit_code == 0, result.stderr
    assert [b["family"] for b in json.loads(result.stdout)["blocks"]] == ["toy", "toy"]
    identity = json.loads(cli("-p", toy, "--sim", "--json", "identify").stdout)
    assert identity["blocks"][0]["identity"] == {"version": "toy 1.0", "joints": 2}
    result = cli("-p", toy, "--sim", "--json", "stream", "-r", "50", "-d", "0.1")
    assert result.exit_code == 0, result.stderr
    values = json.loads(result.stdout.splitlines()[-1])["values"]
    assert -1 <= values["l2/position"] <= 1 and values["toy_right/connection_status"] == 1.0
    out = tmp_path / "toy.mcap"
    assert cli("-p", toy, "--sim", "record", str(out), "-d", "0.2").exit_code == 0
    names = {tuple(m.name) for _, m in ros2_messages(out, ["/joint_states"])}
    assert names == {("l1", "l2", "r1")}


def test_a_verb_the_family_does_not_offer_says_so(cli, toy):
    result = cli("-p", toy, "--sim", "--yes", "jog", "l1", "0.1")
    assert result.exit_code == 2 and "toy_left cannot move" in result.stderr


def test_reading_the_registry_imports_no_driver_or_emulator():
    code = ("import sys; from deltoctl import registry; registry.families(); "
            "print(sorted(m for m in sys.modules if m.startswith('deltoctl.families.') "
            "and m.count('.') > 2))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "[]"
    assert set(registry.families()) >= {"delto", "dynamixel", "bioscara", "lsm6ds3", "generic"}


def test_a_descriptor_with_an_unknown_capability_is_refused():
    from deltoctl.registry import Family

    with pytest.raises(ValueError, match="unknown capabilities jogg"):
        Family("typo", "tests.toyfamily.driver:ToyDriver", capabilities=frozenset({"jogg"}))
