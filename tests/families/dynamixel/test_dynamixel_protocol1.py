"""Dynamixel Protocol 1.0: the instruction table as a host/device session pair, the AX/MX tables,
the emulated bus driven by ROBOTIS' dynamixel-sdk Protocol 1.0 handler over a pty, and every verb
on the PhantomX-class AX-12A arm (phantomx-arm) through the CLI."""

from __future__ import annotations

import json
import struct

import pytest

from deltoctl.families.dynamixel import protocol1 as p1
from deltoctl.families.dynamixel.emulator import DynamixelPtyServer
from deltoctl.families.dynamixel.emulator1 import ANGLE_LIMIT, Protocol1Bus, Servo1
from deltoctl.families.dynamixel.models import by_name, by_number
from deltoctl.families.dynamixel.models1 import AX_12A, BY_NUMBER_1, MODELS_1, UNVERIFIED_1
from deltoctl.servo.session import NEED_DATA, Done
from tests.conftest import block_of, eventually


def result(run) -> dict:
    doc = json.loads(run.stdout)
    return doc.get("result", doc) if isinstance(doc, dict) else doc


# -- the session pair -----------------------------------------------------------------------------

def exchange(bus: Protocol1Bus, device_id: int, instruction: int, params: bytes = b""):
    host = p1.session()
    sent = host.send(device_id, instruction, params)
    replies = b"".join(packet for _, answer in bus.serve(sent) for _, packet in answer)
    if not host.expecting:
        return replies, None
    event = NEED_DATA
    for k in range(len(replies)):  # a byte at a time
        event = host.receive(replies[k:k + 1])
    return replies, event if isinstance(event, Done) else host.give_up()


def test_ping_read_write_and_their_statuses():
    bus = Protocol1Bus([Servo1(1), Servo1(2, BY_NUMBER_1[29])])
    _, done = exchange(bus, 2, p1.PING)
    assert done.replies == [(2, 0, b"")]  # a Protocol 1.0 PING's status holds no data
    _, done = exchange(bus, 2, p1.READ, p1.read_params(0, 3))
    assert struct.unpack("<HB", done.replies[0][2])[0] == 29
    _, done = exchange(bus, 1, p1.WRITE, p1.write_params(25, b"\x01"))
    assert done.replies == [(1, 0, b"")] and bus.servos[1].get("LED") == 1


def test_status_return_level_and_broadcast():
    bus = Protocol1Bus([Servo1(1), Servo1(2)])
    bus.servos[1].memory[16] = 1  # answers PING and READ only
    raw, done = exchange(bus, 1, p1.WRITE, p1.write_params(25, b"\x01"))
    assert raw == b"" and done.replies == [] and bus.servos[1].get("LED") == 1
    raw, _ = exchange(bus, p1.BROADCAST_ID, p1.PING)
    assert raw == b""  # no status to a broadcast PING in Protocol 1.0
    raw, _ = exchange(bus, p1.BROADCAST_ID, p1.WRITE, p1.write_params(25, b"\x00"))
    assert raw == b"" and all(s.get("LED") == 0 for s in bus.servos.values())


def test_reg_write_action_sync_write_and_reset():
    bus = Protocol1Bus([Servo1(1), Servo1(2)])
    exchange(bus, 1, p1.REG_WRITE, p1.write_params(25, b"\x01"))
    assert bus.servos[1].get("LED") == 0 and bus.servos[1].get("Registered") == 1
    exchange(bus, p1.BROADCAST_ID, p1.ACTION)
    assert bus.servos[1].get("LED") == 1
    _, done = exchange(bus, 2, p1.ACTION)  # nothing registered: an instruction error
    assert done.replies[0][1] == 1 << 6
    bus.serve(p1.sync_write(24, 1, {1: b"\x01", 2: b"\x01"}))
    assert all(s.get("Torque Enable") == 1 for s in bus.servos.values())
    exchange(bus, 2, p1.RESET)
    assert bus.servos[2].id == 1 and bus.servos[2].get("Torque Enable") == 0


