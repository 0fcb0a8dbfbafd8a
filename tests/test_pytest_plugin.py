"""The fixture deltoctl registers for users' test suites, used as a user would."""

from __future__ import annotations

import json

from typer.testing import CliRunner

from deltoctl.cli.main import app


def test_deltoctl_sim_fixture(deltoctl_sim):
    target = deltoctl_sim("dg-5f-left", firmware="2.7")
    result = CliRunner().invoke(app, ["-p", "dg-5f-left", "-t", target, "identify", "--json"])
    assert result.exit_code == 0, result.stderr
    assert json.loads(result.stdout)["direction_map"] == "legacy"


def test_deltoctl_sim_fixture_serves_an_i2c_arm(deltoctl_sim):
    target = deltoctl_sim("bioscara-arm")
    assert target.startswith("i2c+tcp://")
    home = CliRunner().invoke(app, ["-p", "bioscara-arm", "-t", target, "home", "--yes",
                                    "-j", "j3", "--json"])
    assert home.exit_code == 0, home.stderr
    assert json.loads(home.stdout)["homed"] == {"j3": "homed"}
