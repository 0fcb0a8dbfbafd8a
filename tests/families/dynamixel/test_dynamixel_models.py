"""Dynamixel X-series models by model number: the tables against the ROBOTIS e-manual, the
emulator serving each servo as its model, and identify, register and config on buses of other
and mixed models (koch-arm: XL430 + XL330; open-manipulator-x: XM430), over ptys."""

from __future__ import annotations

import json
import struct

import pytest

from deltoctl.families.dynamixel import codec
from deltoctl.families.dynamixel.emulator import (
    DATA_LIMIT_ERROR,
    DATA_RANGE_ERROR,
    DynamixelBus,
    DynamixelPtyServer,
    Servo,
)
from deltoctl.families.dynamixel.models import BY_NUMBER, MODELS, UNVERIFIED, by_name
from tests.conftest import block_of, eventually


def result(run) -> dict:
    """A verb's JSON document (its result, when the document wraps one)."""
    doc = json.loads(run.stdout)
    return doc.get("result", doc) if isinstance(doc, dict) else doc


# -- the tables (e-manual facts) ------------------------------------------------------------------

@pytest.mark.parametrize(("number", "name"), [
    (1000, "XH430-W350"), (1001, "XD430-T350"), (1020, "XM430-W350"), (1030, "XM430-W210"),
    (1040, "XH430-V350"), (1060, "XL430-W250"), (1070, "XC430-W150"), (1090, "2XL430-W250"),
    (1100, "XH540-W270"), (1120, "XM540-W270"), (1170, "XW540-T260"), (1190, "XL330-M077"),
    (1200, "XL330-M288"), (1220, "XC330-T288"), (1240, "XC330-M288"), (1270, "XW430-T333"),
    (1310, "XW540-H260")])
def test_model_numbers_are_the_e_manuals(number, name):
    assert BY_NUMBER[number].name == name
    assert by_name(name.lower().replace("-", "_")) is BY_NUMBER[number]
    assert by_name(name + "-R") is BY_NUMBER[number]  # the interface suffix


def test_the_xm430_w350_table():
    xm = by_name("XM430-W350")
    items = xm.by_name
    assert (items["Current Limit"].address, items["Current Limit"].default,
            items["Current Limit"].high) == (38, 1193, 1193)
    assert items["Goal Current"].address == 102 and items["Present Current"].address == 126
    assert "Present Load" not in items
    assert xm.units()["Present Current"] == "2.69 mA"
    assert xm.units()["Present Velocity"] == "0.229 rpm"
    assert items["Max Voltage Limit"].default == 160 and items["PWM Limit"].default == 885
    assert xm.modes == {0, 1, 3, 4, 5, 16}


def test_the_xl330_m288_table():
    xl = by_name("XL330-M288")
    items = xl.by_name
    assert xl.current_unit == 1.0 and items["Current Limit"].default == 1750
    assert items["PWM Slope"].address == 62
    assert (items["Velocity Limit"].default, items["Velocity Limit"].high) == (445, 2047)
    assert (items["Max Voltage Limit"].default, items["Min Voltage Limit"].default) == (70, 35)
    assert items["Baud Rate"].high == 6  # 4 Mbps at most
    assert items["Temperature Limit"].default == 70


def test_the_xl430_has_no_current_and_the_others_differ_where_the_pages_say():
    xl430 = by_name("XL430-W250")
    assert "Current Limit" not in xl430.by_name and "Present Load" in xl430.by_name
    assert xl430.modes == {1, 3, 4, 16}
    assert by_name("XH430-V350").current_unit == 1.34
    assert by_name("XH430-V350").by_name["Current Limit"].default == 689
    assert by_name("XM540-W270").by_name["External Port Mode 1"].address == 56
    assert by_name("XM540-W270").table_size == 158  # External Port Data 3 ends at 157
    assert "LED" not in by_name("XW540-T260").by_name  # the waterproof ones have none
    assert by_name("XC330-T288").by_name["Current Limit"].default == 910


def test_every_model_reads_position_velocity_and_current_where_one_sync_read_does():
    for model in MODELS:
        items = model.by_name
        effort = items.get("Present Current") or items["Present Load"]
        assert (effort.address, items["Present Velocity"].address,
                items["Present Position"].address) == (126, 128, 132), model.name
        assert (items["Present Input Voltage"].address,
                items["Present Temperature"].address) == (144, 146), model.name
    assert set(UNVERIFIED) <= {m.name for m in MODELS}


# -- the emulator: each servo its model ------------------------------------------------------------

def _write(bus: DynamixelBus, device_id: int, address: int, data: bytes) -> int:
    [(_, reply)] = bus.handle(device_id, codec.WRITE, struct.pack("<H", address) + data)
    return codec.decode_status(*codec.PacketReader().feed(reply)[0]).error


def test_the_emulator_runs_the_modes_each_model_has():
    bus = DynamixelBus([Servo(1, model=by_name("XL430-W250")),
                        Servo(2, model=by_name("XM430-W350"))])
    assert _write(bus, 1, 11, bytes([0])) == DATA_RANGE_ERROR  # no current mode on an XL430
    assert _write(bus, 2, 11, bytes([0])) == 0
    assert _write(bus, 1, 102, b"\x10\x00") != 0  # no Goal Current either
    assert _write(bus, 2, 102, struct.pack("<h", 1194)) == DATA_LIMIT_ERROR  # above 1193
    assert _write(bus, 2, 11, bytes([1])) == 0  # velocity mode
    assert _write(bus, 2, 64, bytes([1])) == 0
    assert _write(bus, 2, 104, struct.pack("<i", 100)) == 0
    servo = bus.servos[2]
    start = servo.position
    assert eventually(lambda: (servo.update(), servo.position > start + 20)[1])
    assert servo.get("Present Current") > 0  # in the XM430's 2.69 mA steps
    assert _write(bus, 2, 104, struct.pack("<i", 201)) == DATA_LIMIT_ERROR  # limit 200