def test_bulk_read_on_mx_answers_in_the_order_listed():
    mx = BY_NUMBER_1[29]
    bus = Protocol1Bus([Servo1(3, mx), Servo1(4, mx)])
    _, done = exchange(bus, p1.BROADCAST_ID, p1.BULK_READ,
                       p1.bulk_read_params([(4, 36, 8), (3, 0, 2)]))
    assert [(i, len(d)) for i, _, d in done.replies] == [(4, 8), (3, 2)] and done.complete
    assert struct.unpack("<H", done.replies[1][2])[0] == 29


def test_error_bits_are_named_with_what_to_do():
    bus = Protocol1Bus([Servo1(1)])
    exchange(bus, 1, p1.WRITE, p1.write_params(6, struct.pack("<HH", 200, 800)))
    _, done = exchange(bus, 1, p1.WRITE, p1.write_params(30, struct.pack("<H", 900)))
    error = done.replies[0][1]
    assert error == ANGLE_LIMIT and p1.error_text(error) == "angle limit error"
    assert "CW/CCW Angle Limit" in p1.error_hint(error)
    assert p1.error_words(0x7F) == ["input voltage", "angle limit", "overheating", "range",
                                    "checksum", "overload", "instruction"]


def test_sign_magnitude_load_and_speed():
    item = AX_12A.by_name["Present Load"]
    assert item.decode(bytes([0x10, 0x04])) == -16 and item.encode(-16) == bytes([0x10, 0x04])
    assert AX_12A.by_name["Present Speed"].decode(bytes([0xFF, 0x03])) == 1023


def test_models_by_number_and_name():
    assert {m.name: m.number for m in MODELS_1} == {
        "AX-12A": 12, "AX-18A": 18, "RX-28": 28, "RX-64": 64, "MX-28": 29, "MX-64": 310,
        "MX-106": 320}
    assert by_name("ax_12a") is AX_12A and by_number(320).name == "MX-106"
    assert AX_12A.by_name["Goal Position"].high == 1023
    assert BY_NUMBER_1[29].by_name["Goal Position"].high == 4095
    assert all(m.page.startswith("emanual.robotis.com/docs/en/dxl/") for m in MODELS_1)
    assert set(UNVERIFIED_1) <= {m.name for m in MODELS_1}


@pytest.mark.parametrize(("model", "facts"), [
    ("AX-12A", {"Baud Rate": 1, "Temperature Limit": 70, "Max Voltage Limit": 140,
                "Max Torque": 1023, "Punch": 32, "CCW Angle Limit": 1023}),
    ("AX-18A", {"Baud Rate": 1, "Temperature Limit": 75, "Max Torque": 983}),
    ("RX-28", {"Baud Rate": 34, "Temperature Limit": 80, "Max Voltage Limit": 190}),
    ("RX-64", {"Baud Rate": 34, "Max Voltage Limit": 190, "CW Compliance Slope": 32}),
    ("MX-28", {"Baud Rate": 34, "Max Voltage Limit": 160, "CCW Angle Limit": 4095,
               "Punch": 0, "P Gain": 32, "Goal Acceleration": 0}),
    ("MX-64", {"Max Voltage Limit": 240, "Goal Torque": 0, "Torque Control Mode Enable": 0}),
    ("MX-106", {"Drive Mode": 0, "Max Voltage Limit": 160, "Resolution Divider": 1}),
])
def test_each_model_s_defaults_are_its_page_s(model, facts):
    """The initial values of each e-manual page's control table (docs/en/dxl/<series>/)."""
    table = by_name(model).by_name
    assert {name: table[name].default for name in facts} == facts


