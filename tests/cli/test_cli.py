"""The CLI frame: version, global options on either side of the verb, completions."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from deltoctl import __version__
from deltoctl.cli.completion_cmd import SCRIPT_FILES, completion_script
from deltoctl.cmdline import hoist_global_options
from tests.conftest import REPO


def test_version(cli):
    result = cli("--version")
    assert result.exit_code == 0
    assert result.stdout.strip() == f"deltoctl {__version__}"


@pytest.mark.parametrize("args", [
    ["--json", "-p", "rrbot-gpio", "profile", "show"],
    ["profile", "show", "--json", "-p", "rrbot-gpio"],
    ["-p", "rrbot-gpio", "profile", "show", "--json"],
    ["profile", "--json", "show", "--profile=rrbot-gpio"],
])
def test_global_options_before_or_after_the_verb(cli, args):
    result = cli(*args)
    assert result.exit_code == 0, result.stderr
    assert json.loads(result.stdout)["result"]["name"] == "rrbot-gpio"


def test_hoisting_keeps_verb_arguments_in_place():
    assert hoist_global_options(["jog", "j1", "-0.1", "--json", "-t", "tcp://h:1", "--yes"]) == \
        ["--json", "-t", "tcp://h:1", "--yes", "jog", "j1", "-0.1"]
    assert hoist_global_options(["-p", "x", "stream", "-vv", "--", "--json"]) == \
        ["-p", "x", "-vv", "stream", "--", "--json"]


def test_profile_from_environment(cli):
    result = cli("profile", "show", "--json", env={"DELTOCTL_PROFILE": "fts-2d"})
    assert result.exit_code == 0
    assert json.loads(result.stdout)["result"]["sensors"] == 2


def test_no_profile_is_a_usage_error(cli):
    result = cli("profile", "show", env={"DELTOCTL_PROFILE": ""})
    assert result.exit_code == 2
    assert "no profile given" in result.stderr


def test_bad_option_value_is_a_usage_error(cli):
    result = cli("--arg", "novalue", "profile", "list")
    assert result.exit_code == 2
    assert "NAME:=VALUE" in result.stderr
    result = cli("profile", "export", "dg-4f", "--format", "sdf")
    assert result.exit_code == 2


def test_export_to_file_and_show_part(cli, tmp_path):
    out = tmp_path / "mh5.urdf"
    assert cli("profile", "export", "mh5", "-o", str(out)).exit_code == 0
    assert "<ros2_control name=\"upper_body\"" in out.read_text()
    result = cli("profile", "show", "mh5", "l_kne_p", "--json")
    assert result.exit_code == 0
    part = json.loads(result.stdout)["result"]
    assert (part["address"], part["inverse"], part["offset"]) == (14, True, 1.570796326794897)
    assert cli("profile", "show", "mh5", "nope").exit_code == 2


@pytest.mark.parametrize("shell", sorted(SCRIPT_FILES))
def test_shipped_completions_are_up_to_date(shell):
    shipped = (REPO / "completions" / SCRIPT_FILES[shell]).read_text()
    assert shipped == completion_script(shell), \
        f"completions/{SCRIPT_FILES[shell]} is stale: run `deltoctl completion {shell}`"


def _complete(words: str) -> list[str]:
    env = dict(os.environ, _DELTOCTL_COMPLETE="complete_bash", COMP_WORDS=words,
               COMP_CWORD=str(len(words.split()) - (0 if words.endswith(" ") else 1)))
    out = subprocess.run([sys.executable, "-m", "deltoctl"], env=env, capture_output=True,
                         text=True, check=True).stdout
    return out.split()


def test_completion_of_verbs_profiles_and_parts():
    assert "profile" in _complete("deltoctl pro")
    assert "dg-5f-right" in _complete("deltoctl -p dg-5f-r")
    assert "--json" in _complete("deltoctl --js")
    assert "--format" in _complete("deltoctl profile export --fo")
    parts = _complete("deltoctl profile show rrbot-gpio flange_")
    assert parts == ["flange_digital_IOs", "flange_analog_IOs", "flange_vacuum"]


def test_start_up_imports_only_what_the_verb_needs():
    """Protocol, transport, xacro and mcap modules load only in the verbs that use them."""
    heavy = ("deltoctl.transport", "deltoctl.sim", "mcap", "xacro",
             "serial", "smbus2", "rich", "yaml")
    for args in (["--version"], ["profile", "list"]):
        out = subprocess.run([sys.executable, "-X", "importtime", "-m", "deltoctl", *args],
                             capture_output=True, text=True, check=True)
        imported = {line.rsplit("|", 1)[-1].strip() for line in out.stderr.splitlines()}
        loaded = sorted(m for m in imported if m.split(".")[0] in heavy
                        or m.startswith(heavy))
        if args == ["profile", "list"]:  # a cold cache parses the YAML catalog
            loaded = [m for m in loaded if not m.startswith("yaml")]
        assert loaded == [], f"{args}: {loaded}"


def test_sim_serve_refuses_options_of_another_family(cli):
    result = cli("sim", "serve", "dg-4f", "--missing", "rj_dg_1_1")
    assert result.exit_code == 2 and "--missing: not for dg-4f" in result.stderr
    result = cli("sim", "serve", "bioscara-arm", "--firmware", "2.7", "--short-version")
    assert result.exit_code == 2 and "--firmware, --short-version" in result.stderr
