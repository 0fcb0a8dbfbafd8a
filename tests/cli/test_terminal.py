"""A technician's terminal: suggestions for every name, help that teaches, one JSON shape for
errors, tables that fit, strict target URLs and completion for every argument."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys

import pytest

from deltoctl.cli.main import VERBS
from deltoctl.cmdline import hoist_global_options, split_cluster
from deltoctl.errors import InvalidInput
from deltoctl.suggest import close_matches
from tests.conftest import REPO

DELTOCTL = shutil.which("deltoctl", path=os.path.dirname(sys.executable)) or "deltoctl"
ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")


# -- suggestions ------------------------------------------------------------------------------

def test_the_start_of_a_name_ranks_first():
    from deltoctl.profile.catalog import catalog_names

    close = close_matches("dg5f", catalog_names())
    assert {"dg-5f-left", "dg-5f-right"} <= set(close) and "dg-4f" not in close
    assert close_matches("idnetify", VERBS) == ["identify"]
    assert close_matches("rj_dg_1_1/positon", ["rj_dg_1_1/position", "rj_dg_1_2/position",
                                                "rj_dg_1_1/velocity"]) == ["rj_dg_1_1/position"]
    assert close_matches("zzz", ["head_y", "head_p"]) == []


def test_a_mistyped_verb_is_suggested(cli):
    result = cli("idnetify")
    assert result.exit_code == 2 and "Did you mean 'identify'?" in result.stderr
    result = cli("profile", "lsit")
    assert result.exit_code == 2 and "'list'" in result.stderr


def test_a_mistyped_profile_suggests_the_nearest_names(cli):
    result = cli("-p", "dg5f", "profile", "show")
    assert result.exit_code == 2
    assert "dg-5f-right" in result.stderr and "dg-5f-left" in result.stderr
    assert "dg-4f" not in result.stderr


def test_mistyped_parts_blocks_and_interfaces(cli):
    result = cli("-p", "rrbot-gpio", "gpio", "set", "flange_vacum/vacuum", "on")
    assert result.exit_code == 2 and "did you mean flange_vacuum?" in result.stderr
    result = cli("-p", "mh5", "--hardware", "upper_bdy", "detect")
    assert result.exit_code == 2 and "did you mean upper_body?" in result.stderr
    result = cli("-p", "rrbot-gpio", "stream", "-d", "0.05", "-i", "joint1/positon")
    assert result.exit_code == 2 and "did you mean joint1/position?" in result.stderr


def test_a_mistyped_register_item_is_suggested():
    from deltoctl.families.dynamixel.control_table import item_named

    with pytest.raises(InvalidInput, match="did you mean return_delay_time"):
        item_named("retrun_delay_time")
    assert item_named("return_delay_time").address == 9


def test_a_mistyped_global_option_after_the_verb_is_suggested(cli):
    result = cli("-p", "rrbot-gpio", "profile", "show", "--jsn")
    assert result.exit_code == 2 and "--json" in result.stderr


# -- help -------------------------------------------------------------------------------------

@pytest.mark.parametrize("verb", [[v] for v in VERBS if v != "help"] + [
    ["register", "get"], ["profile", "export"], ["sim", "serve"], ["gpio", "set"]])
def test_every_verb_lists_the_global_options_an_example_and_the_exit_codes(cli, verb):
    result = cli(*verb, "-h")
    assert result.exit_code == 0, result.output
    text = result.stdout
    assert "Global options" in text and "--json" in text and "--target" in text
    assert "Exit codes: 0 ok" in text and "5 refused for safety" in text
    if len(verb) == 1 or " ".join(verb) in ("register get", "profile export"):
        assert "Example: deltoctl" in text


def test_the_root_help_and_help_exit_codes(cli):
    assert "Exit codes: 0 ok" in cli("-h").stdout
    codes = json.loads(cli("help", "exit-codes", "--json").stdout)["result"]
    assert [c["code"] for c in codes] == [0, 1, 2, 3, 4, 5, 130]
    assert "refused for safety" in cli("help", "exit-codes").stdout
    assert "Move one joint" in cli("help", "jog").stdout
    result = cli("help", "jgo")
    assert result.exit_code == 2 and "did you mean jog?" in result.stderr


def test_combined_short_flags_after_the_verb():
    assert split_cluster("-yq") == ("-yq", "", False)
    assert split_cluster("-yn5") == ("-y", "-n5", False)
    assert split_cluster("-5deg") == ("", "-5deg", False)
    assert split_cluster("-yp") == ("-yp", "", True)
    assert split_cluster("-vvpdg-4f") == ("-vvpdg-4f", "", False)
    assert hoist_global_options(["jog", "J", "5deg", "-yq"]) == ["-yq", "jog", "J", "5deg"]
    assert hoist_global_options(["connect", "-yn5", "-qp", "mh5"]) == \
        ["-y", "-qp", "mh5", "connect", "-n5"]
    assert hoist_global_options(["jog", "J", "-0.1", "-vy"]) == ["-vy", "jog", "J", "-0.1"]
    assert hoist_global_options(["-yp", "mh5", "torque", "off"]) == ["-yp", "mh5", "torque", "off"]


def test_yq_after_the_verb_runs(cli):
    result = cli("-p", "rrbot-gpio", "jog", "joint1", "--to", "0.1", "-yq")
    assert result.exit_code == 0, result.output
    result = cli("-p", "rrbot-gpio", "jog", "joint1", "--to", "0.2", "-yq", "--json")
    assert json.loads(result.stdout)["result"]["settled"] is True


# -- one JSON shape ---------------------------------------------------------------------------

def test_profile_export_and_import_answer_in_json(cli, tmp_path):
    plain = cli("profile", "export", "dg-4f", "--format", "yaml").stdout
    doc = json.loads(cli("profile", "export", "dg-4f", "--format", "yaml", "--json").stdout)["result"]
    assert doc["content"] == plain and doc["output"] is None and doc["format"] == "yaml"
    assert doc["blocks"] == ["dg4f_driver"] and doc["joints"] == 18
    out = tmp_path / "dg4f.urdf"
    doc = json.loads(cli("--json", "profile", "export", "dg-4f", "-o", str(out)).stdout)["result"]
    assert doc["output"] == str(out) and doc["bytes"] == out.stat().st_size
    assert "content" not in doc
    yaml_out = tmp_path / "rrbot.yaml"
    result = cli("profile", "import", str(REPO / "urdf" / "rrbot-gpio.urdf"), "-o",
                 str(yaml_out), "--json")
    doc = json.loads(result.stdout)["result"]
    assert doc["format"] == "yaml" and doc["output"] == str(yaml_out) and doc["gpios"] == 3
    assert cli("profile", "validate", str(yaml_out)).exit_code == 0


def _error(result) -> dict:
    assert result.stdout == ""
    return json.loads(result.stderr)["error"]


def test_errors_are_one_json_object_on_stderr_with_json(cli):
    error = _error(cli("--json", "-p", "nope", "profile", "show"))
    assert error["exit_code"] == 2 and "no profile named 'nope'" in error["message"]
    error = _error(cli("-p", "rrbot-gpio", "gpio", "set", "nope/x", "on", "--json"))
    assert error["exit_code"] == 2 and "nope" in error["message"]
    error = _error(cli("--json", "idnetify"))  # a usage error, found while parsing
    assert error == {"message": "No such command 'idnetify'. Did you mean 'identify'?",
                     "hint": "see 'deltoctl -h'", "exit_code": 2}
    error = _error(cli("profile", "show", "--bogus", "--json"))
    assert error["exit_code"] == 2 and "--bogus" in error["message"]
    error = _error(cli("--json", "--arg", "novalue", "profile", "list"))
    assert "NAME:=VALUE" in error["message"]
    result = cli("-p", "nope", "profile", "show")
    assert result.stderr.startswith("deltoctl: error: no profile named 'nope'")


# -- layout -----------------------------------------------------------------------------------

def _on_terminal(*args: str, columns: int = 80) -> list[str]:
    pexpect = pytest.importorskip("pexpect")
    child = pexpect.spawn(DELTOCTL, list(args), dimensions=(60, columns), encoding="utf-8",
                          timeout=30, env=dict(os.environ, TERM="xterm"))
    child.expect(pexpect.EOF)
    return ANSI.sub("", child.before).replace("\r", "").splitlines()


def test_tables_fit_80_columns_without_cutting_a_value():
    lines = _on_terminal("profile", "show", "mh5")
    assert max(len(line) for line in lines) <= 80
    text = "\n".join(lines)
    assert "…" not in text
    for joint in ("head_p", "l_sho_p", "r_ank_r"):
        assert joint in text


def test_a_stream_on_an_80x24_terminal_fits_it():
    pexpect = pytest.importorskip("pexpect")
    child = pexpect.spawn(DELTOCTL, ["-p", "mh5", "--sim", "stream", "-d", "0.5"],
                          dimensions=(24, 80), encoding="utf-8", timeout=60,
                          env=dict(os.environ, TERM="xterm"))
    child.expect(pexpect.EOF)
    lines = ANSI.sub("", child.before).replace("\r", "").splitlines()
    text = "\n".join(lines)
    assert "linear_acceleration.z" in text and "Ctrl-C to stop" in text  # the IMU in view
    assert "more rows (" in text and "narrow with -i 'PATTERN'" in text
    assert "..." not in lines  # nothing cut at the bottom of the screen


def test_piped_tables_are_never_cut(cli):
    lines = cli("profile", "show", "dg-5f-right").stdout.splitlines()
    assert any("position, velocity, effort, temperature" in line for line in lines)
    assert max(len(line) for line in lines) > 80  # plain text takes the room it needs


def test_the_live_table_fits_80_columns(cli):
    from rich.console import Console

    from deltoctl.render.stream import live_tables

    sample = json.loads(cli("--sim", "-p", "dg-5f-right", "stream", "-d", "0.05")
                        .stdout.splitlines()[-1])["values"]
    with open(os.devnull, "w") as devnull:
        console = Console(record=True, width=80, file=devnull)
        console.print(live_tables(sample, "at 80 columns"))
    lines = console.export_text().splitlines()
    assert max(len(line) for line in lines) <= 80
    text = "\n".join(lines)
    assert "…" not in text
    for axis in ("force.x", "force.z", "torque.x", "torque.z", "temperature", "input_1"):
        assert axis in text
    row = [line for line in lines if "right_fingertip_finger_1" in line]
    assert len(row) == 2  # the six axes in two tables, the part's name in each


def test_quiet_hides_notes_not_results(cli, tmp_path):
    out = tmp_path / "x.urdf"
    result = cli("-q", "profile", "export", "dg-4f", "-o", str(out))
    assert result.exit_code == 0 and result.stderr == "" and out.exists()
    result = cli("profile", "export", "dg-4f", "-o", str(out))
    assert f"wrote {out}" in result.stderr
    result = cli("-q", "profile", "show", "rrbot-gpio")
    assert "flange_vacuum" in result.stdout


# -- strict targets ---------------------------------------------------------------------------

def test_tcp_urls_are_strict():
    from deltoctl.transport.tcp import parse_tcp_url

    assert parse_tcp_url("tcp://169.254.186.72:502") == ("169.254.186.72", 502)
    assert parse_tcp_url("tcp://gripper", 502) == ("gripper", 502)  # the caller's default
    for url, what in (("tcp://h:502?baud=9600", "unknown key 'baud'"),
                      ("tcp://h:70000", "1 to 65535"), ("tcp://h:0", "1 to 65535"),
                      ("tcp://169.254.186.720:502", "not an IPv4 address"),
                      ("tcp://h:502/x", "nothing else"), ("udp://h:1", "not a TCP target"),
                      ("tcp://gripper", "no port")):
        with pytest.raises(InvalidInput, match=re.escape(what)):
            parse_tcp_url(url)


def test_i2c_urls_are_strict(cli):
    from deltoctl.transport.i2c import parse_i2c_url

    for url, what in (("i2c:///dev/i2c-1?clock=400000", "unknown key 'clock'"),
                      ("i2c://dev/i2c-1", "three slashes"),
                      ("i2c+tcp://127.0.0.1:99999", "1 to 65535")):
        with pytest.raises(InvalidInput, match=re.escape(what)):
            parse_i2c_url(url)
    result = cli("-p", "bioscara-arm", "-t", "i2c:///dev/i2c-1?clock=400000", "connect")
    assert result.exit_code == 2 and "unknown key 'clock'" in result.stderr


# -- completion -------------------------------------------------------------------------------

def complete(cli, words: str) -> list[str]:
    cword = len(words.split()) - (0 if words.endswith(" ") else 1)
    result = cli(env={"_DELTOCTL_COMPLETE": "complete_bash", "COMP_WORDS": words,
                      "COMP_CWORD": str(cword)}, prog_name="deltoctl")
    return result.stdout.split()


def test_completion_of_servo_verbs(cli):
    assert complete(cli, "deltoctl -p mh5 torque o") == ["on", "off"]
    targets = complete(cli, "deltoctl -p mh5 torque off ")
    assert {"head", "left_arm", "arms", "legs", "all", "head_y", "r_ank_r"} <= set(targets)
    assert complete(cli, "deltoctl -p mh5 reboot le") == ["left_arm", "left_leg", "legs"]
    assert complete(cli, "deltoctl -p mh5 register get head_y present_te") == \
        ["present_temperature"]
    assert complete(cli, "deltoctl -p mh5 register set hea") == ["head_p", "head_y"]
    assert complete(cli, "deltoctl -p mh5 register set head_y ret") == ["return_delay_time"]


def test_completion_of_values_profiles_and_options(cli):
    assert complete(cli, "deltoctl profile export dg-4f --format ") == ["urdf", "xacro", "yaml"]
    assert complete(cli, "deltoctl profile export dg-4f -f x") == ["xacro"]
    assert complete(cli, "deltoctl sim serve dg-5f-ri") == ["dg-5f-right"]
    assert complete(cli, "deltoctl sim serve mh5 --missing head") == ["head_p", "head_y"]
    assert "flange_vacuum/vacuum" in complete(cli, "deltoctl -p rrbot-gpio gpio set fla")
    assert complete(cli, "deltoctl -p mh5 detect --hardware up") == ["upper_body"]
    assert complete(cli, "deltoctl identify --js") == ["--json"]
    assert complete(cli, "deltoctl help exit") == ["exit-codes"]
    assert complete(cli, "deltoctl completion ") == ["bash", "zsh", "fish", "man"]


def test_servo_completion_never_runs_xacro(cli, tmp_path, monkeypatch):
    import xacro

    monkeypatch.setattr(xacro, "process_file", lambda *a, **k: pytest.fail("xacro ran"))
    profile = tmp_path / "r.urdf.xacro"
    profile.write_text(REPO.joinpath("urdf", "mh5.urdf").read_text())
    assert complete(cli, f"deltoctl -p {profile} torque off ") == []
    assert complete(cli, f"deltoctl sim serve {profile} --missing ") == []
    plain = tmp_path / "r.urdf"
    plain.write_text(REPO.joinpath("urdf", "mh5.urdf").read_text())
    assert "head_y" in complete(cli, f"deltoctl -p {plain} reboot ")


def test_the_shipped_bash_script_completes_in_a_real_shell(tmp_path):
    pexpect = pytest.importorskip("pexpect")
    if not shutil.which("bash"):
        pytest.skip("no bash")
    env = dict(os.environ, PATH=f"{os.path.dirname(DELTOCTL)}:{os.environ['PATH']}",
               PS1="$ ", INPUTRC=str(tmp_path / "inputrc"), XDG_CACHE_HOME=str(tmp_path))
    (tmp_path / "inputrc").write_text("set show-all-if-ambiguous on\nset bell-style none\n")
    shell = pexpect.spawn("bash", ["--norc", "--noprofile", "-i"], env=env, encoding="utf-8",
                          timeout=30, dimensions=(40, 200))
    try:
        shell.expect_exact("$ ")
        shell.sendline(f"source {REPO / 'completions' / 'deltoctl.bash'}")
        shell.expect_exact("$ ")
        shell.send("deltoctl -p mh5 torque off le\t")
        shell.expect("left_arm +left_leg +legs")
        shell.send("\x15")  # clear the line
        shell.send("deltoctl -p mh5 register get head_y present_te\t")
        shell.expect_exact("present_temperature ")
        shell.send("\x15")
        shell.send("deltoctl idnet\t")
        shell.expect_exact("deltoctl idnet")  # nothing to complete: the line stays as typed
        shell.send("\x15")
        shell.send("deltoctl ident\t")
        shell.expect_exact("identify ")
    finally:
        shell.close(force=True)


def test_shipped_completion_scripts_are_current():
    from deltoctl.cli.completion_cmd import SCRIPT_FILES, completion_script

    for shell, name in SCRIPT_FILES.items():
        assert (REPO / "completions" / name).read_text() == completion_script(shell)


def test_start_up_stays_light():
    """The new modules load nothing heavy for --version and profile list."""
    for args in (["--version"], ["profile", "list"]):
        out = subprocess.run([sys.executable, "-X", "importtime", "-m", "deltoctl", *args],
                             capture_output=True, text=True, check=True)
        imported = {line.rsplit("|", 1)[-1].strip() for line in out.stderr.splitlines()}
        assert not {"logging", "deltoctl.trace", "deltoctl.suggest", "rich"} & imported


def test_profile_show_suggests_the_nearest_part(cli):
    result = cli("profile", "show", "dg-5f-right", "rj_dg_2_x")
    assert result.exit_code == 2
    assert "did you mean" in result.stderr and "rj_dg_2_1" in result.stderr