def test_the_layouts_addresses_are_the_pages():
    ax, mx = AX_12A.by_name, by_name("MX-106").by_name
    assert [(ax[n].address, ax[n].size) for n in ("Torque Enable", "Goal Position",
            "Moving Speed", "Present Position", "Present Load", "Lock", "Punch")] == [
        (24, 1), (30, 2), (32, 2), (36, 2), (40, 2), (47, 1), (48, 2)]
    assert [(mx[n].address, mx[n].size) for n in ("Drive Mode", "Multi Turn Offset",
            "D Gain", "Realtime Tick", "Current", "Goal Torque", "Goal Acceleration")] == [
        (10, 1), (20, 2), (26, 1), (50, 2), (68, 2), (71, 2), (73, 1)]
    assert not ax["Torque Enable"].eeprom and ax["Shutdown"].eeprom


# -- dynamixel-sdk's Protocol 1.0 handler drives the emulated bus --------------------------------

sdk = pytest.importorskip("dynamixel_sdk")


@pytest.fixture
def sdk_bus():
    mx = BY_NUMBER_1[29]
    bus = Protocol1Bus([Servo1(1), Servo1(2), Servo1(7, mx), Servo1(8, mx)], baud=1_000_000)
    with DynamixelPtyServer(bus) as server:
        port = sdk.PortHandler(server.port)
        assert port.openPort() and port.setBaudRate(1_000_000)
        yield bus, port, sdk.PacketHandler(1.0)
        port.closePort()


def test_sdk_ping_reads_and_writes(sdk_bus):
    bus, port, ph = sdk_bus
    model, result, error = ph.ping(port, 1)
    assert (model, result, error) == (12, sdk.COMM_SUCCESS, 0)
    assert ph.ping(port, 7)[0] == 29
    assert ph.ping(port, 9)[1] == sdk.COMM_RX_TIMEOUT
    assert ph.read1ByteTxRx(port, 2, 3)[:2] == (2, sdk.COMM_SUCCESS)
    assert ph.read2ByteTxRx(port, 1, 36)[0] == 512
    result, error = ph.write2ByteTxRx(port, 1, 6, 100)
    assert (result, error) == (sdk.COMM_SUCCESS, 0) and bus.servos[1].get("CW Angle Limit") == 100
    result, error = ph.write2ByteTxRx(port, 1, 30, 50)  # below the CW Angle Limit
    assert error == ANGLE_LIMIT and ph.getRxPacketError(error) == \
        "[RxPacketError] Angle limit error!"


def test_sdk_group_sync_write(sdk_bus):
    bus, port, ph = sdk_bus
    group = sdk.GroupSyncWrite(port, ph, 25, 1)
    assert group.addParam(1, [1]) and group.addParam(2, [1])
    assert group.txPacket() == sdk.COMM_SUCCESS
    assert eventually(lambda: bus.servos[1].get("LED") == bus.servos[2].get("LED") == 1)


def test_sdk_bulk_read_of_mx(sdk_bus):
    """GroupBulkRead on MX servos. dynamixel-sdk 4.1.0's GroupBulkRead passes the Protocol 1.0
    bulkReadTx one argument too many (a TypeError); there, the handler's own bulkReadTx and
    readRx are driven with the params GroupBulkRead builds (length, ID, address per servo)."""
    _, port, ph = sdk_bus
    group = sdk.GroupBulkRead(port, ph)
    assert group.addParam(7, 36, 8) and group.addParam(8, 0, 2)
    try:
        assert group.txRxPacket() == sdk.COMM_SUCCESS
        position, model = group.getData(7, 36, 2), group.getData(8, 0, 2)
    except TypeError:
        assert ph.bulkReadTx(port, [8, 7, 36, 2, 8, 0], 6) == sdk.COMM_SUCCESS
        first, result, _ = ph.readRx(port, 7, 8)
        assert result == sdk.COMM_SUCCESS
        second, result, _ = ph.readRx(port, 8, 2)
        assert result == sdk.COMM_SUCCESS
        position, model = first[0] | first[1] << 8, second[0] | second[1] << 8
    assert (position, model) == (2048, 29)


