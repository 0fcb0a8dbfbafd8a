"""deltoctl setup sets the items a profile pins: a factory-new OpenMANIPULATOR-X (five
XM430-W350, IDs 11-15) walked on its simulator, its gripper's Operating Mode 5 and Goal Current
200 written once it answers at ID 15 and read back, dynamixel-sdk confirming them; a second
setup finds them set and writes nothing. A pinned value outside its item's documented range
(exit 2) or a pinned safety setting without its --allow (exit 5) is refused before anything is
written; params that are not items are the plugin's, never written."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from deltoctl.families.dynamixel.emulator import Servo
from deltoctl.schemas_lookup import schema_file

PROFILE = "open-manipulator-x"
ALLOW = ("--allow", "operating-mode")
WAIT = ("--wait", "0.05")  # s a probe waits: generous, a loaded machine answers late
GRIPPER = 15
OPERATING_MODE, GOAL_CURRENT = 11, 102  # addresses (XM430-W350's e-manual)


def _count_writes(monkeypatch):
    writes = []
    original = Servo.write

    def counted(self, address, data):
        writes.append((self.id, address, bytes(data)))
        return original(self, address, data)

    monkeypatch.setattr(Servo, "write", counted)
    return writes


def _doc(result):
    document = json.loads(result.stdout)
    jsonschema = pytest.importorskip("jsonschema")
    jsonschema.validate(document, json.loads(schema_file("setup").read_text()))
    return document["result"]


def _read_by_the_sdk(url: str) -> tuple[int, int]:
    """The gripper's Operating Mode and Goal Current, read by dynamixel-sdk at 1 Mbps."""
    sdk = pytest.importorskip("dynamixel_sdk")
    port, ph = sdk.PortHandler(url.split("?")[0].removeprefix("serial://")), \
        sdk.PacketHandler(2.0)
    assert port.openPort() and port.setBaudRate(1_000_000)
    port.setPacketTimeout = lambda _length: port.setPacketTimeoutMillis(500)
    try:
        mode, result, error = ph.read1ByteTxRx(port, GRIPPER, OPERATING_MODE)
        assert (result, error) == (sdk.COMM_SUCCESS, 0)
        current, result, error = ph.read2ByteTxRx(port, GRIPPER, GOAL_CURRENT)
        assert (result, error) == (sdk.COMM_SUCCESS, 0)
        return mode, current
    finally:
        port.closePort()


def test_a_factory_new_arm_gets_its_pinned_items_then_a_second_setup_writes_none(
        cli, monkeypatch):
    from deltoctl.app.setup import open_setup

    with open_setup(PROFILE, sim={"factory_new": True}, wait=0.05,
                    allow=["operating-mode"]) as run:
        plan = run.wanted_plan()
        assert [(s["joint"], s["item"], s["from"], s["to"]) for s in plan.steps] == [
            ("gripper", "Operating Mode", None, 5), ("gripper", "Goal Current", None, 200)]
        done = run.walk(lambda w, reply: None)
        items = [s for s in done.steps if s["action"] == "item"]
        assert [(s["item"], s["from"], s["to"], s["status"], s["verified"]) for s in items] \
            == [("Operating Mode", 3, 5, "set", True), ("Goal Current", 0, 200, "set", True)]
        assert all(r["verified"] for r in done.joints)
        run.controls.run("connect all")
        [target] = run.targets()
        assert _read_by_the_sdk(target.partition("=")[2]) == (5, 200)

        writes = _count_writes(monkeypatch)
        again = cli("-p", PROFILE, "-t", target, "--json", "setup", "--in-place", "--yes",
                    *ALLOW, *WAIT)
        assert again.exit_code == 0, again.output
        items = [s for s in _doc(again)["steps"] if s["action"] == "item"]
        assert [(s["item"], s["from"], s["status"]) for s in items] == [
            ("Operating Mode", 5, "already set"), ("Goal Current", 200, "already set")]
        assert writes == []


def test_the_dry_run_lists_the_pinned_items_and_writes_nothing(cli, monkeypatch):
    writes = _count_writes(monkeypatch)
    result = cli("-p", PROFILE, "--sim", "--sim-fresh", "--sim-option", "factory_new",
                 "--json", "setup", "--dry-run", *ALLOW, *WAIT)
    assert result.exit_code == 0, result.output
    items = [(s["joint"], s["action"], s["item"], s["to"]) for s in _doc(result)["steps"]]
    assert items == [("gripper", "item", "Operating Mode", 5),
                     ("gripper", "item", "Goal Current", 200)]
    assert writes == []


def _pinned(tmp_path: Path, old: str, new: str) -> str:
    from deltoctl.profile.catalog import resolve

    text = resolve(PROFILE).read_text()
    assert old in text
    path = tmp_path / f"{PROFILE}.yaml"
    path.write_text(text.replace(old, new))
    return str(path)


def test_a_pinned_value_outside_its_range_is_refused_before_any_write(cli, monkeypatch,
                                                                       tmp_path):
    writes = _count_writes(monkeypatch)
    profile = _pinned(tmp_path, "Operating Mode: 5", "Operating Mode: 17")
    result = cli("-p", profile, "--sim", "--sim-fresh", "--sim-option", "factory_new",
                 "setup", "--yes", *ALLOW, *WAIT)
    assert result.exit_code == 2, result.output
    assert "gripper: the profile pins Operating Mode 17" in result.stderr
    assert "0..16" in result.stderr
    assert writes == []


@pytest.mark.parametrize("joint", [(), ("gripper",)])
def test_a_pinned_safety_setting_needs_its_allow(cli, monkeypatch, joint):
    writes = _count_writes(monkeypatch)
    result = cli("-p", PROFILE, "--sim", "--sim-fresh", "--sim-option", "factory_new",
                 "setup", *joint, "--yes", *WAIT)
    assert result.exit_code == 5, result.output
    assert "--allow operating-mode" in result.stderr
    assert writes == []


def test_params_that_are_not_items_are_the_plugins():
    from deltoctl.app.setup_items import pinned
    from deltoctl.families.dynamixel.models import config_rules
    from deltoctl.servo.addressing import Wanted

    w = Wanted("gripper", "arm", 15, 1_000_000, "Dynamixel 2.0", "XM430-W350",
               {"Goal Current": "200", "id": "15", "use_dummy": "false"})
    assert pinned(w, config_rules()) == {"Goal Current": 200}


def test_a_pinned_reading_or_command_is_refused_and_not_written(cli, monkeypatch, tmp_path):
    writes = _count_writes(monkeypatch)
    profile = _pinned(tmp_path, "Goal Current: 200", "Torque Enable: 1")
    result = cli("-p", profile, "--sim", "--sim-fresh", "--sim-option", "factory_new",
                 "setup", "gripper", "--yes", *ALLOW, *WAIT)
    assert result.exit_code == 2, result.output
    assert "gripper: the profile pins Torque Enable, which is not a setting" in result.stderr
    torque_on = (64, b"\x01")  # (the torque is switched off to address it: that is written)
    assert not [w for w in writes if w[1] == OPERATING_MODE or w[1:] == torque_on]
