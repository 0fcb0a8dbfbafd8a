"""The verbs on the mh5 profile, through pyserial, against the XL430 bus emulator on ptys."""

from __future__ import annotations

import json

import pytest

from tests.conftest import block_for, block_of, eventually, mh5_targets, ros2_messages


def test_identify_detect_stream_with_sim(cli):
    result = cli("--sim", "-p", "mh5", "identify", "--json")
    assert result.exit_code == 0, result.stderr
    report = json.loads(result.stdout)
    servos = {**block_of(report, "upper_body")["identity"]["servos"],
              **block_of(report, "lower_body")["identity"]["servos"]}
    assert len(servos) == 22 and servos["l_kne_p"]["id"] == 14
    assert all(s["model_number"] == 1060 for s in servos.values())
    assert cli("--sim", "-p", "mh5", "detect").exit_code == 0
    result = cli("--sim", "-p", "mh5", "stream", "-d", "0.1", "--json", "-i", "l_kne_p/*")
    sample = json.loads(result.stdout.splitlines()[0])["values"]
    assert sample["l_kne_p/position"] == pytest.approx(1.570796326794897)  # the offset
    assert sample["l_kne_p/voltage"] == 12.0 and sample["l_kne_p/temperature"] == 30.0


def test_detect_names_a_missing_servo(cli, mh5_buses):
    mh5_buses["lower_body"].bus.faults.missing.add(24)
    result = cli("-p", "mh5", *mh5_targets(mh5_buses), "detect", "--json")
    assert result.exit_code == 1  # a servo the profile declares does not answer
    report = json.loads(result.stdout)
    assert block_of(report, "lower_body")["details"]["missing"] == [24]
    assert report["result"]["failed"] == ["detect.lower_body.r_kne_p"]
    assert "detect.lower_body.r_kne_p: r_kne_p (ID 24) does not answer" in result.stderr
    identify = cli("-p", "mh5", *mh5_targets(mh5_buses), "identify")
    assert identify.exit_code == 3 and "r_kne_p" in identify.stderr


def test_corrupted_replies_count_as_errors_not_exceptions(cli, mh5_buses):
    mh5_buses["upper_body"].bus.faults.corrupt_crc.add(51)
    result = cli("-p", "mh5", *mh5_targets(mh5_buses), "stream", "-d", "0.1", "--json",
                 "-i", "head_*/position")
    assert "Traceback" not in result.stderr
    assert result.exit_code == 3  # head_p never answered a ping: a warning
    assert "head_p" in result.stderr


def test_unopenable_port_is_unreachable(cli):
    result = cli("-p", "mh5", "-t", "upper_body=serial:///dev/nonexistent?baud=2000000",
                 "identify")
    assert result.exit_code == 4
    assert "cannot open /dev/nonexistent" in result.stderr


def test_jog_turns_torque_on_and_reaches_the_goal(cli, mh5_buses):
    servo = mh5_buses["upper_body"].bus.servos[52]  # head_y
    result = cli("-p", "mh5", *mh5_targets(mh5_buses), "jog", "head_y", "10deg", "--velocity",
                 "40deg", "--yes", "--json")
    assert result.exit_code == 0, result.stderr
    assert json.loads(result.stdout)["result"]["settled"] is True
    assert eventually(lambda: servo.memory[64] == 1 and servo.memory[10] & 0x04)
    assert servo.get("Goal Position") == round(0.17453292519943295 / 0.001533980787886 + 2047)
    refused = cli("-p", "mh5", *mh5_targets(mh5_buses), "jog", "head_y", "30deg", "--yes")
    assert refused.exit_code == 5  # larger than max_jog_step (20°)


def test_torque_by_group_and_reboot_after_a_shutdown(cli, mh5_buses):
    upper = mh5_buses["upper_body"].bus.servos
    lower = mh5_buses["lower_body"].bus.servos
    targets = mh5_targets(mh5_buses)
    result = cli("-p", "mh5", *targets, "torque", "on", "arms", "--yes", "--json")
    assert result.exit_code == 0, result.stderr
    assert len(json.loads(result.stdout)["result"]["joints"]) == 8
    assert eventually(lambda: all(upper[i].memory[64] == 1
                                  for i in (31, 32, 33, 34, 41, 42, 43, 44)))
    assert upper[51].memory[64] == 0 and lower[11].memory[64] == 0  # head, legs untouched
    assert cli("-p", "mh5", *targets, "torque", "on", "head").exit_code == 5  # no --yes
    assert cli("--yes", "-p", "mh5", *targets, "torque", "off", "l_sho_p").exit_code == 0
    assert eventually(lambda: upper[34].memory[64] == 0)
    lower[24].memory[70] = 0x20  # overload shutdown on r_kne_p
    result = cli("--yes", "-p", "mh5", *targets, "reboot", "right_leg", "--json")
    assert result.exit_code == 0, result.stderr
    assert "r_kne_p" in json.loads(result.stdout)["result"]["rebooted"]
    assert lower[24].memory[70] == 0
    assert cli("-p", "mh5", *targets, "torque", "on", "wings", "--yes").exit_code == 2