def test_sdk_reads_of_an_ax_bus_at_another_rate_time_out(sdk_bus):
    """A servo answers only at its Baud Rate: at 57600 bps the 1 Mbps bus is silent."""
    _, port, ph = sdk_bus
    assert port.setBaudRate(57600)
    assert ph.read2ByteTxRx(port, 1, 36)[1] == sdk.COMM_RX_TIMEOUT


# -- every verb on the PhantomX-class arm ---------------------------------------------------------

def test_phantomx_arm_runs_every_verb(cli, tmp_path):
    sim = ("--sim", "-p", "phantomx-arm")
    run = cli(*sim, "connect")
    assert run.exit_code == 0, run.stderr
    run = cli(*sim, "identify", "--json")
    assert run.exit_code == 0, run.stderr
    servos = block_of(result(run))["identity"]["servos"]
    assert {s["model"] for s in servos.values()} == {"AX-12A"} and len(servos) == 5
    run = cli(*sim, "detect", "--json")
    assert run.exit_code == 0, run.stderr
    assert cli(*sim, "home", "--yes").exit_code == 0
    run = cli(*sim, "jog", "elbow", "10deg", "--yes", "--json")
    assert run.exit_code == 0, run.stderr
    assert cli(*sim, "torque", "off", "--yes").exit_code == 0
    run = cli(*sim, "register", "get", "elbow", "present_position", "moving_speed", "--json")
    assert run.exit_code == 0, run.stderr
    run = cli(*sim, "register", "set", "elbow", "cw_compliance_slope", "64", "--yes", "--json")
    assert run.exit_code == 0, run.stderr
    assert "64" in run.stdout
    snapshot = tmp_path / "px.json"
    assert cli(*sim, "config", "snapshot", "-o", str(snapshot)).exit_code == 0
    assert "Moving Speed" in snapshot.read_text()
    run = cli(*sim, "config", "diff", str(snapshot))
    assert run.exit_code == 0, run.stderr
    run = cli(*sim, "stream", "--duration", "0.2", "--json")
    assert run.exit_code == 0, run.stderr
    assert '"elbow/voltage":12.0' in run.stdout
    run = cli(*sim, "record", str(tmp_path / "px.mcap"), "--duration", "0.2")
    assert run.exit_code == 0, run.stderr
    assert (tmp_path / "px.mcap").stat().st_size > 0


def test_jog_moves_the_ax_servo_by_its_300_degree_scale(cli):
    bus = Protocol1Bus([Servo1(i) for i in range(1, 6)], baud=1_000_000)
    with DynamixelPtyServer(bus) as server:
        target = f"serial://{server.port}?baud=1000000"
        run = cli("-p", "phantomx-arm", "-t", target, "jog", "elbow", "15deg", "--yes")
        assert run.exit_code == 0, run.stderr
        # 15° is 51.2 steps of 300°/1024 from the middle step, 512
        assert bus.servos[3].get("Goal Position") == 563
        assert eventually(lambda: bus.servos[3].update() or bus.servos[3].position == 563)
        assert bus.servos[1].get("Goal Position") == 512  # only the elbow's goal changed


def test_a_servo_of_a_model_without_a_table_is_refused_even_when_allowed(cli):
    bus = Protocol1Bus([Servo1(i) for i in range(1, 6)], baud=1_000_000)
    bus.servos[3].memory[0:2] = struct.pack("<H", 300)  # an AX-12W: deltoctl has no table
    with DynamixelPtyServer(bus) as server:
        target = f"serial://{server.port}?baud=1000000"
        run = cli("-p", "phantomx-arm", "-t", target, "identify")
        assert run.exit_code == 1 and "model mismatch" in run.stderr
        run = cli("-p", "phantomx-arm", "-t", target, "identify", "--allow-model-mismatch")
    assert run.exit_code == 1, run.output
    assert "elbow (ID 3) reports model number 300" in run.stderr
    assert "not a Protocol 1.0 model deltoctl knows" in run.stderr and "AX-12A" in run.stderr


