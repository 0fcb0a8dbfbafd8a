"""config restore of an untrusted snapshot on the MH5's emulated XL430 buses (ptys): every value
is checked against its item's documented range (ROBOTIS e-manual), not only its byte size, and
the safety settings (limits, shutdown, homing offset, modes) are written only when --allow
names them."""

from __future__ import annotations

import copy
import json

import pytest

from tests.app.test_config import save, servo_items, take
from tests.conftest import mh5_targets

HEAD_Y = 52  # its Dynamixel ID on upper_body


def _restore(cli, targets, path, *args):
    return cli("-p", "mh5", *targets, "config", "restore", path, "--yes", "--json", *args)


def test_values_outside_their_documented_range_are_refused_and_nothing_written(
        cli, mh5_buses, tmp_path):
    targets = mh5_targets(mh5_buses)
    doc = take(cli, tmp_path, "-p", "mh5", *targets)
    servo = mh5_buses["upper_body"].bus.servos[HEAD_Y]
    before = bytes(servo.memory)
    cases = [("Max Position Limit", 5000, "0..4095"), ("Min Position Limit", 4096, "0..4095"),
             ("Temperature Limit", 150, "0..100"), ("Min Voltage Limit", 20, "60..140"),
             ("PWM Limit", 1000, "0..885"), ("Velocity Limit", 2000, "0..1023"),
             ("Homing Offset", 2_000_000, "-1044479..1044479"),
             ("Return Delay Time", 255, "0..254"), ("Position P Gain", 20000, "0..16383")]
    for item, value, documented in cases:
        edited = copy.deepcopy(doc)
        servo_items(edited, "upper_body", "head_y")[item]["value"] = value
        servo_items(edited, "upper_body", "head_y")["LED"]["value"] = 1  # fine, not written
        path = save(tmp_path, edited)
        allow = ("--allow", item.lower().replace(" ", "-"), "--allow", "torque-off")
        result = _restore(cli, targets, path, *allow)
        assert result.exit_code == 2, (item, result.stderr)
        message = json.loads(result.stderr)["error"]["message"]
        assert message.startswith(f"{path}:")
        assert f"upper_body/head_y/{item}: {value} is outside the item's documented range " \
               f"{documented}" in message, message
        assert result.stdout == ""
        assert bytes(servo.memory) == before, item  # nothing written, not even the LED


def test_a_safety_setting_is_written_only_when_allowed(cli, mh5_buses, tmp_path):
    targets = mh5_targets(mh5_buses)
    doc = take(cli, tmp_path, "-p", "mh5", *targets)
    head_y = servo_items(doc, "upper_body", "head_y")
    head_y["Max Position Limit"]["value"] = 3000
    head_y["LED"]["value"] = 1
    edited = save(tmp_path, doc)
    servo = mh5_buses["upper_body"].bus.servos[HEAD_Y]
    refused = _restore(cli, targets, edited)
    assert refused.exit_code == 5, refused.stderr
    error = json.loads(refused.stderr)["error"]
    assert "head_y" in error["message"] and "--allow max-position-limit" in error["message"]
    assert "--allow max-position-limit" in error["hint"]
    items = {i["item"]: i for i in json.loads(refused.stdout)["result"]["items"]}
    assert items["Max Position Limit"]["status"] == "refused"
    assert items["Max Position Limit"]["note"] == "needs --allow max-position-limit"
    assert items["LED"]["status"] == "write"
    assert servo.get("Max Position Limit") == 4095 and servo.get("LED") == 0  # none written
    # named (as the snapshot spells it, too): written and read back
    allowed = _restore(cli, targets, edited, "--allow", "Max_Position_Limit")
    assert allowed.exit_code == 0, allowed.stderr
    report = json.loads(allowed.stdout)["result"]
    assert report["summary"] == {"verified": 2}
    assert {i["item"]: i["after"] for i in report["items"]} == {"Max Position Limit": 3000,
                                                               "LED": 1}
    assert servo.get("Max Position Limit") == 3000 and servo.get("LED") == 1


@pytest.mark.parametrize(("item", "value"), [
    ("Min Position Limit", 100), ("Temperature Limit", 60), ("Max Voltage Limit", 120),
    ("Min Voltage Limit", 70), ("PWM Limit", 500), ("Velocity Limit", 200), ("Shutdown", 20),
    ("Homing Offset", 1000), ("Drive Mode", 4), ("Operating Mode", 1),
])
def test_each_safety_setting_needs_its_own_allow(cli, mh5_buses, tmp_path, item, value):
    targets = mh5_targets(mh5_buses)
    doc = take(cli, tmp_path, "-p", "mh5", *targets)
    servo_items(doc, "upper_body", "head_y")[item]["value"] = value
    edited = save(tmp_path, doc)
    servo = mh5_buses["upper_body"].bus.servos[HEAD_Y]
    before = servo.get(item)
    key = item.lower().replace(" ", "-")
    other = _restore(cli, targets, edited, "--allow", "max-position-limit")
    assert other.exit_code == 5, other.stderr
    assert f"--allow {key}" in json.loads(other.stderr)["error"]["message"]
    assert servo.get(item) == before
    allowed = _restore(cli, targets, edited, "--allow", key)
    assert allowed.exit_code == 0, allowed.stderr
    assert servo.get(item) == value


def test_torque_on_and_a_safety_setting_need_both_permissions(cli, mh5_buses, tmp_path):
    targets = mh5_targets(mh5_buses)
    doc = take(cli, tmp_path, "-p", "mh5", *targets)
    servo_items(doc, "upper_body", "head_y")["Temperature Limit"]["value"] = 65
    edited = save(tmp_path, doc)
    assert cli("-p", "mh5", *targets, "torque", "on", "head_y", "--yes").exit_code == 0
    servo = mh5_buses["upper_body"].bus.servos[HEAD_Y]
    for allow in (("--allow", "torque-off"), ("--allow", "temperature-limit")):
        result = _restore(cli, targets, edited, *allow)
        assert result.exit_code == 5, result.stderr
        note = json.loads(result.stdout)["result"]["items"][0]["note"]
        assert note == "needs " + ("--allow temperature-limit" if "torque-off" in allow
                                   else "--allow torque-off")
        assert servo.get("Temperature Limit") == 72 and servo.get("Torque Enable") == 1
    both = _restore(cli, targets, edited, "--allow", "torque-off", "--allow",
                    "temperature-limit")
    assert both.exit_code == 0, both.stderr
    assert servo.get("Temperature Limit") == 65 and servo.get("Torque Enable") == 1
