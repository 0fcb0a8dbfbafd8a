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