@pytest.mark.parametrize("sweep", ["", "detect_sweep: true"])
def test_detect_sweeps_every_id_for_servos_the_profile_lacks_only_when_asked(cli, tmp_path,
                                                                              sweep):
    from tests.conftest import REPO

    text = (REPO / "profiles" / "phantomx-arm.yaml").read_text()
    profile = tmp_path / "px.yaml"
    profile.write_text(text.replace("protocol_version: 1.0", f"protocol_version: 1.0\n      "
                                    f"{sweep}"))
    bus = Protocol1Bus([*(Servo1(i) for i in range(1, 6)), Servo1(9, BY_NUMBER_1[29])],
                       baud=1_000_000)
    with DynamixelPtyServer(bus) as server:
        run = cli("-p", str(profile), "-t", f"serial://{server.port}?baud=1000000", "detect",
                  "--json")
    (block,) = json.loads(run.stdout)["blocks"]
    if sweep:
        assert run.exit_code == 3, run.output  # a servo the profile lacks: a warning
        assert block["details"]["unexpected"] == [9] and block["details"]["swept"]
        assert "1 unexpected" in block["summary"] and "ID 9" in run.stdout
    else:
        assert run.exit_code == 0, run.output
        assert block["details"]["unexpected"] == [] and not block["details"]["swept"]
        assert "other IDs not looked for" in block["summary"]
        assert "detect_sweep" in block["summary"]


def test_detect_names_a_servo_answering_in_the_other_protocol(cli):
    run = cli("--sim", "--sim-option", "other_protocol=elbow", "-p", "phantomx-arm",
              "detect", "--json")
    assert run.exit_code == 1  # the profile's servo does not answer in the bus's protocol
    (block,) = json.loads(run.stdout)["blocks"]
    assert block["details"]["other_protocol"] == {"3": "2.0"}
    assert "answering in Protocol 2.0: elbow (ID 3)" in block["summary"]
    run = cli("--sim", "--sim-option", "other_protocol=joint2", "-p", "open-manipulator-x",
              "detect", "--json")
    assert '"12": "1.0"' in run.stdout


def test_a_bad_protocol_version_is_a_usage_error(cli, tmp_path):
    from tests.conftest import REPO

    text = (REPO / "profiles" / "phantomx-arm.yaml").read_text()
    bad = tmp_path / "bad.yaml"
    bad.write_text(text.replace("protocol_version: 1.0", "protocol_version: 3"))
    run = cli("--sim", "-p", str(bad), "identify")
    assert run.exit_code == 2, run.stderr
    assert "protocol_version '3' is not a Dynamixel protocol" in run.stderr


def test_a_goal_outside_the_joint_is_refused_and_a_status_error_says_what_to_do(cli):
    sim = ("--sim", "-p", "phantomx-arm")
    run = cli(*sim, "register", "set", "elbow", "goal_position", "1023", "--yes")
    assert run.exit_code == 5  # 149.7° past the elbow's 1.8 rad: nothing written
    assert "outside its limits" in run.stderr
    run = cli(*sim, "register", "set", "elbow", "cw_compliance_slope", "255", "--yes")
    assert run.exit_code == 2  # the table's range is checked before anything is sent
    assert "CW Compliance Slope 255 is outside the AX-12A's documented range 0..254" \
        in run.stderr and "Traceback" not in run.stderr
    run = cli(*sim, "reboot", "elbow", "--yes")
    assert run.exit_code == 1 and "no REBOOT instruction" in run.stderr


@pytest.fixture
def _trace_off():
    from deltoctl import trace

    yield
    trace.configure(0, None)


