"""The fixture deltoctl registers for users' test suites, used as a user would."""

from __future__ import annotations

import json

from typer.testing import CliRunner

from deltoctl.cli.main import app
from tests.conftest import block_of, joints_of


def test_deltoctl_sim_fixture(deltoctl_sim):
    target = deltoctl_sim("dg-5f-left", firmware="2.7")
    result = CliRunner().invoke(app, ["-p", "dg-5f-left", "-t", target, "identify", "--json"])
    assert result.exit_code == 0, result.stderr
    assert block_of(json.loads(result.stdout))["identity"]["direction_map"] == "legacy"


def test_deltoctl_sim_fixture_serves_an_i2c_arm(deltoctl_sim):
    target = deltoctl_sim("bioscara-arm")
    assert target.startswith("i2c+tcp://")
    home = CliRunner().invoke(app, ["-p", "bioscara-arm", "-t", target, "home", "--yes",
                                    "-j", "j3", "--json"])
    assert home.exit_code == 0, home.stderr
    assert joints_of(json.loads(home.stdout), "outcome") == {"j3": "homed"}


def test_deltoctl_sim_buses_serves_every_bus_with_faults(deltoctl_sim):
    buses = deltoctl_sim.buses("mh5", missing=("head_y",))
    assert set(buses) == {"upper_body", "lower_body", "i2c"}
    targets = [a for bus, url in buses.items() for a in ("-t", f"{bus}={url}")]
    result = CliRunner().invoke(app, ["-p", "mh5", *targets, "detect", "--json"])
    assert result.exit_code == 1  # head_y is missing
    assert block_of(json.loads(result.stdout), "upper_body")["details"]["missing"] == [52]
    try:
        deltoctl_sim("mh5")
    except ValueError as exc:
        assert "deltoctl_sim.buses('mh5')" in str(exc)
    else:
        raise AssertionError("a three-bus profile has no single target")