# -- identify, register, config over a pty ---------------------------------------------------------

def _koch_bus(models: list[str]) -> DynamixelPtyServer:
    return DynamixelPtyServer(DynamixelBus(
        [Servo(i, model=by_name(m)) for i, m in enumerate(models, 1)], baud=1_000_000)).start()


def test_identify_names_each_model_of_a_mixed_bus(cli):
    run = cli("--sim", "-p", "koch-arm", "identify", "--json")
    assert run.exit_code == 0, run.stderr
    servos = block_of(result(run))["identity"]["servos"]
    assert {j: s["model"] for j, s in servos.items()} == {
        "shoulder_pan": "XL430-W250", "shoulder_lift": "XL430-W250",
        "elbow_flex": "XL330-M288", "wrist_flex": "XL330-M288", "wrist_roll": "XL330-M288",
        "gripper": "XL330-M288"}
    assert all(s["model_match"] for s in servos.values())


def test_a_model_the_profile_does_not_name_is_an_error_unless_allowed(cli):
    server = _koch_bus(["XL430-W250", "XM430-W350", "XL330-M288", "XL330-M288",
                        "XL330-M288", "XL330-M288"])
    target = f"serial://{server.port}?baud=1000000"
    try:
        refused = cli("-p", "koch-arm", "-t", target, "identify")
        assert refused.exit_code == 1
        assert "shoulder_lift (ID 2) is XM430-W350 (1020), the profile says XL430-W250" \
            in refused.stderr
        assert "Traceback" not in refused.stderr
        allowed = cli("-p", "koch-arm", "-t", target, "identify", "--allow-model-mismatch",
                      "--json")
        assert allowed.exit_code == 3, allowed.stderr
        servo = block_of(result(allowed))["identity"]["servos"]["shoulder_lift"]
        assert (servo["model"], servo["model_match"]) == ("XM430-W350", False)
    finally:
        server.close()


def test_register_uses_the_servos_own_table(cli):
    run = cli("--sim", "-p", "open-manipulator-x", "register", "get", "joint1",
              "current_limit", "--json")
    assert run.exit_code == 0, run.stderr
    assert result(run)["values"] == {"Current Limit": 1193}
    whole = result(cli("--sim", "-p", "open-manipulator-x", "register", "get", "joint1",
                       "--json"))
    names = set(whole["values"])
    assert "Present Current" in names and "Present Load" not in names
    xl430 = cli("--sim", "-p", "koch-arm", "register", "get", "shoulder_pan", "current_limit")
    assert xl430.exit_code == 2 and "XL430-W250" in xl430.stderr
    assert "Traceback" not in xl430.stderr


def test_register_set_on_an_xl330(cli):
    server = _koch_bus(["XL430-W250", "XL430-W250", "XL330-M288", "XL330-M288",
                        "XL330-M288", "XL330-M288"])
    try:
        run = cli("-p", "koch-arm", "-t", f"serial://{server.port}?baud=1000000", "--yes",
                  "register", "set", "wrist_roll", "pwm_slope", "100", "--json")
        assert run.exit_code == 0, run.stderr
        assert server.bus.servos[5].get("PWM Slope") == 100
    finally:
        server.close()


def test_config_restore_checks_each_servo_against_its_models_range(cli, tmp_path):
    server = _koch_bus(["XL430-W250", "XL430-W250", "XL330-M288", "XL330-M288",
                        "XL330-M288", "XL330-M288"])
    target = ("-p", "koch-arm", "-t", f"serial://{server.port}?baud=1000000")
    snap = tmp_path / "koch.yaml"
    try:
        taken = cli(*target, "config", "snapshot", "-o", str(snap))
        assert taken.exit_code == 0, taken.stderr
        text = snap.read_text()
        assert "Current Limit: {value: 1750, unit: 1 mA" in text  # the XL330's, in its unit
        # 2000 is within some model's range (the XC330-M's), not the XL330-M288's 0..1750
        snap.write_text(text.replace("Current Limit: {value: 1750", "Current Limit: {value: "
                                     "2000", 1))
        refused = cli(*target, "--yes", "config", "restore", str(snap), "--allow",
                      "current-limit")
        assert refused.exit_code == 2, refused.stderr
        assert "elbow_flex/Current Limit: 2000" in refused.stderr
        assert "0..1750" in refused.stderr and "Traceback" not in refused.stderr
        assert all(s.get("Current Limit") == 1750 for s in list(server.bus.servos.values())[2:])
        snap.write_text(text.replace("Current Limit: {value: 1750", "Current Limit: {value: "
                                     "1000", 1))
        written = cli(*target, "--yes", "config", "restore", str(snap), "--allow",
                      "current-limit")
        assert written.exit_code == 0, written.stderr
        assert server.bus.servos[3].get("Current Limit") == 1000
    finally:
        server.close()


def test_register_set_keeps_to_an_items_documented_range(cli):
    run = cli("--sim", "-p", "koch-arm", "--yes", "register", "set", "shoulder_pan",
              "torque_enable", "128")
    assert run.exit_code == 2, run.stderr
    assert "Torque Enable 128 is outside the XL430-W250's documented range 0..1" in run.stderr
