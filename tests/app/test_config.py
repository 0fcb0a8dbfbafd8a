"""deltoctl config snapshot|diff|restore against the emulators, through the CLI."""

from __future__ import annotations

import json

import pytest
import yaml

from tests.conftest import eventually, mh5_targets, sim_i2c_bus


def targets_of(buses: dict[str, str]) -> list[str]:
    return [a for bus, url in buses.items() for a in ("-t", f"{bus}={url}")]


def take(cli, tmp_path, *args: str, name: str = "snap.yaml") -> dict:
    """A snapshot written to tmp_path; returns the document the file holds."""
    path = tmp_path / name
    result = cli(*args, "config", "snapshot", "-o", str(path))
    assert result.exit_code == 0, result.stderr
    return yaml.safe_load(path.read_text())


def save(tmp_path, doc: dict, name: str = "edited.yaml") -> str:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(doc, sort_keys=False, allow_unicode=True))
    return str(path)


def servo_items(doc: dict, block: str, joint: str) -> dict:
    return doc["blocks"][block]["parts"][joint]


# -- snapshot ------------------------------------------------------------------------------------

def test_snapshot_of_the_mh5_holds_every_servo_table_and_the_imu(cli, deltoctl_sim, tmp_path):
    buses = deltoctl_sim.buses("mh5")
    result = cli("-p", "mh5", *targets_of(buses), "config", "snapshot", "-o",
                 str(tmp_path / "mh5.yaml"), "--json")
    assert result.exit_code == 0, result.stderr
    doc = json.loads(result.stdout)["result"]
    assert doc == yaml.safe_load((tmp_path / "mh5.yaml").read_text())  # the file, as printed
    assert doc["deltoctl_config"] == 1 and doc["profile"] == "mh5" and doc["deltoctl"]
    blocks = doc["blocks"]
    assert {name: b["family"] for name, b in blocks.items()} == {
        "upper_body": "dynamixel", "lower_body": "dynamixel", "i2c": "lsm6ds3"}
    assert blocks["upper_body"]["target"] == buses["upper_body"]
    servos = {**blocks["upper_body"]["parts"], **blocks["lower_body"]["parts"]}
    assert len(servos) == 22
    from deltoctl.families.dynamixel.control_table import XL430

    for items in servos.values():
        assert list(items) == [i.name for i in XL430]  # the whole control table, by name
    head_y = servos["head_y"]
    assert head_y["ID"]["value"] == 52
    assert head_y["Return Delay Time"] == {"value": 250, "unit": "2 µs", "access": "RW",
                                           "area": "EEPROM", "address": 9}
    assert head_y["Present Position"]["state"] is True  # a reading: never compared
    imu = blocks["i2c"]["parts"]["imu"]
    assert imu["WHO_AM_I"]["value"] == 0x6A
    assert imu["CTRL1_XL"]["meaning"] == "416 Hz, ±2 g, filter 100 Hz"
    assert imu["CTRL2_G"]["meaning"] == "416 Hz, ±245 dps"


