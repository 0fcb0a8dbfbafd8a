"""calibrate joints through the library on the Koch arm's (Dynamixel) and the SO-101's (Feetech)
emulators: the arm's middle pose and its range moved by hand (the emulators' ``hand`` control
lines), the homing offsets and position limits read back by ROBOTIS' dynamixel-sdk and Feetech's
scservo_sdk, LeRobot's file, nothing written without --allow, and a register changed later
named at the next open."""

from __future__ import annotations

import json
import math

import pytest

from deltoctl import open_robot
from deltoctl.app.joint_calibration import PERMISSIONS, calibration_file
from deltoctl.errors import DeviceError, InvalidInput, Refused
from tests.conftest import eventually

ARM = ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper")
STEPS_PER_DEGREE = 4096 / 360
MIDDLE = 20.0  # degrees: the middle pose, away from the shaft's own middle
LOW, HIGH = -30.0, 50.0  # the range moved by hand, degrees of the shaft
KOCH = ("koch-arm", "koch_follower", "dxl")
SO101 = ("so101-follower", "so_follower", "so_bus")


@pytest.fixture(autouse=True)
def _data_dirs(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    monkeypatch.setenv("HF_LEROBOT_CALIBRATION", str(tmp_path / "lerobot"))


def _by_hand(control, joints=ARM, low=LOW, high=HIGH):
    """A ``done`` for calibrate_joints: each joint turned by hand to ``low``, then to
    ``high`` once every sample saw the low end, then done once it saw the high end."""
    stage = {"step": 0}

    def done(rows) -> bool:
        by = {r["joint"]: r for r in rows}
        if stage["step"] == 0:
            for j in joints:
                control(f"hand {j} {low}")
            stage["step"] = 1
        elif stage["step"] == 1 and all(_at(by[j]["present"], low) for j in joints):
            for j in joints:
                control(f"hand {j} {high}")
            stage["step"] = 2
        return stage["step"] == 2 and all(_at(by[j]["present"], high) for j in joints)

    return done


def _at(steps: int, degrees: float) -> bool:
    """A present position (under the new offset) at a hand's angle of the shaft."""
    return abs(steps - (2047 + (degrees - MIDDLE) * STEPS_PER_DEGREE)) <= 2


def _served(deltoctl_sim, profile):
    """The profile's emulators, the arm (limp) put in its middle pose by hand."""
    buses = deltoctl_sim.buses(profile)
    for joint in ARM:
        deltoctl_sim.control(f"hand {joint} {MIDDLE}")
    return buses


def _calibrate(deltoctl_sim, profile, allow=PERMISSIONS, **options):
    buses = _served(deltoctl_sim, profile)
    with open_robot(profile, buses) as robot:
        result = robot.calibrate_joints(done=_by_hand(deltoctl_sim.control), seconds=30,
                                        allow=allow, **options)
        warnings = robot.warnings()
    return buses, result, warnings


def _dynamixel_registers(url: str) -> dict[int, tuple[int, int, int]]:
    """ID → (Homing Offset, Min, Max Position Limit), read by dynamixel-sdk."""
    sdk = pytest.importorskip("dynamixel_sdk")
    port = sdk.PortHandler(url.split("//", 1)[1].split("?")[0])
    assert port.openPort() and port.setBaudRate(1_000_000)
    ph = sdk.PacketHandler(2.0)
    found = {}
    try:
        for i in range(1, 7):
            values = []
            for address in (20, 52, 48):
                value, result, error = ph.read4ByteTxRx(port, i, address)
                assert (result, error) == (sdk.COMM_SUCCESS, 0)
                values.append(value - (1 << 32) if value >= 1 << 31 else value)
            found[i] = tuple(values)
    finally:
        port.closePort()
    return found


def _feetech_registers(url: str) -> dict[int, tuple[int, int, int]]:
    """ID → (Homing_Offset, Min, Max_Position_Limit), read by scservo_sdk."""
    scs = pytest.importorskip("scservo_sdk")
    port = scs.PortHandler(url.split("//", 1)[1].split("?")[0])
    assert port.openPort() and port.setBaudRate(1_000_000)
    ph = scs.PacketHandler(0)
    found = {}
    try:
        for i in range(1, 7):
            values = []
            for address in (31, 9, 11):
                value, result, _ = ph.read2ByteTxRx(port, i, address)
                assert result == scs.COMM_SUCCESS
                if address == 31 and value & 0x800:  # sign-magnitude, sign in bit 11
                    value = -(value & 0x7FF)
                values.append(value)
            found[i] = tuple(values)
    finally:
        port.closePort()
    return found


def _refused(deltoctl_sim, joint: str) -> bool:
    """Whether a hand line is refused because the joint's torque is on."""
    try:
        deltoctl_sim.control(f"hand {joint} 10")
    except InvalidInput as exc:
        return "its torque is on" in exc.message
    return False


PEERS = {"koch-arm": _dynamixel_registers, "so101-follower": _feetech_registers}


@pytest.mark.parametrize(("profile", "robot_type", "bus"), [KOCH, SO101])
def test_the_calibration_is_written_and_the_sdk_reads_it_back(deltoctl_sim, profile,
                                                              robot_type, bus, tmp_path):
    buses, result, warnings = _calibrate(deltoctl_sim, profile, lerobot="arm1")
    assert result["written"] and result["torque"] == "off"
    rows = {r["joint"]: r for r in result["joints"]}
    for r in rows.values():
        assert r["written"] == "verified"
        # the middle pose reads the middle of the turn: its offset moved it MIDDLE degrees
        assert abs(abs(r["homing_offset"]) - MIDDLE * STEPS_PER_DEGREE) <= 2
        assert _at(r["range_min"], LOW) and _at(r["range_max"], HIGH)
        assert math.isclose(math.degrees(r["lower"]), LOW - MIDDLE, abs_tol=0.2)
    peer = PEERS[profile](buses[bus])
    assert peer == {r["id"]: (r["homing_offset"], r["range_min"], r["range_max"])
                    for r in rows.values()}
    lerobot = json.loads((tmp_path / "lerobot" / "robots" / robot_type / "arm1.json")
                         .read_text())
    assert list(lerobot) == list(ARM)
    assert lerobot["elbow_flex"] == {k: rows["elbow_flex"][k] for k in
                                     ("id", "drive_mode", "homing_offset", "range_min",
                                      "range_max")}
    assert result["lerobot_file"].endswith(f"robots/{robot_type}/arm1.json")
    saved = json.loads(calibration_file(profile).read_text())
    assert saved["blocks"][rows["gripper"]["block"]]["gripper"]["range_max"] == \
        rows["gripper"]["range_max"]
    # the range moved is short of every limit of the profile: named per joint
    assert {w.split(":")[0] for w in warnings if "the range moved" in w} == set(ARM)
    for joint in ARM:  # back in the middle pose: it reads the profile's zero now
        deltoctl_sim.control(f"hand {joint} {MIDDLE}")
    with open_robot(profile, buses) as robot:
        assert robot.calibration_warnings == []
        assert eventually(lambda: all(abs(robot.read()[f"{j}/position"]) < 0.005 for j in ARM))


@pytest.mark.parametrize("profile", ["koch-arm", "so101-follower"])
def test_without_allow_nothing_is_written_to_the_servos(deltoctl_sim, profile, monkeypatch):
    from deltoctl.families.dynamixel import emulator as dxl
    from deltoctl.families.feetech import emulator as feetech

    writes = []
    for module, torque in ((dxl, 64), (feetech, 40)):
        original = module.Servo.write

        def counted(servo, address, data, original=original, torque=torque):
            if address != torque:
                writes.append((servo.id, address))
            return original(servo, address, data)

        monkeypatch.setattr(module.Servo, "write", counted)
    buses, result, warnings = _calibrate(deltoctl_sim, profile, allow=())
    assert writes == []
    assert not result["written"]
    assert {r["written"] for r in result["joints"]} == {"not written"}
    assert any(w.startswith("not written to the servos") and "--allow homing-offset" in w
               for w in warnings)
    bus = next(iter(buses.values()))
    assert {v[0] for v in PEERS[profile](bus).values()} == {0}  # the offsets as they were
    # the file was saved, a record the servos were not given: never compared
    assert json.loads(calibration_file(profile).read_text())["written"] is False
    with open_robot(profile, buses) as robot:
        assert robot.calibration_warnings == []


@pytest.mark.parametrize(("profile", "bus", "register"), [
    ("koch-arm", "dxl", "Max Position Limit"), ("so101-follower", "so_bus", "Max_Position_Limit")])
def test_a_register_changed_later_is_a_warning_naming_joint_and_register(deltoctl_sim, cli,
                                                                        profile, bus, register):
    buses, _, _ = _calibrate(deltoctl_sim, profile)
    with open_robot(profile, buses) as robot:
        assert robot.calibration_warnings == []
        robot.write_register("elbow_flex", "max_position_limit", 3000)
    result = cli("-p", profile, "-t", f"{bus}={buses[bus]}", "identify")
    assert result.exit_code == 3, result.output
    assert f"elbow_flex: {register} is 3000, its calibration" in result.stderr
    with open_robot(profile, buses) as robot:
        [warning] = robot.calibration_warnings
        assert warning.startswith(f"elbow_flex: {register} is 3000")
        assert warning in robot.warnings()


def test_a_joint_not_moved_is_named_and_nothing_written(deltoctl_sim):
    buses = _served(deltoctl_sim, "so101-follower")
    with open_robot("so101-follower", buses) as robot, pytest.raises(
            DeviceError, match="not moved through a range: shoulder_pan;"):
        robot.calibrate_joints(done=_by_hand(deltoctl_sim.control, ARM[1:]), seconds=30,
                               allow=PERMISSIONS)
    assert {v[0] for v in _feetech_registers(buses["so_bus"]).values()} == {0}
    assert not calibration_file("so101-follower").exists()


def test_some_permissions_only_are_refused_and_unknown_ones_named(deltoctl_sim):
    buses = deltoctl_sim.buses("koch-arm")
    with open_robot("koch-arm", buses) as robot:
        with pytest.raises(Refused, match="--allow max-position-limit"):
            robot.calibrate_joints(seconds=1, allow=["homing-offset", "min-position-limit"])
        with pytest.raises(InvalidInput, match="--allow homing-ofset: not a permission"):
            robot.calibrate_joints(seconds=1, allow=["homing-ofset"])
        with pytest.raises(InvalidInput, match="--full-turn elbow: not a calibrated joint"):
            robot.calibrate_joints(seconds=0.1, full_turn=["elbow"])


def test_full_turn_joints_take_the_whole_turn(deltoctl_sim):
    buses = _served(deltoctl_sim, "so101-follower")
    with open_robot("so101-follower", buses) as robot:
        result = robot.calibrate_joints(done=_by_hand(deltoctl_sim.control, ARM[:-1]),
                                        seconds=30, allow=PERMISSIONS, full_turn=["gripper"])
    gripper = result["joints"][-1]
    assert (gripper["range_min"], gripper["range_max"], gripper["check"]) == \
        (0, 4095, "full turn")


@pytest.mark.parametrize("profile", ["koch-arm", "so101-follower", "phantomx-arm"])
def test_a_hand_turns_a_limp_servo_and_not_one_whose_torque_is_on(deltoctl_sim, profile):
    buses = deltoctl_sim.buses(profile)
    with open_robot(profile, buses) as robot:
        joint = robot.profile.hardware[0].joints[1].name
        assert "turned by hand to 45°" in deltoctl_sim.control(f"hand {joint} 45")
        assert eventually(lambda: math.isclose(robot.read()[f"{joint}/position"],
                                               math.radians(45), abs_tol=0.02))
        robot.torque([joint], True)
        assert eventually(lambda: _refused(deltoctl_sim, joint))
    for line, message in (("hand nowhere 10", "not a servo joint"),
                          (f"hand {joint} far", "DEGREES must be degrees"),
                          (f"sweep {joint} 0 10", "takes JOINT FROM TO SECONDS"),
                          (f"sweep {joint} 0 10 -1", "SECONDS must be")):
        with pytest.raises(InvalidInput, match=message):
            deltoctl_sim.control(line)


def test_a_robot_on_its_own_simulators_runs_control_lines(deltoctl_sim):
    with open_robot("koch-arm", sim=True) as robot:
        assert "swept by hand" in robot.control("sweep gripper 0 30 0.1")
        assert eventually(lambda: math.isclose(robot.read()["gripper/position"],
                                               math.radians(30), abs_tol=0.01))
        result = robot.calibrate_joints(seconds=2, hand=["hand gripper 0"],
                                        full_turn=ARM[:-1])
        assert result["file"] == str(calibration_file("koch-arm", simulated=True))
        assert result["joints"][-1]["range_max"] - result["joints"][-1]["range_min"] > 300
    with open_robot("koch-arm", deltoctl_sim.buses("koch-arm")) as robot:
        with pytest.raises(InvalidInput, match="no simulator of this robot"):
            robot.control("hand gripper 0")
        robot.torque(["gripper"], True)
        assert eventually(lambda: _refused(deltoctl_sim, "gripper"))
        with pytest.raises(InvalidInput, match="no simulator of this robot"):
            robot.calibrate_joints(seconds=1, hand=["hand gripper 0"])
        assert _refused(deltoctl_sim, "gripper")  # its torque left on: nothing was done


@pytest.mark.parametrize("text", ["not json", "[]", '{"format": "deltoctl joint calibration", '
                                  '"blocks": {"koch_arm": {"gripper": {"range_max": "x"}}}}'])
def test_a_bad_calibration_file_is_a_warning_not_a_failure(deltoctl_sim, text):
    path = calibration_file("koch-arm")
    path.parent.mkdir(parents=True)
    path.write_text(text)
    with open_robot("koch-arm", deltoctl_sim.buses("koch-arm")) as robot:
        [warning] = robot.warnings()
    assert warning.startswith(f"calibration not checked: {path}: not a")


MIXED = """
name: mixed
buses:
  b: serial:///dev/ttyUSB0?baud=1000000
ros2_control:
  - name: mixed
    type: system
    plugin: feetech_sts_hardware/FeetechSTSHardware
    family: feetech
    bus: b
    joints:
      - name: sts
        limits: {lower: -3, upper: 3, velocity: 5, effort: 3}
        command_interfaces: [position]
        state_interfaces: [position, velocity, effort]
        params: {id: 1, model: STS3215}
      - name: gripper
        limits: {lower: -2, upper: 2, velocity: 5, effort: 1}
        command_interfaces: [position]
        state_interfaces: [position, velocity, effort]
        params: {id: 2, model: SCS0009}
"""


def _writes(monkeypatch) -> list[int]:
    """Every register write the emulators take from now on (addresses)."""
    from deltoctl.families.dynamixel import emulator as dxl
    from deltoctl.families.dynamixel import emulator1 as dxl1
    from deltoctl.families.feetech import emulator as feetech

    writes: list[int] = []
    for cls in (dxl.Servo, dxl1.Servo1, feetech.Servo):
        original = cls.write

        def counted(servo, address, data, original=original):
            writes.append(address)
            return original(servo, address, data)

        monkeypatch.setattr(cls, "write", counted)
    return writes


@pytest.mark.parametrize(("profile", "named"), [
    ("phantomx-arm", "phantomx_arm: its servos have no homing offset register"),
    ("mixed", "mixed: gripper has no homing offset register")])
def test_a_block_that_cannot_be_calibrated_is_refused_before_anything_is_sent(
        profile, named, tmp_path, monkeypatch):
    if profile == "mixed":  # an SCS0009 has no Homing_Offset
        profile = tmp_path / "mixed.yaml"
        profile.write_text(MIXED)
    told = []
    with open_robot(profile, sim=True) as robot:
        writes = _writes(monkeypatch)
        with pytest.raises(InvalidInput, match=f"nothing done: cannot calibrate {named}"):
            robot.calibrate_joints(seconds=1, allow=PERMISSIONS, confirm=told.append)
        robot.identify()  # its replies come after any write sent before them
        assert writes == [] and told == []


@pytest.mark.parametrize("bad", ["../x", "a/b", ".hidden", "my arm", ""])
def test_a_bad_id_is_refused_before_anything_is_read(deltoctl_sim, bad, monkeypatch):
    told = []
    with open_robot("koch-arm", deltoctl_sim.buses("koch-arm")) as robot:
        writes = _writes(monkeypatch)
        for options in ({"name": bad}, {"lerobot": bad}):
            with pytest.raises(InvalidInput, match="must be a plain name"):
                robot.calibrate_joints(seconds=1, allow=PERMISSIONS, confirm=told.append,
                                       **options)
        assert writes == [] and told == []
    assert not calibration_file("koch-arm").exists()


def test_a_profile_named_with_a_slash_keeps_its_file_in_the_data_dir(tmp_path):
    from deltoctl.data_paths import user_data_dir
    from tests.conftest import REPO

    text = (REPO / "profiles" / "koch-arm.yaml").read_text()
    assert "\nname: koch-arm\n" in text
    path = tmp_path / "escape.yaml"
    path.write_text(text.replace("\nname: koch-arm\n", "\nname: ../../x/y\n"))
    with open_robot(path, sim=True) as robot:
        result = robot.calibrate_joints(seconds=1, hand=["hand gripper 30"], full_turn=ARM[:-1],
                                        lerobot="arm")
    saved = user_data_dir("calibration", "sim") / "%2E%2E%2F%2E%2E%2Fx%2Fy.json"
    assert result["file"] == str(saved) and saved.is_file()
    assert calibration_file("../../x/y", simulated=True) == saved
    assert [p for p in tmp_path.rglob("*.json") if "calibration" in str(p)] == [saved]


@pytest.mark.parametrize(("text", "says"), [
    ("[" * 200_000, "not a calibration file (nested too deep)"),
    (" " * (1 << 20) + "{}", "larger than 1 MiB")])
def test_a_deep_or_large_calibration_file_is_a_warning(deltoctl_sim, text, says):
    path = calibration_file("koch-arm")
    path.parent.mkdir(parents=True)
    path.write_text(text)
    with open_robot("koch-arm", deltoctl_sim.buses("koch-arm")) as robot:
        [warning] = robot.warnings()
    assert warning.startswith(f"calibration not checked: {path}: {says}")


def test_the_middle_pose_is_read_before_the_torque_goes_off(deltoctl_sim, monkeypatch):
    from deltoctl.families.dynamixel.driver import DynamixelDriver

    calls = []
    for name in ("middle_offsets", "set_torque"):
        original = getattr(DynamixelDriver, name)

        def spied(driver, *args, original=original, name=name):
            calls.append(name if name == "middle_offsets" else f"torque {args[1]}")
            return original(driver, *args)

        monkeypatch.setattr(DynamixelDriver, name, spied)
    _calibrate(deltoctl_sim, "koch-arm")
    assert calls.index("middle_offsets") < calls.index("torque False")


def test_a_register_that_does_not_hold_is_a_failure_naming_it(deltoctl_sim, monkeypatch):
    from deltoctl.families.dynamixel import emulator as dxl

    original = dxl.Servo.write

    def deaf(servo, address, data):  # elbow_flex (ID 3) keeps its Homing Offset (20)
        if address == 20 and servo.get("ID") == 3:
            return 0
        return original(servo, address, data)

    monkeypatch.setattr(dxl.Servo, "write", deaf)
    with pytest.raises(DeviceError, match=r"did not hold: elbow_flex: Homing Offset reads 0 "
                                          r"after -?\d+ was written; not saved"):
        _calibrate(deltoctl_sim, "koch-arm")
    assert not calibration_file("koch-arm").exists()


def test_two_arms_of_one_profile_each_have_their_file(deltoctl_sim):
    buses, left, _ = _calibrate(deltoctl_sim, "koch-arm", name="left")
    assert left["file"] == str(calibration_file("koch-arm", name="left"))
    for joint in ARM:  # the other arm: another range
        deltoctl_sim.control(f"hand {joint} {MIDDLE}")
    with open_robot("koch-arm", buses) as robot:
        assert robot.calibration_warnings == []
        right = robot.calibrate_joints(done=_by_hand(deltoctl_sim.control, low=LOW + 10,
                                                     high=HIGH - 10), seconds=30,
                                       allow=PERMISSIONS, name="right")
    assert right["file"] == str(calibration_file("koch-arm", name="right"))
    assert left["joints"][0]["range_min"] != right["joints"][0]["range_min"]
    with open_robot("koch-arm", buses) as robot:  # the servos match the right arm's file
        assert robot.calibration_warnings == []
        robot.write_register("elbow_flex", "max_position_limit", 3000)
    with open_robot("koch-arm", buses) as robot:  # named against the closest file
        [warning] = robot.calibration_warnings
        assert warning.startswith("elbow_flex: Max Position Limit is 3000")
        assert "right.json" in warning