def test_record_reports_each_bus_loop_with_the_mh5_keys(cli, mh5_buses, tmp_path):
    import threading

    # once the servos have answered their pings, servo 14's replies go bad
    threading.Timer(0.5, mh5_buses["lower_body"].bus.faults.corrupt_crc.add, [14]).start()
    out = tmp_path / "mh5.mcap"
    result = cli("-p", "mh5", *mh5_targets(mh5_buses), "record", str(out), "-d", "1.3")
    assert result.exit_code == 0, result.stderr
    statuses = {st.name: {kv.key: kv.value for kv in st.values}
                for _, m in ros2_messages(out, ["/diagnostics"])
                for st in m.status if "reader" in st.name or "writer" in st.name}
    assert set(statuses) == {f"deltoctl/{bus}_{loop}" for bus in ("upper_body", "lower_body")
                             for loop in ("pvl_reader", "tv_reader", "pv_writer", "t_writer")}
    upper, lower = statuses["deltoctl/upper_body_pvl_reader"], \
        statuses["deltoctl/lower_body_pvl_reader"]
    assert set(upper) == {"packets", "errors", "error_rate_perc", "total_packets",
                          "total_errors", "total_error_rate_perc", "real_rate"}
    assert int(upper["packets"]) > 50 and upper["errors"] == "0"
    assert int(lower["errors"]) > 10  # each sync read from then on lacks servo 14's reply
    assert statuses["deltoctl/upper_body_tv_reader"]["total_packets"] in ("1", "2")


def test_comm_loop_runs_at_its_own_rate():
    import time

    from deltoctl.core.loop import CommLoop

    loop = CommLoop("bus_tv_reader", 20.0)
    runs = 0
    end = time.monotonic() + 0.5
    while time.monotonic() < end:  # a 1 kHz cycle
        runs += loop.due()
        time.sleep(0.001)
    assert 9 <= runs <= 12
    loop.count(True)
    loop.count(False)
    report = loop.report()
    assert (report["packets"], report["errors"], report["error_rate_perc"]) == (2, 1, 50.0)
    assert loop.report()["packets"] == 0 and loop.report()["total_packets"] == 2


def test_register_get_and_set_with_the_eeprom_rule(cli, mh5_buses):
    servo = mh5_buses["upper_body"].bus.servos[52]
    targets = mh5_targets(mh5_buses)
    result = cli("-p", "mh5", *targets, "register", "get", "head_y", "present_temperature",
                 "9", "--json")
    assert result.exit_code == 0, result.stderr
    assert json.loads(result.stdout)["result"]["values"] == {"Present Temperature": 30,
                                                   "Return Delay Time": 250}
    dump = cli("-p", "mh5", *targets, "register", "get", "head_y")
    assert "Model Number" in dump.stdout and "Present Input Voltage" in dump.stdout
    assert cli("-p", "mh5", *targets, "register", "set", "head_y", "return_delay_time",
               "0").exit_code == 5  # a write asks first
    done = cli("-p", "mh5", *targets, "register", "set", "head_y", "return_delay_time", "0",
               "--yes")
    assert done.exit_code == 0, done.stderr
    assert servo.get("Return Delay Time") == 0
    servo.set("Torque Enable", 1)
    refused = cli("-p", "mh5", *targets, "register", "set", "head_y", "drive_mode", "4",
                  "--yes")
    assert refused.exit_code == 1
    assert "access error" in refused.stderr and "EEPROM items need torque off" in refused.stderr
    bad = cli("-p", "mh5", *targets, "register", "get", "head_y", "warp_drive")
    assert bad.exit_code == 2 and "no control table item 'warp_drive'" in bad.stderr