def test_snapshot_file_is_named_by_profile_address_and_time(cli, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert cli("-p", "mh5", "--sim", "config", "snapshot").exit_code == 0
    assert cli("-p", "dg-5f-right", "--sim", "config", "snapshot").exit_code == 0
    names = sorted(p.name for p in tmp_path.glob("config-*.yaml"))
    assert names[0].startswith("config-dg-5f-right-127.0.0.1_") and \
        names[1].startswith("config-mh5-2"), names
    assert all(n.endswith("Z.yaml") for n in names)


def test_snapshot_of_two_hands(cli, tmp_path):
    doc = take(cli, tmp_path, "-p", "dg-5f-bimanual", "--sim")
    assert set(doc["blocks"]) == {"DG5FLeftHardware", "DG5FRightHardware"}
    for block in doc["blocks"].values():
        gripper = block["parts"]["gripper"]
        assert block["family"] == "delto"
        assert gripper["firmware"] == {"value": "3.0", "access": "R"}
        assert gripper["sensor type"]["value"] == "ft_6axis"
        assert gripper["finger mask"]["value"] == 0b11111
        residuals = [p for p in block["parts"] if p != "gripper"]
        assert len(residuals) == 5  # one F/T sensor per finger, read at rest
        assert all(e["state"] for p in residuals for e in block["parts"][p].values())


def test_snapshot_of_the_arm_with_its_gripper(cli, tmp_path):
    doc = take(cli, tmp_path, "-p", "bioscara-dg-3f-m", "--sim")
    arm = doc["blocks"]["bioscara_arm"]
    assert arm["family"] == "bioscara" and set(arm["parts"]) == {"j1", "j2", "j3", "j4"}
    j2 = arm["parts"]["j2"]
    assert j2["home offset"] == {"value": 0.0, "unit": "m", "access": "RW"}
    assert j2["flags"]["meaning"] == "not homed, not enabled"
    assert j2["drive current"] == {"value": 40, "unit": "% of 2.5 A", "access": "profile"}
    assert doc["blocks"]["dg3f_m_driver"]["parts"]["gripper"]["model"]["value"].startswith(
        "DG-3F-M")


def test_hardware_narrows_the_snapshot(cli, tmp_path):
    doc = take(cli, tmp_path, "-p", "mh5", "--sim", "--hardware", "lower_body")
    assert list(doc["blocks"]) == ["lower_body"]


# -- diff ----------------------------------------------------------------------------------------

@pytest.mark.parametrize("profile", ["mh5", "dg-5f-bimanual", "bioscara-dg-3f-m", "rrbot-gpio"])
def test_a_snapshot_matches_the_live_devices(cli, deltoctl_sim, tmp_path, profile):
    targets = targets_of(deltoctl_sim.buses(profile)) if profile != "rrbot-gpio" else []
    take(cli, tmp_path, "-p", profile, *targets)
    result = cli("-p", profile, *targets, "config", "diff", str(tmp_path / "snap.yaml"),
                 "--json")
    assert result.exit_code == 0, result.stdout + result.stderr
    report = json.loads(result.stdout)["result"]
    assert report["same"] is True and report["differences"] == [] and report["against"] == "live"


def test_diff_shows_what_changed_on_the_device_and_between_files(cli, mh5_buses, tmp_path):
    targets = mh5_targets(mh5_buses)
    doc = take(cli, tmp_path, "-p", "mh5", *targets)
    servo = mh5_buses["upper_body"].bus.servos[52]
    servo.set("Return Delay Time", 20)
    servo.set("Present Position", 1000)  # a reading: no difference
    result = cli("-p", "mh5", *targets, "config", "diff", str(tmp_path / "snap.yaml"), "--json")
    assert result.exit_code == 3
    assert json.loads(result.stdout)["result"]["differences"] == [
        {"block": "upper_body", "part": "head_y", "item": "Return Delay Time", "unit": "2 µs",
         "snapshot": 250, "live": 20}]
    table = cli("-p", "mh5", *targets, "config", "diff", str(tmp_path / "snap.yaml"))
    assert table.exit_code == 3
    assert "head_y" in table.stdout and "Return Delay Time" in table.stdout
    # two files: no device needed
    servo_items(doc, "lower_body", "l_hip_r")["LED"]["value"] = 1
    other = save(tmp_path, doc)
    files = cli("config", "diff", str(tmp_path / "snap.yaml"), other, "--json")
    assert files.exit_code == 3
    rows = json.loads(files.stdout)["result"]["differences"]
    assert [(r["part"], r["item"], r["snapshot"], r["other"]) for r in rows] == [
        ("l_hip_r", "LED", 0, 1)]
    assert cli("config", "diff", other, other).exit_code == 0


# -- restore -------------------------------------------------------------------------------------

def test_restore_writes_only_what_differs_and_verifies_it(cli, mh5_buses, tmp_path):
    targets = mh5_targets(mh5_buses)
    doc = take(cli, tmp_path, "-p", "mh5", *targets)
    head_y = servo_items(doc, "upper_body", "head_y")
    head_y["Return Delay Time"]["value"] = 100  # EEPROM (torque is off)
    head_y["Position P Gain"]["value"] = 700  # RAM
    servo_items(doc, "lower_body", "r_ank_p")["Velocity I Gain"]["value"] = 1234
    edited = save(tmp_path, doc)
    result = cli("-p", "mh5", *targets, "config", "restore", edited, "--yes", "--json")
    assert result.exit_code == 0, result.stderr
    report = json.loads(result.stdout)["result"]
    assert report["summary"] == {"verified": 3}
    assert {(i["part"], i["item"], i["live"], i["after"]) for i in report["items"]} == {
        ("head_y", "Return Delay Time", 250, 100), ("head_y", "Position P Gain", 640, 700),
        ("r_ank_p", "Velocity I Gain", 1000, 1234)}
    servo = mh5_buses["upper_body"].bus.servos[52]
    assert servo.get("Return Delay Time") == 100 and servo.get("Position P Gain") == 700
    assert mh5_buses["lower_body"].bus.servos[22].get("Velocity I Gain") == 1234
    assert mh5_buses["upper_body"].bus.servos[51].get("Return Delay Time") == 250
    # the first snapshot brings the emulator back
    back = cli("-p", "mh5", *targets, "config", "restore", str(tmp_path / "snap.yaml"), "-y")
    assert back.exit_code == 0, back.stderr
    assert servo.get("Return Delay Time") == 250 and servo.get("Position P Gain") == 640
    assert cli("-p", "mh5", *targets, "config", "diff", str(tmp_path / "snap.yaml")) \
        .exit_code == 0
    again = cli("-p", "mh5", *targets, "config", "restore", str(tmp_path / "snap.yaml"),
                "--json")  # nothing differs: nothing to confirm
    assert again.exit_code == 0 and json.loads(again.stdout)["result"]["items"] == []


def test_restore_asks_first_and_writes_nothing_unconfirmed(cli, mh5_buses, tmp_path):
    targets = mh5_targets(mh5_buses)
    doc = take(cli, tmp_path, "-p", "mh5", *targets)
    servo_items(doc, "upper_body", "head_p")["LED"]["value"] = 1
    result = cli("-p", "mh5", *targets, "config", "restore", save(tmp_path, doc))
    assert result.exit_code == 5
    assert "confirmation" in result.stderr
    assert mh5_buses["upper_body"].bus.servos[51].get("LED") == 0


def test_eeprom_with_torque_on_is_refused_and_leaves_the_servo_unchanged(cli, mh5_buses,
                                                                        tmp_path):
    targets = mh5_targets(mh5_buses)
    doc = take(cli, tmp_path, "-p", "mh5", *targets)
    head_y = servo_items(doc, "upper_body", "head_y")
    head_y["Return Delay Time"]["value"] = 100
    head_y["Position P Gain"]["value"] = 700
    edited = save(tmp_path, doc)
    assert cli("-p", "mh5", *targets, "torque", "on", "head_y", "--yes").exit_code == 0
    servo = mh5_buses["upper_body"].bus.servos[52]
    # a sync write has no reply: the emulator's thread applies it a moment later
    assert eventually(lambda: servo.get("Torque Enable") == 1)
    refused = cli("-p", "mh5", *targets, "config", "restore", edited, "--yes", "--json")
    assert refused.exit_code == 5, refused.stderr
    error = json.loads(refused.stderr)["error"]
    assert "head_y" in error["message"] and "--allow torque-off" in error["hint"]
    statuses = {i["item"]: i["status"] for i in json.loads(refused.stdout)["result"]["items"]}
    assert statuses == {"Return Delay Time": "refused", "Position P Gain": "write"}
    assert servo.get("Return Delay Time") == 250 and servo.get("Position P Gain") == 640
    assert servo.get("Torque Enable") == 1
    # allowed: torque off for the EEPROM write, on again holding where it is
    servo.set("Goal Position", 3000)  # a stale goal must not become a move
    allowed = cli("-p", "mh5", *targets, "config", "restore", edited, "--yes",
                  "--allow", "torque-off", "--json")
    assert allowed.exit_code == 0, allowed.stderr
    assert json.loads(allowed.stdout)["result"]["summary"] == {"verified": 2}
    assert servo.get("Return Delay Time") == 100 and servo.get("Position P Gain") == 700
    assert servo.get("Torque Enable") == 1
    assert servo.get("Goal Position") == servo.get("Present Position")


def test_bus_settings_and_readings_are_not_restored(cli, mh5_buses, tmp_path):
    targets = mh5_targets(mh5_buses)
    doc = take(cli, tmp_path, "-p", "mh5", *targets)
    head_p = servo_items(doc, "upper_body", "head_p")
    head_p["Baud Rate"]["value"] = 3  # would take the servo off the bus
    head_p["Goal Position"]["value"] = 100  # a command: restoring it would move the servo
    head_p["Firmware Version"]["value"] = 45  # read-only
    result = cli("-p", "mh5", *targets, "config", "restore", save(tmp_path, doc), "-y",
                 "--json")
    assert result.exit_code == 3
    statuses = {i["item"]: i["status"] for i in json.loads(result.stdout)["result"]["items"]}
    assert statuses == {"Baud Rate": "skipped", "Firmware Version": "read-only"}
    servo = mh5_buses["upper_body"].bus.servos[51]
    assert servo.get("Baud Rate") == 1 and servo.get("Goal Position") == 2047


def test_imu_registers_restore_and_profile_settings_stay(cli, mh5_buses, tmp_path):
    targets = mh5_targets(mh5_buses)
    doc = take(cli, tmp_path, "-p", "mh5", *targets)
    imu = doc["blocks"]["i2c"]["parts"]["imu"]
    imu["CTRL6_C"]["value"] = 0x10
    imu["CTRL1_XL"]["value"] = 0x40  # the profile's rate and range: set at each start
    result = cli("-p", "mh5", *targets, "config", "restore", save(tmp_path, doc), "-y",
                 "--json")
    assert result.exit_code == 3, result.stderr
    statuses = {i["item"]: i["status"] for i in json.loads(result.stdout)["result"]["items"]}
    assert statuses == {"CTRL6_C": "verified", "CTRL1_XL": "read-only"}
    chip = mh5_buses["i2c"].bus.devices[0x6A]
    assert chip.registers[0x15] == 0x10 and chip.registers[0x10] == 0x62


@pytest.fixture
def arm():
    """The Bioscara arm's bus, its joints at hand."""
    from deltoctl.profile.catalog import load_profile
    from deltoctl.sim.i2c_bus import I2CSocketServer

    sim = sim_i2c_bus(load_profile("bioscara-arm"))
    server = I2CSocketServer(sim).start()
    yield server.url, sim.devices
    server.close()


def test_home_offset_is_restored_only_when_asked(cli, arm, tmp_path):
    url, joints = arm
    doc = take(cli, tmp_path, "-p", "bioscara-arm", "-t", url)
    doc["blocks"]["bioscara_arm"]["parts"]["j3"]["home offset"]["value"] = 0.5
    doc["blocks"]["bioscara_arm"]["parts"]["j3"]["max velocity"]["value"] = 1.0
    edited = save(tmp_path, doc)
    skipped = cli("-p", "bioscara-arm", "-t", url, "config", "restore", edited, "-y", "--json")
    assert skipped.exit_code == 3
    statuses = {i["item"]: i["status"] for i in json.loads(skipped.stdout)["result"]["items"]}
    assert statuses == {"home offset": "skipped", "max velocity": "read-only"}
    assert joints[0x13].home_offset == 0.0
    asked = cli("-p", "bioscara-arm", "-t", url, "config", "restore", edited, "-y",
                "--allow", "home-offset", "--json")
    assert asked.exit_code == 3  # max velocity comes from the profile
    statuses = {i["item"]: i["status"] for i in json.loads(asked.stdout)["result"]["items"]}
    assert statuses == {"home offset": "verified", "max velocity": "read-only"}
    assert joints[0x13].home_offset == 0.5


def test_gripper_values_are_read_only_but_compared(cli, deltoctl_sim, tmp_path):
    target = deltoctl_sim("dg-5f-right")
    doc = take(cli, tmp_path, "-p", "dg-5f-right", "-t", target)
    doc["blocks"]["DG5FRightHardware"]["parts"]["gripper"]["firmware"]["value"] = "2.9"
    edited = save(tmp_path, doc)
    diff = cli("-p", "dg-5f-right", "-t", target, "config", "diff", edited, "--json")
    assert diff.exit_code == 3
    assert [(r["item"], r["snapshot"], r["live"]) for r in
            json.loads(diff.stdout)["result"]["differences"]] == [("firmware", "2.9", "3.0")]
    restore = cli("-p", "dg-5f-right", "-t", target, "config", "restore", edited, "-y",
                  "--json")
    assert restore.exit_code == 3
    assert [(i["item"], i["status"]) for i in json.loads(restore.stdout)["result"]["items"]] == [
        ("firmware", "read-only")]


def test_generic_blocks_restore_their_interface_values(cli, tmp_path):
    doc = take(cli, tmp_path, "-p", "rrbot-gpio")
    doc["blocks"]["RRBotSystemMutipleGPIOs"]["parts"]["flange_analog_IOs"][
        "analog_output1"]["value"] = 1.5
    result = cli("-p", "rrbot-gpio", "config", "restore", save(tmp_path, doc), "-y", "--json")
    assert result.exit_code == 0, result.stderr
    assert [(i["item"], i["status"], i["after"]) for i in json.loads(result.stdout)["result"]["items"]] \
        == [("analog_output1", "verified", 1.5)]


# -- an untrusted snapshot -------------------------------------------------------------------------

@pytest.fixture
def mh5_snapshot(cli, mh5_buses, tmp_path):
    targets = mh5_targets(mh5_buses)
    take(cli, tmp_path, "-p", "mh5", *targets)
    return targets, (tmp_path / "snap.yaml").read_text()


@pytest.mark.parametrize(("old", "new", "message"), [
    ("Return Delay Time: {value: 250", "Return Delay Time: {value: 256",
     "head_p/Return Delay Time: 256 is outside the item's range 0..255"),
    ("Homing Offset: {value: 0,", "Homing Offset: {value: -2147483649,",
     "Homing Offset: -2147483649 is outside the item's range -2147483648..2147483647"),
    ("Return Delay Time: {value: 250", "Return Delay Tim: {value: 250",
     "no item 'Return Delay Tim' (did you mean Return Delay Time?)"),
    ("Homing Offset: {value: 0,", "Homing Offset: {value: zero,",
     "Homing Offset: 'zero' is text; the item holds an integer"),
    ("Return Delay Time: {value: 250", "Return Delay Time: {value: !!python/object:os.system 1",
     "could not determine a constructor"),
    ("Return Delay Time: {value: 250", "Return Delay Time: {value: .nan",
     "Return Delay Time: not a finite number"),
    ("      head_p:\n", "      head_q:\n", "no part 'head_q'"),
    ("  upper_body:\n", "  upper_bod:\n", "mh5 has no such block"),
    ("family: lsm6ds3", "family: bioscara", "a bioscara block in the snapshot"),
    ("deltoctl_config: 1", "deltoctl_config: 7", "not a deltoctl configuration snapshot"),
    ("profile: mh5", "profile: mh5\nextra: 1", "unknown key 'extra'"),
])
def test_a_bad_snapshot_is_refused_naming_the_item(cli, mh5_buses, mh5_snapshot, tmp_path, old,
                                                   new, message):
    targets, text = mh5_snapshot
    assert old in text
    bad = tmp_path / "bad.yaml"
    bad.write_text(text.replace(old, new, 1))
    before = bytes(mh5_buses["upper_body"].bus.servos[51].memory)
    for verb in ("diff", "restore"):
        result = cli("-p", "mh5", *targets, "config", verb, str(bad), "-y", "--json")
        assert result.exit_code == 2, (verb, result.stdout, result.stderr)
        error = json.loads(result.stderr)["error"]["message"]
        assert error.startswith(f"{bad}:") and message in error, error
    assert bytes(mh5_buses["upper_body"].bus.servos[51].memory) == before


def test_snapshot_size_and_alias_bombs_are_refused(cli, tmp_path, monkeypatch):
    from deltoctl.app import config

    bomb = tmp_path / "bomb.yaml"
    lines = ["a: &a [x, x, x, x, x, x, x, x, x, x]"]
    for i, name in enumerate("bcdef"):
        prev = "abcdef"[i]
        lines.append(f"{name}: &{name} [" + ", ".join([f"*{prev}"] * 10) + "]")
    bomb.write_text("\n".join(lines) + "\n")
    result = cli("config", "diff", str(bomb), str(bomb))
    assert result.exit_code == 2 and "alias" in result.stderr
    monkeypatch.setattr(config, "MAX_SNAPSHOT_BYTES", 100)
    big = tmp_path / "big.yaml"
    big.write_text("deltoctl_config: 1\n" + "#" * 200 + "\n")
    result = cli("config", "diff", str(big), str(big))
    assert result.exit_code == 2 and "the limit for a snapshot" in result.stderr
    assert cli("config", "diff", str(tmp_path), str(big)).exit_code == 2  # not a regular file


def test_a_servo_that_does_not_answer_is_named_not_compared(cli, deltoctl_sim, tmp_path):
    take(cli, tmp_path, "-p", "mh5", "--sim")
    buses = deltoctl_sim.buses("mh5", missing=("head_y",))
    result = cli("-p", "mh5", *targets_of(buses), "config", "diff",
                 str(tmp_path / "snap.yaml"), "--json")
    assert result.exit_code == 3
    report = json.loads(result.stdout)["result"]
    assert report["differences"] == []
    assert "upper_body/head_y: in the snapshot, not compared (it does not answer)" in \
        report["warnings"]


def test_snapshot_to_stdout(cli):
    result = cli("-p", "rrbot-gpio", "config", "snapshot", "-o", "-")
    assert result.exit_code == 0
    doc = yaml.safe_load(result.stdout)
    assert doc["profile"] == "rrbot-gpio"
    assert doc["blocks"]["RRBotSystemMutipleGPIOs"]["target"] is None
