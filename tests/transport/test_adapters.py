"""``deltoctl ports``, ``usb:`` and by-id targets, and doctor's adapter checks and fixes, on a
computer's adapters laid out as the kernel and udev lay them out (adapter_tree), each serial
node a pseudo-terminal — a Dynamixel bus emulator's where a verb talks to the servos."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import jsonschema
import pytest

from deltoctl.schemas_lookup import schema_file
from deltoctl.transport.adapters import ROOT_ENV
from tests.transport.adapter_tree import CANDLE, CH340, CH343, U2D2, U2D2_B, Tree, Usb

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def tree(tmp_path, monkeypatch):
    laid = Tree(tmp_path / "root")
    laid.root.mkdir()
    monkeypatch.setenv(ROOT_ENV, str(laid.root))
    yield laid
    laid.close()


@pytest.fixture
def koch_bus():
    """The koch-arm's six servos on an emulated bus (a pseudo-terminal); ``latency`` holds each
    reply as an FTDI adapter's latency timer does."""
    from deltoctl.families.dynamixel.emulator import DynamixelBus, DynamixelPtyServer, Servo
    from deltoctl.families.dynamixel.emulator import _model_of as model_of
    from deltoctl.families.dynamixel.ros2_control import servo_ids
    from deltoctl.profile.catalog import load_profile

    profile = load_profile("koch-arm")
    servers = []

    def serve(latency: float = 0.0, missing: frozenset[int] = frozenset()):
        hw = profile.hardware[0]
        bus = DynamixelBus([Servo(i, model=model_of(hw, j))
                            for i, j in servo_ids(profile, hw).items()])
        bus.faults.missing |= missing
        servers.append(DynamixelPtyServer(bus, latency=latency).start())
        return servers[-1].port

    yield serve
    for server in servers:
        server.close()


def _doc(result) -> dict:
    return json.loads(result.stdout)["result"]


def _checks(result, name: str) -> list[dict]:
    return [c for c in _doc(result)["checks"] if c["check"] == name]


# -- deltoctl ports ---------------------------------------------------------------------------

def test_ports_lists_each_adapter_as_the_kernel_lays_it_out(cli, tree):
    u2d2 = tree.serial("ttyUSB0", U2D2, latency_ms=16)
    ch343 = tree.serial("ttyACM0", CH343)
    tree.serial("ttyUSB1", CH340)
    tree.platform_uart("ttyS0")
    tree.platform_uart("ttySC0", driver="sc16is7xx", device="spi0.0")
    tree.can("can0", up=False, usb=CANDLE)
    tree.i2c(1, "bcm2835 (i2c@7e804000)")
    result = cli("ports", "--json")
    assert result.exit_code == 0, result.output
    jsonschema.validate(json.loads(result.stdout), json.loads(schema_file("ports").read_text()))
    found = _doc(result)
    serial = {a["name"]: a for a in found["serial"]}
    # the 8250 UART is no adapter; the SC16IS752 on SPI (the MH5's buses) is one
    assert sorted(serial) == ["ttyACM0", "ttySC0", "ttyUSB0", "ttyUSB1"]
    assert serial["ttySC0"]["driver"] == "sc16is7xx" and serial["ttySC0"]["usb"] is None
    a = serial["ttyUSB0"]
    assert (a["vid"], a["pid"], a["serial"], a["driver"]) == ("0403", "6014", "FT6Z5XYZ",
                                                              "ftdi_sio")
    assert a["known"] == "FTDI FT232H (ROBOTIS U2D2)" and a["latency_timer_ms"] == 16
    assert a["stable"] == u2d2 and a["usb"] == "usb:0403:6014:FT6Z5XYZ"
    assert a["by_path"] and a["access"] and a["holders"] == []
    b = serial["ttyACM0"]
    assert b["driver"] == "cdc_acm" and b["stable"] == ch343
    assert b["refused_bauds"] == [128000, 250000] and b["latency_timer_ms"] is None
    assert serial["ttyUSB1"]["driver"] == "ch341" and serial["ttyUSB1"]["usb"] == "usb:1a86:7523"
    (can,) = found["can"]
    assert (can["name"], can["up"], can["driver"], can["vid"]) == ("can0", False, "gs_usb", "1d50")
    (i2c,) = found["i2c"]
    assert i2c["adapter"] == "bcm2835 (i2c@7e804000)" and i2c["present"]

    text = cli("ports").stdout
    assert f"stable     {u2d2}   or usb:0403:6014:FT6Z5XYZ" in text
    assert "latency    16 ms   (a sync loop needs 1 ms" in text
    assert "refuses 128000, 250000" in text and "can0  CAN  1d50:606f" in text