@pytest.mark.usefixtures("_trace_off")
def test_the_trace_names_protocol_1_frames(cli, tmp_path):
    assert p1.frame_name(p1.read(3, 36, 8)) == "READ"
    assert p1.frame_name(p1.FRAMES.status(3, 0, bytes(8))) == "STATUS"
    assert p1.frame_name(p1.sync_write(24, 1, {1: b"\x01"})) == "SYNC_WRITE"
    assert p1.frame_name(b"\x00\x01") is None
    assert p1.frame_name(b"\x02\xff\xff\xff\xff\x00\x10") is None  # a 2.0 reply's tail
    log = tmp_path / "wire.ndjson"
    run = cli("--sim", "-p", "phantomx-arm", "--log-file", str(log), "jog", "elbow", "5deg",
              "--yes")
    assert run.exit_code == 0, run.stderr
    names = {record["frame"] for record in map(json.loads, log.read_text().splitlines())
             if record["logger"] == "deltoctl.wire" and "frame" in record}
    assert {"PING", "READ", "SYNC_WRITE"} <= names  # (a reply read in pieces has no name)


def test_register_set_keeps_moving_speed_and_the_angle_limits_in_the_envelope(cli):
    sim = ("--sim", "-p", "phantomx-arm", "--yes")
    fast = cli(*sim, "register", "set", "elbow", "moving_speed", "1023")
    assert fast.exit_code == 5 and "velocity" in fast.stderr, fast.stderr
    # 0 is the servo's greatest speed, uncontrolled
    assert cli(*sim, "register", "set", "elbow", "moving_speed", "0").exit_code == 5
    assert cli(*sim, "register", "set", "elbow", "moving_speed", "400").exit_code == 0
    wheel = cli(*sim, "register", "set", "elbow", "ccw_angle_limit", "0")
    assert wheel.exit_code == 5 and "--allow ccw-angle-limit" in wheel.stderr, wheel.stderr


def test_a_lost_link_is_a_lost_bus_that_reconnects_not_an_error(monkeypatch):
    from deltoctl import open_robot
    from deltoctl.errors import LinkLost

    with open_robot("phantomx-arm", sim=True) as robot:
        driver = robot.blocks[0].driver
        loop = driver.loops["pvl_reader"]

        def gone(*_args, **_kwargs):
            raise LinkLost("the adapter was unplugged")

        monkeypatch.setattr(driver, "read_present", gone)
        monkeypatch.setattr(loop, "due", lambda: True)
        driver.read()
        assert not driver.connected and any("lost" in w for w in driver.warnings)


def test_a_goal_beyond_the_servos_reach_is_refused_before_torque_is_on(tmp_path):
    from deltoctl import open_robot
    from deltoctl.errors import Refused
    from tests.conftest import REPO

    wide = tmp_path / "wide.yaml"
    wide.write_text((REPO / "profiles" / "phantomx-arm.yaml").read_text()
                    .replace("lower: -1.8, upper: 1.8", "lower: -900, upper: 900"))
    bus = Protocol1Bus([Servo1(i) for i in range(1, 6)], baud=1_000_000)
    with DynamixelPtyServer(bus) as server, \
            open_robot(wide, f"serial://{server.port}?baud=1000000") as robot:
        driver = robot.blocks[0].driver
        with pytest.raises(Refused, match=r"elbow.*0\.\.1023"):
            driver.send_goals({"elbow": 800.0}, 1.0)
        assert all(s.get("Torque Enable") == 0 for s in bus.servos.values())


def test_a_bad_detect_sweep_is_named_with_its_file_and_line_by_validate(cli, tmp_path):
    import re

    from tests.conftest import REPO

    text = (REPO / "profiles" / "phantomx-arm.yaml").read_text()
    bad = tmp_path / "bad.yaml"
    bad.write_text(text.replace("protocol_version: 1.0",
                                "protocol_version: 1.0\n      detect_sweep: maybe"))
    for run in (cli("profile", "validate", str(bad)), cli("--sim", "-p", str(bad), "identify")):
        assert run.exit_code == 2, run.output
        assert re.search(r"bad\.yaml:\d+: param 'detect_sweep' of block 'phantomx_arm' is true "
                         r"or false, got 'maybe'", run.stderr), run.stderr
