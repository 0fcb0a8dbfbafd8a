"""The verb table (deltoctl.verbs): it declares every command of the CLI's click tree, the
fleet's sets and the help examples come from it, and a command it does not declare counts as
one that moves the robot (fail-closed), also when the fleet agent resolves a command line."""

from __future__ import annotations

import subprocess
import sys

import pytest
import typer
import typer.main

from deltoctl import verbs
from deltoctl.cli import main as cli_main
from deltoctl.cmdline import GLOBAL_OPTIONS
from deltoctl.errors import InvalidInput
from deltoctl.fleet import ACTUATING, MOTION, NOT_REMOTE
from deltoctl.fleet.argv import check_argv
from deltoctl.verb_help import EXAMPLES


def _click_tree() -> dict[str, object]:
    """Every command path of the CLI (every verb loaded) → its click command."""
    root = typer.main.get_command(cli_main.app)
    ctx = root.make_context("deltoctl", [], resilient_parsing=True)
    paths: dict[str, object] = {}

    def visit(command, prefix: str, context) -> None:
        for name in command.list_commands(context):
            sub = command.get_command(context, name)
            path = f"{prefix} {name}".strip()
            paths[path] = sub
            if hasattr(sub, "list_commands"):
                visit(sub, path, sub.make_context(name, [], parent=context,
                                                  resilient_parsing=True))

    visit(root, "", ctx)
    return paths


def test_the_table_declares_every_command_of_the_cli_and_nothing_else():
    tree = _click_tree()
    undeclared = [p for p in tree if verbs.lookup(p) is None]
    assert not undeclared, f"declare these in deltoctl/verbs.py: {undeclared}"
    declared = [p for p, _ in verbs.walk()]
    assert sorted(declared) == sorted(tree)
    assert {v.effect for _, v in verbs.walk()} <= {verbs.READS, verbs.ACTUATES, verbs.MOVES}
    assert all(v.example.startswith("deltoctl ") for v in verbs.TABLE.values())


def test_the_fleet_sets_and_help_examples_come_from_the_table():
    assert MOTION.declared() == {"home", "jog", "replay", "report", "fleet run"}
    assert ACTUATING.declared() == MOTION.declared() | {
        "gpio set", "torque", "reboot", "register set", "config restore", "calibrate ft",
        "calibrate imu", "calibrate servos", "calibrate joints", "doctor", "setup"}
    assert sorted(NOT_REMOTE) == ["agent", "bench", "completion", "fleet", "sim"]
    assert EXAMPLES["gpio set"] == verbs.lookup("gpio set").example  # type: ignore[union-attr]
    assert list(cli_main.VERBS) == list(verbs.TABLE)
    assert "gpio get" not in ACTUATING and "stream" not in MOTION


def test_global_options_are_the_root_options():
    root = typer.main.get_command(cli_main.app)
    taken = {o: not (p.is_flag or p.count) for p in root.params
             if p.name not in ("version", "install_completion", "show_completion")
             for o in p.opts}
    assert taken == GLOBAL_OPTIONS


def test_an_undeclared_verb_or_sub_command_counts_as_one_that_moves():
    for path in ("spin", "gpio toggle", "config erase", verbs.UNRESOLVED):
        assert verbs.effect(path) == verbs.MOVES
        assert path in MOTION and path in ACTUATING
    assert 42 not in MOTION


@pytest.fixture
def undeclared_commands():
    """A verb ``spin`` and a sub-command ``gpio toggle`` added to the CLI's command tree
    without an entry in the table (as a new verb forgotten there would be)."""
    extra = typer.Typer()
    extra.command("spin")(lambda: None)
    extra.command("toggle")(lambda: None)
    commands = typer.main.get_group(extra).commands
    root = cli_main._command_tree()
    cli_main.command_path(["gpio", "get"])  # loads gpio in the tree
    gpio = root.commands["gpio"]
    root.commands["spin"] = commands["spin"]
    gpio.commands["toggle"] = commands["toggle"]
    yield
    del root.commands["spin"], gpio.commands["toggle"]


def test_the_agent_judges_an_undeclared_command_as_motion(undeclared_commands):
    assert check_argv(["spin", "--json"]) == "spin"
    assert check_argv(["-y", "gpio", "--", "toggle", "output_2"]) == "gpio toggle"
    assert "spin" in MOTION and "gpio toggle" in ACTUATING


