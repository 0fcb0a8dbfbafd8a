"""Confirmation follows what a command does, by the verb table: every command that actuates or
moves asks on a terminal, saying what it is about to do, and needs --yes without one; a no
leaves the device as it was (exit 5), Ctrl-C at the question is exit 130."""

from __future__ import annotations

import json
import os
import shutil
import sys

import pytest

from deltoctl import verbs
from deltoctl.cli import confirm
from deltoctl.families.delto.emulator import DeltoServer, firmware_for_profile
from deltoctl.profile.catalog import load_profile
from tests.conftest import eventually, mh5_targets

DELTOCTL = shutil.which("deltoctl", path=os.path.dirname(sys.executable)) or "deltoctl"


@pytest.fixture
def hand():
    server = DeltoServer(firmware_for_profile(load_profile("dg-5f-right"))).start()
    yield server
    server.close()


def _spawn(*args: str):
    pexpect = pytest.importorskip("pexpect")
    return pexpect, pexpect.spawn(DELTOCTL, list(args), encoding="utf-8", timeout=60,
                                  env=dict(os.environ, TERM="dumb"))


def _answer(args: list[str], prompt: str, answer: str | None) -> tuple[int, str]:
    """Run on a terminal (a pty), wait for the question, answer it (None: Ctrl-C)."""
    pexpect, child = _spawn(*args)
    try:
        child.expect_exact(prompt)
        said = child.before + child.after
        if answer is None:
            child.sendintr()
        else:
            child.sendline(answer)
        child.expect(pexpect.EOF)
    finally:
        child.close()
    return child.exitstatus, said + child.before


def _torque_on(cli, mh5_buses):
    targets = mh5_targets(mh5_buses)
    assert cli("-p", "mh5", *targets, "--hardware", "upper_body", "torque", "on",
               "--yes").exit_code == 0
    servos = mh5_buses["upper_body"].bus.servos.values()
    assert eventually(lambda: all(s.get("Torque Enable") == 1 for s in servos))
    return targets, servos


# -- on a terminal ------------------------------------------------------------------------------

def test_torque_off_asks_and_a_no_leaves_the_torque_on(cli, mh5_buses):
    targets, servos = _torque_on(cli, mh5_buses)
    code, out = _answer(["-p", "mh5", *targets, "--hardware", "upper_body", "torque", "off"],
                        "go limp, and an arm under gravity falls. Go on? [y/N]", "n")
    assert code == 5 and "not confirmed" in out
    assert "switch torque off for 10 joint(s)" in out.replace("\r\n", " ")
    assert all(s.get("Torque Enable") == 1 for s in servos)


def test_gpio_set_asks_what_it_sets_and_does_it_on_yes(hand):
    target = ["-p", "dg-5f-right", "-t", hand.endpoint, "gpio", "set", "output_2", "on"]
    code, out = _answer(target, "set gpio/output_2 of DG5FRightHardware to on. Go on? [y/N]",
                        "n")
    assert code == 5 and hand.firmware.gpio_out == [False, False, False]
    code, out = _answer(target, "Go on? [y/N]", "y")
    assert code == 0, out
    assert hand.firmware.gpio_out == [False, True, False]


def test_register_set_asks_with_the_item_value_and_servo_id(cli, mh5_buses):
    targets = mh5_targets(mh5_buses)
    servo = mh5_buses["upper_body"].bus.servos[52]
    before = servo.get("Return Delay Time")
    code, _ = _answer(["-p", "mh5", *targets, "register", "set", "head_y", "return_delay_time",
                       "7"], "write return_delay_time = 7 to head_y (ID 52). Go on? [y/N]", "")
    assert code == 5 and servo.get("Return Delay Time") == before


def test_ctrl_c_at_the_question_is_exit_130(hand):
    code, out = _answer(["-p", "dg-5f-right", "-t", hand.endpoint, "gpio", "set", "output_1",
                         "on"], "Go on? [y/N]", None)
    assert code == 130 and "interrupted" in out
    assert hand.firmware.gpio_out == [False, False, False]


# -- in a script --------------------------------------------------------------------------------

def test_without_a_terminal_torque_gpio_and_registers_need_yes(cli, mh5_buses, hand):
    targets, servos = _torque_on(cli, mh5_buses)
    mh5 = ["-p", "mh5", *targets, "--hardware", "upper_body"]
    for args in (["torque", "off", "all"], ["register", "set", "head_y", "led", "1"]):
        refused = cli(*mh5, *args)
        assert refused.exit_code == 5, refused.stderr
        assert "needs confirmation" in refused.stderr and "--yes" in refused.stderr
    assert all(s.get("Torque Enable") == 1 for s in servos)
    assert mh5_buses["upper_body"].bus.servos[52].get("LED") == 0
    assert cli(*mh5, "register", "set", "head_y", "led", "1", "--yes").exit_code == 0
    assert mh5_buses["upper_body"].bus.servos[52].get("LED") == 1
    assert cli(*mh5, "torque", "off", "all", "-y").exit_code == 0
    assert eventually(lambda: all(s.get("Torque Enable") == 0 for s in servos))

    delto = ["-p", "dg-5f-right", "-t", hand.endpoint, "gpio", "set", "output_2", "on"]
    refused = cli(*delto, "--json")
    error = json.loads(refused.stderr)["error"]
    assert refused.exit_code == 5 and "--yes" in error["message"] + error["hint"]
    assert hand.firmware.gpio_out == [False, False, False]
    assert cli(*delto, "--yes").exit_code == 0
    assert hand.firmware.gpio_out == [False, True, False]