def test_register_reads_retry_then_say_so(mh5_buses):
    from deltoctl.errors import DeviceError
    from deltoctl.families.dynamixel.control_table import BY_NAME
    from deltoctl.families.dynamixel.driver import DynamixelDriver
    from deltoctl.profile.catalog import load_profile

    profile = load_profile("mh5")
    hw = next(h for h in profile.hardware if h.name == "upper_body")
    driver = DynamixelDriver(block_for(
        profile, hw, f"serial://{mh5_buses['upper_body'].port}?baud=1000000"))
    driver.configure()
    bus = mh5_buses["upper_body"].bus
    bus.faults.corrupt_crc.add(52)
    with pytest.raises(DeviceError, match=r"no valid reply to .* from servo 52 .* \(5 tries\)"):
        driver.read_register(52, BY_NAME["Present Temperature"])
    before = driver.stats["errors"]
    bus.faults.corrupt_crc.clear()
    assert driver.read_register(52, BY_NAME["Present Temperature"]) == 30
    assert driver.stats["errors"] == before
    driver.cleanup()


def test_detect_finds_a_servo_at_another_baud_rate():
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-m", "deltoctl", "sim", "serve", "mh5", "--json",
                             "--wrong-baud", "head_y"], stdout=subprocess.PIPE, text=True)
    try:
        buses = json.loads(proc.stdout.readline())["buses"]
        targets = [a for bus, url in buses.items() for a in ("-t", f"{bus}={url}")]
        result = subprocess.run([sys.executable, "-m", "deltoctl", "-p", "mh5", *targets,
                                 "detect", "--json"], capture_output=True, text=True)
    finally:
        proc.terminate()
        proc.wait(timeout=5)
    assert result.returncode == 1, result.stderr
    upper = block_of(json.loads(result.stdout), "upper_body")["details"]
    assert upper["missing"] == [52] and upper["wrong_baud"] == {"52": 57600}
    assert "head_y (ID 52) does not answer (found at 57600 baud, not 2000000)" in result.stderr


def test_an_inverse_joint_is_reversed_in_the_servo(cli, mh5_buses):
    servos = mh5_buses["upper_body"].bus.servos
    result = cli("-p", "mh5", *mh5_targets(mh5_buses), "jog", "head_p", "5deg", "--yes")
    assert result.exit_code == 0, result.stderr
    assert eventually(lambda: servos[51].get("Drive Mode") == 5)  # time-based + reverse
    assert servos[52].get("Drive Mode") == 0  # head_y was not commanded


def test_a_move_with_torque_already_on_follows_the_servos_drive_mode(cli, mh5_buses):
    servos = mh5_buses["upper_body"].bus.servos
    targets = mh5_targets(mh5_buses)
    assert cli("-p", "mh5", *targets, "torque", "on", "head", "--yes").exit_code == 0
    # Drive Mode cannot change now: head_y stays velocity-based, so the profile velocity is a
    # speed (0.229 rpm units) and the move still takes its time
    result = cli("-p", "mh5", *targets, "jog", "head_y", "15deg", "--velocity", "30deg",
                 "--yes", "--json")
    assert result.exit_code == 0, result.stderr
    assert 0.3 < json.loads(result.stdout)["result"]["seconds"] < 2.0
    assert servos[52].get("Drive Mode") == 0 and servos[52].get("Profile Velocity") == 22
    refused = cli("-p", "mh5", *targets, "jog", "head_p", "5deg", "--yes")
    assert refused.exit_code == 5  # inverse in the profile, not reversed in the servo
    assert "turns the other way" in refused.stderr


def test_a_silent_bus_is_unreachable(cli, mh5_buses):
    mh5_buses["lower_body"].bus.faults.no_reply = True
    result = cli("-p", "mh5", *mh5_targets(mh5_buses), "identify")
    assert result.exit_code == 4
    assert "no servo of 'lower_body' answers" in result.stderr and "Traceback" not in result.stderr


def test_detect_finds_a_whole_bus_at_another_baud_rate(cli):
    from deltoctl.families.dynamixel.emulator import DynamixelBus, DynamixelPtyServer, Servo

    bus = DynamixelBus([Servo(i) for i in (11, 12)], baud=2_000_000)
    for servo in bus.servos.values():
        servo.set("Baud Rate", 3)  # 1 Mbps
    upper = DynamixelBus([Servo(52)], baud=2_000_000)
    with DynamixelPtyServer(bus) as lower_pty, DynamixelPtyServer(upper) as upper_pty:
        targets = ["-t", f"lower_body=serial://{lower_pty.port}?baud=2000000",
                   "-t", f"upper_body=serial://{upper_pty.port}?baud=2000000",
                   "-t", "i2c=i2c:///dev/i2c-99"]
        assert cli("-p", "mh5", *targets, "identify").exit_code == 4  # nothing at 2 Mbps
        result = cli("-p", "mh5", *targets, "detect", "--json")
    assert result.exit_code == 1, result.stderr
    lower = block_of(json.loads(result.stdout), "lower_body")["details"]
    assert lower["wrong_baud"] == {"11": 1_000_000, "12": 1_000_000}