def test_ports_names_the_process_holding_an_adapter(cli, tree):
    by_id = tree.serial("ttyUSB0", U2D2, latency_ms=1)
    holder = subprocess.Popen([sys.executable, "-c", "import sys, time\n"
                               f"f = open({by_id!r}, 'rb', buffering=0)\n"
                               "print('open', flush=True); time.sleep(30)"],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "open"
        (a,) = _doc(cli("ports", "--json"))["serial"]
        assert a["holders"] == [f"{holder.pid} (python{sys.version_info[0]})"] or \
            a["holders"][0].startswith(f"{holder.pid} (")
    finally:
        holder.kill()
        holder.wait()


def test_ports_when_there_is_nothing(cli, tree):
    result = cli("ports")
    assert result.exit_code == 0
    assert result.stdout.strip() == "no serial adapter, CAN interface or I2C adapter"


def test_ports_on_this_computer_runs_as_a_command():
    """``python -m deltoctl ports`` on the real /sys (whatever it holds) exits 0."""
    env = {k: v for k, v in os.environ.items() if k != ROOT_ENV}
    done = subprocess.run([sys.executable, "-m", "deltoctl", "ports", "--json"], env=env,
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert set(json.loads(done.stdout)["result"]) == {"serial", "can", "i2c"}


# -- stable targets ---------------------------------------------------------------------------

def test_a_usb_target_reaches_the_servos_behind_its_by_id_link(cli, tree, koch_bus):
    tree.serial("ttyUSB0", U2D2, latency_ms=1, node=koch_bus())
    for target in ("dxl=usb:0403:6014:FT6Z5XYZ?baud=1000000", "usb:0403:6014?baud=1000000"):
        result = cli("-p", "koch-arm", "-t", target, "identify", "--json")
        assert result.exit_code == 0, result.output
        block = json.loads(result.stdout)["blocks"][0]
        assert block["target"] == target.removeprefix("dxl=")
        assert len(block["identity"]["servos"]) == 6


def test_a_by_id_target_reaches_the_servos(cli, tree, koch_bus):
    by_id = tree.serial("ttyUSB0", U2D2, latency_ms=1, node=koch_bus())
    result = cli("-p", "koch-arm", "-t", f"dxl=serial://{by_id}?baud=1000000", "identify")
    assert result.exit_code == 0, result.output


def test_a_usb_target_that_matches_no_adapter_lists_those_there_are(cli, tree):
    tree.serial("ttyUSB0", U2D2, latency_ms=1)
    result = cli("-p", "koch-arm", "-t", "dxl=usb:0403:6001?baud=1000000", "identify")
    assert result.exit_code == 4
    assert "no serial adapter matches usb:0403:6001" in result.stderr
    assert "usb:0403:6014:FT6Z5XYZ" in result.stderr and "deltoctl ports" in result.stderr


def test_a_usb_target_that_matches_two_adapters_is_a_usage_error(cli, tree):
    tree.serial("ttyUSB0", U2D2, latency_ms=1)
    tree.serial("ttyUSB1", U2D2_B, latency_ms=1)
    result = cli("-p", "koch-arm", "-t", "dxl=usb:0403:6014?baud=1000000", "identify")
    assert result.exit_code == 2
    assert "matches 2 adapters" in result.stderr
    assert "usb:0403:6014:FT6Z5XYZ" in result.stderr and "usb:0403:6014:FT7ABCDE" in result.stderr


@pytest.mark.parametrize("bad", ["usb:403:6014", "usb:0403", "usb:0403:60g4", "usb:0403:6014:"])
def test_a_malformed_usb_target_is_named(cli, tree, bad):
    result = cli("-p", "koch-arm", "-t", f"dxl={bad}?baud=1000000", "identify")
    assert result.exit_code == 2
    assert "expected usb:VID:PID[:SERIAL]" in result.stderr and "Traceback" not in result.output


def test_a_profile_may_name_its_adapter_by_usb_id(tmp_path, cli, tree, koch_bus):
    tree.serial("ttyUSB0", U2D2, latency_ms=1, node=koch_bus())
    text = (REPO / "profiles" / "koch-arm.yaml").read_text()
    mine = tmp_path / "koch.yaml"
    mine.write_text(text.replace("serial:///dev/ttyUSB0?baud=1000000",
                                 "usb:0403:6014:FT6Z5XYZ?baud=1000000"))
    assert cli("profile", "validate", str(mine)).exit_code == 0
    assert cli("-p", str(mine), "identify").exit_code == 0


def test_a_baud_scan_leaves_out_the_rates_its_adapter_cannot_set(cli, tree, koch_bus):
    ft232r = Usb("1-7", "0403", "6001", "FTDI", "FT232R USB UART", "A50285BI", "ftdi_sio")
    tree.serial("ttyUSB0", ft232r, latency_ms=1, node=koch_bus(missing=frozenset({6})))
    result = cli("-p", "koch-arm", "-t", "dxl=usb:0403:6001?baud=1000000", "detect", "--json")
    assert result.exit_code == 1, result.output  # the gripper's servo does not answer
    block = json.loads(result.stdout)["blocks"][0]
    unscanned = block["details"]["unscanned"]
    assert sorted(map(int, unscanned)) == [4_000_000, 4_500_000]  # an FT232R's limit: 3 Mbaud
    assert "ftdi_sio on this chip sets at most 3000000 baud" in unscanned["4000000"]
    assert "not scanned: 4000000" in block["summary"]


# -- doctor: each check failing, and its fix --------------------------------------------------

def test_doctor_fails_a_16_ms_latency_timer_and_its_fix_clears_it(cli, tree):
    by_id = tree.serial("ttyUSB0", U2D2, latency_ms=16)
    args = ("-p", "koch-arm", "-t", f"dxl=serial://{by_id}?baud=1000000", "doctor", "--json")
    result = cli(*args)
    assert result.exit_code == 1, result.output
    (latency,) = _checks(result, "latency timer")
    assert not latency["ok"] and "16 ms" in latency["detail"] and "~62 Hz" in latency["detail"]
    timer = tree.root / "sys/bus/usb-serial/devices/ttyUSB0/latency_timer"
    assert latency["fix"].startswith(f"echo 1 | sudo tee {timer}")
    subprocess.run(["sh", "-c", latency["fix"].split("|")[0]], stdout=timer.open("w"),
                   check=True)  # the fix, without sudo (this is a laid-out tree)
    result = cli(*args)
    assert result.exit_code == 0, result.output
    assert _checks(result, "latency timer")[0]["ok"]


def test_doctor_without_a_profile_reports_the_timer_and_checks_each_adapter(cli, tree):
    tree.serial("ttyUSB0", U2D2, latency_ms=16)
    result = cli("doctor", "--json")
    (latency,) = _checks(result, "latency timer")
    assert latency["ok"] and "doctor --udev-rule" in latency["detail"]
    assert {c["subject"] for c in _doc(result)["checks"]} >= {"ttyUSB0"}


def test_doctor_suggests_the_stable_name_for_a_ttyusb_target(cli, tree):
    by_id = tree.serial("ttyUSB0", U2D2, latency_ms=1)
    node = tree.root / "dev/ttyUSB0"
    result = cli("-p", "koch-arm", "-t", f"dxl=serial://{node}?baud=1000000", "doctor", "--json")
    assert result.exit_code == 3, result.output  # works today, may not after a reboot
    (stable,) = _checks(result, "stable name")
    assert not stable["ok"] and "plug-in order" in stable["detail"]
    assert f"serial://{by_id}?baud=1000000" in stable["fix"]
    assert "usb:0403:6014:FT6Z5XYZ?baud=1000000" in stable["fix"]
    result = cli("-p", "koch-arm", "-t", f"dxl=serial://{by_id}?baud=1000000", "doctor")
    assert result.exit_code == 0, result.output


def test_doctor_names_a_rate_a_cdc_acm_adapter_refuses(cli, tree):
    by_id = tree.serial("ttyACM0", CH343)
    result = cli("-t", f"serial://{by_id}?baud=250000", "doctor", "--json")
    assert result.exit_code == 1
    (baud,) = _checks(result, "baud")
    assert not baud["ok"] and "cdc_acm adapters refuse 250000 baud" in baud["detail"]
    result = cli("-t", f"serial://{by_id}?baud=1000000", "doctor", "--json")
    assert _checks(result, "baud")[0]["ok"] and result.exit_code == 0


def test_doctor_prints_a_udev_rule_that_names_the_adapter_and_sets_its_timer(cli, tree):
    tree.serial("ttyUSB0", U2D2, latency_ms=16)
    tree.serial("ttyACM0", CH343)
    result = cli("-p", "koch-arm", "-t", "dxl=usb:0403:6014?baud=1000000", "doctor",
                 "--udev-rule")
    assert result.exit_code == 0, result.output
    rule = result.stdout
    assert ('SUBSYSTEM=="tty", ATTRS{idVendor}=="0403", ATTRS{idProduct}=="6014", '
            'ATTRS{serial}=="FT6Z5XYZ", SYMLINK+="koch-arm-dxl"') in rule
    assert 'DRIVER=="ftdi_sio"' in rule and 'ATTR{latency_timer}="1"' in rule
    assert "55d3" not in rule  # not on the profile's bus
    every = cli("doctor", "--udev-rule").stdout  # without a profile: every USB adapter
    assert 'SYMLINK+="deltoctl-FT6Z5XYZ"' in every and 'SYMLINK+="deltoctl-5A7C121362"' in every
    assert every.count("latency_timer") == 1  # the CH343 has none


def test_doctor_installs_the_udev_rule_as_root_and_refuses_otherwise(cli, tree, monkeypatch):
    tree.serial("ttyUSB0", U2D2, latency_ms=16)
    monkeypatch.setattr(os, "geteuid", lambda: 1000)
    result = cli("-t", "usb:0403:6014?baud=1000000", "doctor", "--write-udev-rule")
    assert result.exit_code == 5
    assert "needs root" in result.stderr and "sudo deltoctl doctor --write-udev-rule" in \
        result.stderr
    rules = tree.root / "etc/udev/rules.d/99-deltoctl.rules"
    assert not rules.exists()
    monkeypatch.setattr(os, "geteuid", lambda: 0)
    result = cli("doctor", "--write-udev-rule")
    assert result.exit_code == 0, result.output
    assert f"wrote {rules}" in result.stderr
    assert 'ATTR{latency_timer}="1"' in rules.read_text()


def test_doctor_udev_rule_without_an_adapter_says_so(cli, tree):
    result = cli("doctor", "--udev-rule")
    assert result.exit_code == 4 and "no USB serial adapter" in result.stderr


# -- a loop's achieved rate against the latency timer -----------------------------------------

def test_stream_names_the_latency_timer_that_held_its_loop_back(cli, tree, koch_bus):
    tree.serial("ttyUSB0", U2D2, latency_ms=16, node=koch_bus(latency=0.016))
    result = cli("-p", "koch-arm", "-t", "dxl=usb:0403:6014?baud=1000000", "stream",
                 "--rate", "200", "--duration", "0.5", "--json")
    assert result.exit_code == 3, result.output
    assert "latency timer of" in result.stderr and "(16 ms)" in result.stderr
    assert "allows at most ~62 Hz" in result.stderr


def test_stream_blames_no_latency_timer_set_to_1_ms(cli, tree, koch_bus):
    tree.serial("ttyUSB0", U2D2, latency_ms=1, node=koch_bus())
    result = cli("-p", "koch-arm", "-t", "dxl=usb:0403:6014?baud=1000000", "stream",
                 "--rate", "200", "--duration", "0.3", "--json")
    assert "latency timer" not in result.stderr, result.stderr


def test_profile_show_and_validate_suggest_the_stable_name_of_a_ttyusb_bus(cli, tree):
    by_id = tree.serial("ttyUSB0", U2D2, latency_ms=1)
    shown = cli("profile", "show", "koch-arm").stdout
    assert "note: /dev/ttyUSB0 is named in plug-in order" in shown
    assert f"serial://{by_id}?baud=1000000 or usb:0403:6014:FT6Z5XYZ" in shown
    text = (REPO / "profiles" / "koch-arm.yaml").read_text()
    mine = tree.root / "koch.yaml"
    mine.write_text(text.replace("/dev/ttyUSB0", str(tree.root / "dev/ttyUSB0")))
    result = cli("profile", "validate", str(mine))
    assert result.exit_code == 0  # advice, not a warning
    assert f"serial://{by_id}?baud=1000000 or usb:0403:6014:FT6Z5XYZ?baud=1000000" in \
        result.stderr
    notes = json.loads(cli("profile", "validate", str(mine), "--json").stdout)["result"]
    assert "plug-in order" in notes[0]["notes"][0]
    (tree.root / "sys/class/tty/ttyUSB0").unlink()  # unplugged: what would name one
    shown = cli("profile", "show", "koch-arm").stdout
    assert "its /dev/serial/by-id/ link or usb:VID:PID[:SERIAL] (deltoctl ports" in shown


HOSTILE = Usb("1-7", "1234", "5678", "ACME", 'Cable\nACTION=="add", RUN+="/bin/sh -c id"',
              'S1\nRUN+="/bin/touch /tmp/owned"', "ch341")


def test_the_udev_rule_keeps_only_safe_characters_of_what_the_device_says(cli, tree):
    """An adapter's product and serial come from the device: a newline in them would start a
    rule line of its own (RUN+=…), comments included."""
    tree.serial("ttyUSB0", HOSTILE)
    result = cli("doctor", "--udev-rule")
    assert result.exit_code == 0, result.output
    for line in result.stdout.splitlines():
        assert line.startswith(("#", 'SUBSYSTEM=="tty"', 'ACTION=="add", SUBSYSTEM=="usb-serial"'))
    assert "RUN+=" not in result.stdout and '"/bin/sh' not in result.stdout
    assert 'ATTRS{idVendor}=="1234", ATTRS{idProduct}=="5678", SYMLINK+=' in result.stdout


def test_ports_shows_no_control_character_a_device_sends(cli, tree):
    """Manufacturer, product and serial come from the device: an escape sequence in them
    does not reach the terminal (in --json they are JSON strings)."""
    tree.serial("ttyUSB0", Usb("1-8", "1234", "5678", "\x1b]0;owned\x07ACME",
                               "Cable\x1b[2J", "S\x1b[31m1", "ch341"))
    result = cli("ports")
    assert result.exit_code == 0, result.output
    assert "\x1b" not in result.stdout and "\x07" not in result.stdout
    assert "?]0;owned?ACME" in result.stdout and "Cable?[2J" in result.stdout
    (a,) = _doc(cli("ports", "--json"))["serial"]
    assert a["product"] == "Cable\x1b[2J"