# -- every command that actuates or moves asks (fail-closed) ------------------------------------

def _restore_case(cli, tmp_path) -> list[str]:
    snap = tmp_path / "mh5.yaml"
    assert cli("-p", "mh5", "--sim", "--hardware", "upper_body", "config", "snapshot", "-o",
               str(snap)).exit_code == 0
    text = snap.read_text()
    # one servo's LED on in the snapshot: a fresh simulator differs, the restore writes it
    at = text.index("LED:")
    at = text.index("value: 0", at)
    snap.write_text(text[:at] + "value: 1" + text[at + len("value: 0"):])
    return ["-p", "mh5", "--sim", "--hardware", "upper_body", "config", "restore", str(snap)]


def _replay_case(cli, tmp_path) -> list[str]:
    out = tmp_path / "jog.mcap"
    assert cli("-p", "rrbot-gpio", "--sim", "jog", "joint1", "--to", "0.1", "--record",
               str(out), "-y").exit_code == 0
    return ["replay", str(out), "--device", "--sim"]


# each command path that actuates or moves → a command line that does it (no --yes)
CASES = {
    "config restore": _restore_case,
    "home": lambda cli, tmp: ["-p", "bioscara-arm", "--sim", "home"],
    "jog": lambda cli, tmp: ["-p", "rrbot-gpio", "--sim", "jog", "joint1", "--to", "0.1"],
    "calibrate ft": lambda cli, tmp: ["-p", "dg-5f-right", "--sim", "calibrate", "ft", "-o",
                                      str(tmp)],
    "calibrate imu": lambda cli, tmp: ["-p", "mh5", "--sim", "--hardware", "i2c", "calibrate",
                                       "imu", "-o", str(tmp)],
    "calibrate servos": lambda cli, tmp: ["-p", "so101-follower", "--sim", "calibrate",
                                          "servos", "--half-turn", "-o", str(tmp / "c.json")],
    "calibrate joints": lambda cli, tmp: ["-p", "koch-arm", "--sim", "calibrate", "joints",
                                          "--range-seconds", "1"],
    "gpio set": lambda cli, tmp: ["-p", "rrbot-gpio", "--sim", "gpio", "set",
                                  "flange_vacuum/vacuum", "on"],
    "replay": _replay_case,
    "torque": lambda cli, tmp: ["-p", "mh5", "--sim", "--hardware", "upper_body", "torque",
                                "off", "head_y"],
    "reboot": lambda cli, tmp: ["-p", "mh5", "--sim", "--hardware", "upper_body", "reboot",
                                "head_y"],
    "register set": lambda cli, tmp: ["-p", "mh5", "--sim", "--hardware", "upper_body",
                                      "register", "set", "head_y", "led", "1"],
    "setup": lambda cli, tmp: ["-p", "koch-arm", "--sim", "--sim-fresh", "--sim-option",
                               "factory_new", "setup", "elbow_flex", "--wait", "0.05"],
}
# the robots' agents run each line of a fleet run, and ask by this rule there (and the
# caller once for them all: tests/cli/test_verbs.py); doctor actuates the host, not the robot,
# and only with --write-udev-rule, which is itself the word (as root: tests/transport)
ELSEWHERE = {"fleet run", "doctor"}


def _confirmed_by_yes_alone(entry: verbs.Verb) -> bool:
    """A command that reads, and moves only with --yes: the option that confirms it."""
    return entry.effect == verbs.READS and all(
        e == verbs.READS or set(spellings) <= set(verbs.YES)
        for spellings, e in entry.when.items())


def test_every_command_that_actuates_or_moves_has_a_case():
    acting = {path for path, entry in verbs.walk()
              if entry.effects() - {verbs.READS} and not _confirmed_by_yes_alone(entry)}
    assert acting == set(CASES) | ELSEWHERE


@pytest.mark.parametrize("path", sorted(CASES))
def test_every_command_that_actuates_or_moves_asks(cli, tmp_path, monkeypatch, path):
    args = CASES[path](cli, tmp_path)
    refused = cli(*args)
    assert refused.exit_code == 5, refused.output
    assert "needs confirmation" in refused.stderr and "--yes" in refused.stderr
    monkeypatch.setattr(confirm, "on_terminal", lambda: True)
    answered = cli(*args, input="n\n")
    assert answered.exit_code == 5, answered.output
    assert "[y/N]: " in answered.stderr and "not confirmed" in answered.stderr
    question = answered.stderr.split("[y/N]")[0]
    assert len(question) > 30  # it says what will happen


def test_a_command_that_reads_never_asks(cli, monkeypatch):
    monkeypatch.setattr(confirm, "on_terminal", lambda: True)
    result = cli("-p", "rrbot-gpio", "--sim", "gpio", "get", input="")
    assert result.exit_code == 0 and "[y/N]" not in result.stderr