@pytest.mark.parametrize("argv, path", [
    (["-y", "gpio", "--", "set", "output_2", "on"], "gpio set"),
    (["-y", "--", "gpio", "set", "output_2", "on"], "gpio set"),
    (["gpio", "--hardware", "h", "--", "set", "output_2", "on"], "gpio set"),
    (["register", "--", "set", "head_y", "return_delay_time", "0"], "register set"),
    (["config", "--", "restore", "mh5.yaml"], "config restore"),
    (["calibrate", "--", "ft"], "calibrate ft"),
    (["jog", "j1", "-5deg", "--json", "-y"], "jog"),
    (["identify", "--json"], "identify"),
    (["gpio", "-h"], "gpio"),
    (["help", "gpio", "set"], "help"),
])
def test_a_command_line_is_judged_by_the_clis_own_resolution(argv, path):
    assert check_argv(argv) == path


@pytest.mark.parametrize("argv, moves", [
    (["report"], False),
    (["report", "-o", "acceptance.html", "--json"], False),
    (["report", "--yes"], True),
    (["report", "-y", "--record", "1"], True),
    (["-y", "report"], True),
    (["--yes", "report"], True),
    (["-yq", "report"], True),
    (["-q", "report", "-vy"], True),
])
def test_an_option_raises_a_commands_effect_as_the_cli_parses_it(argv, moves):
    """`report` reads (its tares, self-tests and motion checks need --yes); with the global
    --yes/-y, before or after the verb, in a cluster too, it tares, self-tests and moves the
    joints."""
    command = check_argv(argv)
    assert command == "report"
    assert verbs.effect(command) == (verbs.MOVES if moves else verbs.READS)
    assert (command in MOTION) is moves and (command in ACTUATING) is moves
    assert "report" not in MOTION  # the path alone: the table's own effect


def test_the_effect_of_an_option_is_in_the_table_and_in_help():
    report = verbs.lookup("report")
    assert report is not None and report.effect == verbs.READS
    assert report.effects() == {verbs.READS, verbs.MOVES}
    assert verbs.describe("report") == "reads the robot; moves with --yes/-y"
    assert verbs.describe("jog") == "moves the robot"
    assert verbs.effect(verbs.Command("report", {"-o"})) == verbs.READS
    assert verbs.effect(verbs.Command("doctor", {"--write-udev-rule"})) == verbs.ACTUATES
    assert verbs.effect(verbs.Command("doctor", {"--udev-rule"})) == verbs.READS
    assert verbs.effect(verbs.Command("spin", {"--yes"})) == verbs.MOVES  # undeclared


def test_the_callers_confirmation_follows_the_parse():
    """A fleet run asks before motion only for a line that moves: `report` reads."""
    from deltoctl.fleet.fleet_run import confirmed

    asked: list[bool] = []

    def ask() -> bool:
        asked.append(True)
        return True

    assert confirmed([["report", "--json"]], ask) == [["report", "--json"]] and not asked
    lines = [["report", "-y"], ["identify"]]
    assert confirmed(lines, ask) == [["--yes", "report", "-y"], ["identify"]] and asked


def test_a_verbs_help_says_its_effect(cli):
    out = cli("report", "--help").stdout
    assert ("Effect: reads the robot; moves with --yes/-y."
            in " ".join(out.split()))


@pytest.mark.parametrize("argv, message", [
    (["gpio", "sett", "output_2", "on"], "no command 'gpio sett'"),
    (["--json"], "no verb given"),
    (["--bogus", "gpio", "set", "output_2", "on"], "no verb given"),
    (["sim", "serve", "mh5"], "runs on this computer"),
    (["--install-completion"], "writes outside"),
    (["identify", "--show-completion"], "writes outside"),
    (["-yp", "mh5", "identify"], "not taken remotely"),
])
def test_what_the_agent_does_not_run(argv, message):
    with pytest.raises(InvalidInput, match=message):
        check_argv(argv)


def test_without_the_cli_to_resolve_it_every_command_counts_as_motion():
    code = ("from deltoctl.fleet import MOTION; from deltoctl.fleet.argv import check_argv; "
            "import sys; verb = check_argv(['gpio', 'get']); "
            "print(verb, verb in MOTION, 'typer' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split()
    assert out == [verbs.UNRESOLVED, "True", "False"]
