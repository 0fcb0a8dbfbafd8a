"""The safety envelope is the System's: a move, a command to a joint or a replayed setpoint
outside the joint's limits, soft limits, velocity or effort limit, or beyond max_jog_step is
refused (exit 5) before a byte is sent — whoever calls the System. Each family's emulator,
on its real transport, shows that nothing was written to it; a move within the envelope
still moves."""

from __future__ import annotations

import math

import pytest

from deltoctl.core.system import System
from deltoctl.errors import InvalidInput, Refused
from deltoctl.families.bioscara import codec as bioscara
from deltoctl.families.delto import codec as delto
from deltoctl.families.delto.emulator import DeltoServer, firmware_for_block
from deltoctl.families.dynamixel import codec as dynamixel
from deltoctl.families.dynamixel.control_table import item_named as dynamixel_item
from deltoctl.families.dynamixel.emulator import DynamixelBus, DynamixelPtyServer, Servo
from deltoctl.profile.catalog import load_profile
from deltoctl.sim.i2c_bus import I2CSocketServer
from tests.conftest import eventually, mh5_targets, sim_i2c_bus

NAN = float("nan")
DELTO_WRITES = {delto.SET_DUTY, delto.SET_GPIO, delto.SET_FT_SENSOR_OFFSET}
DYNAMIXEL_WRITES = {dynamixel.WRITE, dynamixel.REG_WRITE, dynamixel.ACTION,
                    dynamixel.SYNC_WRITE, dynamixel.BULK_WRITE}
BIOSCARA_READS = {bioscara.PING, bioscara.ANGLEMOVED, bioscara.GETENCODERRPM}


class Received:
    """The requests an emulator's handler was given, in order: its handler wrapped, so the
    emulator still answers them."""

    def __init__(self, writes: set[int]) -> None:
        self.codes: list[int] = []
        self.writes = writes

    def spy(self, owner: object, method: str, code) -> None:
        original = getattr(owner, method)

        def handle(*args):
            self.codes.append(code(*args))
            return original(*args)

        setattr(owner, method, handle)

    def count(self) -> int:
        return sum(c in self.writes for c in self.codes)


def refused_without_a_write(system: System, received: Received, call, match: str) -> None:
    """``call`` is Refused, and the emulator got no write for it: a read after it (a round
    trip on the same link) comes back after anything the call could have sent."""
    system.read()
    before = received.count()
    with pytest.raises(Refused, match=match):
        call()
    system.read()
    assert received.count() == before


# -- Delto gripper (TCP) ---------------------------------------------------------------------

@pytest.fixture
def hand():
    """A DG-5F-R on loopback TCP: (its System, the SET_* frames it received)."""
    profile = load_profile("dg-5f-right")
    firmware = firmware_for_block(profile.hardware[0])
    received = Received(DELTO_WRITES)
    received.spy(firmware, "handle", lambda data: data[2])
    with DeltoServer(firmware) as server, System(profile, [server.endpoint]) as system:
        yield system, received


def test_a_gripper_refuses_outside_its_envelope_and_sends_nothing(hand):
    system, received = hand
    refused_without_a_write(system, received, lambda: system.move({"rj_dg_2_2": -0.3}),
                            r"rj_dg_2_2 target -0.3000 is outside its limits \[0.0000, 2.0071\]")
    refused_without_a_write(system, received, lambda: system.move({"rj_dg_2_2": 0.6}),
                            r"larger than the profile's max_jog_step 0.5236")
    refused_without_a_write(system, received,
                            lambda: system.move({"rj_dg_2_2": 0.2}, velocity=4.0),
                            r"rj_dg_2_2 velocity 4.0000 is beyond its limit 3.1416")
    # 150 mA × 1.15 N·m/A: the current cap, well inside the joint's 7.5 N·m
    refused_without_a_write(system, received,
                            lambda: system.set_command("rj_dg_2_2/effort", 0.5),
                            r"effort command 0.5000 is beyond the profile's safety cap 0.1725")
    refused_without_a_write(system, received,
                            lambda: system.follow({"rj_dg_2_2": (-0.3, NAN, 0.1)}),
                            "outside its limits")
    # a replayed effort beyond the joint's limit (one beyond the cap is clamped to it)
    refused_without_a_write(system, received,
                            lambda: system.follow({"rj_dg_2_2": (NAN, NAN, 8.0)}),
                            r"effort command 8.0000 is beyond its limit 7.5000")


def test_a_gripper_moves_and_takes_efforts_within_its_envelope(hand):
    system, received = hand
    before = received.count()
    result = system.move({"rj_dg_2_2": 0.2})
    system.stop()
    assert result.settled
    assert system.read()["rj_dg_2_2/position"] == pytest.approx(0.2, abs=math.radians(2))
    assert received.count() > before
    sent = received.count()
    system.set_command("rj_dg_2_2/effort", 0.1)  # inside the cap: one SET_DUTY
    system.read()
    assert received.count() == sent + 1


# -- Dynamixel MH5 (serial over a pty) -------------------------------------------------------

@pytest.fixture
def servos():
    """The MH5's upper body bus on a pty: (its System, the instructions it received)."""
    profile = load_profile("mh5")
    hw = next(h for h in profile.hardware if h.name == "upper_body")
    bus = DynamixelBus([Servo(j.address) for j in hw.joints])
    received = Received(DYNAMIXEL_WRITES)
    received.spy(bus, "handle", lambda device_id, instruction, params: instruction)
    with DynamixelPtyServer(bus) as server, \
            System(profile, [f"upper_body=serial://{server.port}?baud=2000000"],
                   hardware=["upper_body"]) as system:
        yield system, received


def test_a_servo_refuses_outside_its_envelope_and_sends_nothing(servos):
    system, received = servos
    start = system.read()["head_y/position"]
    refused_without_a_write(system, received, lambda: system.move({"head_y": 3.5}),
                            r"head_y target 3.5000 is outside its limits")
    refused_without_a_write(system, received, lambda: system.move({"head_y": start + 0.4}),
                            r"max_jog_step 0.3491")
    refused_without_a_write(system, received,
                            lambda: system.set_command("head_y/position", -3.3),
                            "outside its limits")
    refused_without_a_write(system, received,
                            lambda: system.set_command("head_y/velocity", 6.0),
                            r"velocity command 6.0000 is beyond its limit 5.0000")
    # a replayed goal: the first a step from where the joint is, then from the one before
    refused_without_a_write(system, received,
                            lambda: system.follow({"head_y": (start + 0.4, 1.0, NAN)}),
                            "max_jog_step")
    system.follow({"head_y": (start + 0.3, 1.0, NAN)})
    refused_without_a_write(system, received,
                            lambda: system.follow({"head_y": (start + 0.65, 1.0, NAN)}),
                            "max_jog_step")
    system.stop()


def test_a_servo_moves_within_its_envelope(servos):
    system, received = servos
    start = system.read()["head_y/position"]
    before = received.count()
    result = system.move({"head_y": start + 0.1}, velocity=1.0)
    system.stop()
    assert result.settled and received.count() > before
    assert system.read()["head_y/position"] == pytest.approx(start + 0.1, abs=math.radians(2))


def test_a_servo_goal_written_as_a_register_keeps_to_the_envelope(servos):
    """A Goal Position or Goal Velocity register is a command like a move's."""
    system, received = servos
    driver = system.member("head_y").driver
    here = driver.read_register(52, dynamixel_item("Present Position"))
    refused_without_a_write(system, received,
                            lambda: driver.write_register("head_y", "Goal Position", 4095),
                            r"head_y target 3.1416 is outside its limits")
    refused_without_a_write(system, received,
                            lambda: driver.write_register("head_y", "Goal Position", here + 300),
                            "max_jog_step")
    refused_without_a_write(system, received,
                            lambda: driver.write_register("head_y", "Goal Velocity", 300),
                            r"head_y velocity command 7.1942 is beyond its limit 5.0000")
    assert driver.write_register("head_y", "Goal Position", here + 50) == here + 50
    system.stop()


def test_register_set_of_a_goal_outside_the_envelope_is_refused(cli, mh5_buses):
    servo = mh5_buses["upper_body"].bus.servos[52]
    goal = servo.get("Goal Position")
    result = cli("-p", "mh5", *mh5_targets(mh5_buses), "--yes", "register", "set", "head_y",
                 "Goal Position", "4095")
    assert result.exit_code == 5, result.stderr
    assert "head_y target 3.1416 is outside its limits" in result.stderr
    assert servo.get("Goal Position") == goal


# -- Bioscara arm (I2C over loopback TCP) ----------------------------------------------------

@pytest.fixture
def arm():
    """The arm's bus on loopback, j4 homed (at its upper stop): (its System, the command
    registers its joints received)."""
    profile = load_profile("bioscara-arm")
    smbus = sim_i2c_bus(profile)
    received = Received(set(bioscara.COMMANDS) - BIOSCARA_READS)
    for joint in smbus.devices.values():
        received.spy(joint, "write", lambda data: data[0] if data else -1)
    with I2CSocketServer(smbus) as server, System(profile, [server.url]) as system:
        assert system.member("j4").driver.home(["j4"]) == {"j4": "homed"}
        yield system, received


def test_an_arm_refuses_outside_its_envelope_and_sends_nothing(arm):
    system, received = arm
    start = system.read()["j4/position"]
    refused_without_a_write(system, received, lambda: system.move({"j4": start + 0.2}),
                            "j4 target .* is outside its limits")
    refused_without_a_write(system, received, lambda: system.move({"j4": start - 0.6}),
                            r"max_jog_step 0.5000")
    refused_without_a_write(system, received,
                            lambda: system.move({"j4": start - 0.2}, velocity=11.0),
                            r"j4 velocity 11.0000 is beyond its limit 10.0000")
    # j2 is a prismatic joint of 0.03 m/s: a velocity command beyond it enables nothing
    refused_without_a_write(system, received,
                            lambda: system.set_command("j2/velocity", 0.05),
                            r"j2 velocity command 0.0500 is beyond its limit 0.0300")
    refused_without_a_write(system, received,
                            lambda: system.set_command("j4/position", 3.2),
                            "outside its limits")


def test_an_arm_moves_within_its_envelope(arm):
    system, received = arm
    start = system.read()["j4/position"]
    before = received.count()
    result = system.move({"j4": start - 0.2})
    system.stop()
    assert result.settled and received.count() > before
    assert system.read()["j4/position"] == pytest.approx(start - 0.2, abs=0.01)


# -- the ros2_control mock (generic family) --------------------------------------------------

def test_a_mock_joint_refuses_outside_its_envelope_and_keeps_its_state():
    profile = load_profile("rrbot-gpio")
    with System(profile) as system:
        before = dict(system.read())
        with pytest.raises(Refused, match=r"joint1 target 1.5000 is outside its limits"):
            system.set_command("joint1/position", 1.5)
        with pytest.raises(Refused, match=r"max_jog_step 0.5000"):
            system.move({"joint1": 0.7})
        with pytest.raises(InvalidInput, match="finite"):
            system.move({"joint1": NAN})
        with pytest.raises(InvalidInput, match="at least one joint"):
            system.move({})
        with pytest.raises(InvalidInput, match="not a joint"):
            system.move({"flange_vacuum": 1.0})
        assert system.read() == before  # the mock mirrors a command at once: none came
        system.move({"joint1": 0.4})
        system.set_command("joint2/position", -0.3)
        system.set_command("flange_digital_IOs/digital_output1", 1.0)  # not a joint
        with pytest.raises(Refused, match="max_jog_step"):
            system.move({"joint1": -0.4})
        system.move({"joint1": -0.4}, jog=False)  # a known pose (home's): the limits alone
        with pytest.raises(Refused, match="outside its limits"):
            system.move({"joint1": -1.2}, jog=False)
        after = system.read()
    assert (after["joint1/position"], after["joint2/position"]) == (-0.4, -0.3)
    assert after["flange_digital_IOs/digital_output1"] == 1.0


# -- several blocks: one refused target sends nothing to any block ---------------------------

def test_a_cell_refuses_a_move_of_both_blocks_and_sends_nothing_to_either():
    profile = load_profile("bioscara-dg-3f-m")
    hand_hw = profile.hardware[1]
    smbus = sim_i2c_bus(profile)
    arm = Received(set(bioscara.COMMANDS) - BIOSCARA_READS)
    for joint in smbus.devices.values():
        arm.spy(joint, "write", lambda data: data[0] if data else -1)
    firmware = firmware_for_block(hand_hw)
    hand = Received(DELTO_WRITES)
    hand.spy(firmware, "handle", lambda data: data[2])
    with I2CSocketServer(smbus) as i2c, DeltoServer(firmware) as tcp, \
            System(profile, [f"i2c={i2c.url}", f"gripper={tcp.endpoint}"]) as system:
        assert system.member("j4").driver.home(["j4"]) == {"j4": "homed"}
        values = system.read()
        j4, finger = values["j4/position"], values["j_dg_1_2/position"]
        sent = (arm.count(), hand.count())
        # the gripper's target is fine, the arm's is beyond its stop: neither moves
        with pytest.raises(Refused, match="j4 target"):
            system.move({"j_dg_1_2": finger + 0.1, "j4": j4 + 0.2})
        system.read()
        assert (arm.count(), hand.count()) == sent
        result = system.move({"j_dg_1_2": finger + 0.1, "j4": j4 - 0.1})
        system.stop()
        assert result.settled
        assert arm.count() > sent[0] and hand.count() > sent[1]


def test_a_snapshot_cannot_put_a_mock_joint_outside_its_envelope(cli, tmp_path):
    """A config snapshot is untrusted: a joint position in it is a command like any other."""
    import yaml

    with System(load_profile("rrbot-gpio")) as system:
        before = dict(system.read())
        with pytest.raises(Refused, match=r"joint1 target 5.0000 is outside its limits"):
            system.member("joint1").driver.config_write({
                "flange_analog_IOs": {"analog_output1": 1.5}, "joint1": {"position": 5.0}})
        assert system.read() == before  # refused whole: not even the analog output
    path = tmp_path / "snap.yaml"
    assert cli("-p", "rrbot-gpio", "config", "snapshot", "-o", str(path)).exit_code == 0
    doc = yaml.safe_load(path.read_text())
    doc["blocks"]["RRBotSystemMutipleGPIOs"]["parts"]["joint1"]["position"]["value"] = 5.0
    path.write_text(yaml.safe_dump(doc))
    result = cli("-p", "rrbot-gpio", "config", "restore", str(path), "-y")
    assert result.exit_code == 5, result.stderr
    assert "joint1 target 5.0000 is outside its limits" in result.stdout


# -- a refusal has no effect: no command and no stop, through the library and the CLI -------

def refused_without_an_effect(system: System, received: Received, calls, match: str) -> None:
    """Each of ``calls`` (a Robot's move, jog or home) is Refused, and the device got nothing
    for it: no command, and no stop either (a held command stays held)."""
    system.read()
    before = received.count()
    for call in calls:
        with pytest.raises(Refused, match=match):
            call()
    system.read()
    assert received.count() == before


def test_a_refused_move_leaves_a_gripper_holding_its_grasp(hand):
    from deltoctl.app.robot import Robot

    system, received = hand
    robot = Robot(system)
    system.set_command("rj_dg_2_2/effort", 0.1)  # a grasp, held by its duty
    refused_without_an_effect(system, received, [
        lambda: robot.move({"rj_dg_2_2": -0.3}),
        lambda: robot.move({"rj_dg_2_3": 0.2, "rj_dg_2_2": -0.3}),
        lambda: robot.jog({"rj_dg_2_2": 0.6}),
        lambda: robot.move({"rj_dg_2_2": 0.2}, velocity=4.0),
        lambda: robot.home(velocity=4.0)], "outside its limits|max_jog_step|beyond its limit")
    system.stop()  # this session drove a duty: a stop still sends duty 0
    system.read()
    assert received.codes.count(delto.SET_DUTY) == 2


def test_a_refused_move_leaves_servos_following_their_goals(servos):
    from deltoctl.app.robot import Robot

    system, received = servos
    robot = Robot(system)
    start = system.read()["head_y/position"]
    system.follow({"head_y": (start + 0.1, 1.0, NAN)})  # goals being followed
    refused_without_an_effect(system, received, [
        lambda: robot.move({"head_y": 3.5}),
        lambda: robot.jog({"head_y": 0.4}),
        lambda: robot.move({"head_y": start}, velocity=6.0)],
        "outside its limits|max_jog_step|beyond its limit")
    system.stop()


def test_a_refused_move_leaves_an_arm_joint_running(arm):
    from deltoctl.app.robot import Robot

    system, received = arm
    robot = Robot(system)
    start = system.read()["j4/position"]
    assert system.member("j2").driver.home(["j2"]) == {"j2": "homed"}
    system.set_command("j2/velocity", -0.01)  # j2 running at a speed
    refused_without_an_effect(system, received, [
        lambda: robot.move({"j4": start + 0.2}),
        lambda: robot.jog({"j4": -0.6}),
        lambda: robot.move({"j4": start - 0.2}, velocity=11.0)],
        "outside its limits|max_jog_step|beyond its limit")
    system.stop()


def test_a_refused_move_leaves_the_mock_as_it_was(monkeypatch):
    from deltoctl.app.robot import Robot
    from deltoctl.families.generic.driver import GenericDriver

    calls = count_calls(monkeypatch, GenericDriver)
    with System(load_profile("rrbot-gpio")) as system:
        robot = Robot(system)
        system.set_command("joint1/position", 0.3)
        before, reached = dict(system.read()), len(calls)
        for call in (lambda: robot.move({"joint1": 1.5}), lambda: robot.jog({"joint1": 0.6}),
                     lambda: robot.move({"joint1": 0.4}, velocity=100.0)):
            with pytest.raises(Refused):
                call()
        assert len(calls) == reached and system.read() == before


def count_calls(monkeypatch, cls, methods=("set_command", "move", "stop")) -> list[str]:
    """The calls of ``methods`` (commands and stops) that reach drivers of ``cls``."""
    calls: list[str] = []
    for method in methods:
        original = getattr(cls, method)

        def counted(self, *args, _original=original, _name=method, **kwargs):
            calls.append(_name)
            return _original(self, *args, **kwargs)

        monkeypatch.setattr(cls, method, counted)
    return calls


def test_a_move_of_the_arm_leaves_the_gripper_holding(cli):
    """Only the blocks that moved are stopped: the cell's gripper keeps its grasp while the
    arm moves."""
    from deltoctl.app.robot import Robot

    profile = load_profile("bioscara-dg-3f-m")
    firmware = firmware_for_block(profile.hardware[1])
    hand = Received({delto.SET_DUTY})
    hand.spy(firmware, "handle", lambda data: data[2])
    with I2CSocketServer(sim_i2c_bus(profile)) as i2c, DeltoServer(firmware) as tcp, \
            System(profile, [f"i2c={i2c.url}", f"gripper={tcp.endpoint}"]) as system:
        robot = Robot(system)
        assert system.member("j4").driver.home(["j4"]) == {"j4": "homed"}
        system.set_command("j_dg_1_2/effort", 0.1)
        system.read()
        grasp = hand.count()
        assert robot.jog({"j4": -0.1})["settled"]
        system.read()
        assert hand.count() == grasp


# the CLI: a refused jog or home reaches nothing, from start to exit

def test_a_refused_jog_on_the_cli_sends_a_gripper_nothing(cli):
    profile = load_profile("dg-5f-right")
    firmware = firmware_for_block(profile.hardware[0])
    received = Received(DELTO_WRITES)
    received.spy(firmware, "handle", lambda data: data[2])
    with DeltoServer(firmware) as server:
        for args in (["jog", "rj_dg_2_2", "--to", "-0.3"], ["jog", "rj_dg_2_2", "0.6"],
                     ["jog", "rj_dg_2_2", "0.1", "--velocity", "4"],
                     ["home", "--velocity", "4"]):
            result = cli("-p", "dg-5f-right", "-t", server.endpoint, *args, "--yes")
            assert result.exit_code == 5, result.output + result.stderr
        assert eventually(lambda: len(received.codes) > 0)
        assert received.count() == 0


def test_a_refused_jog_on_the_cli_sends_servos_nothing(cli, mh5_buses):
    bus = mh5_buses["upper_body"].bus
    received = Received(DYNAMIXEL_WRITES)
    received.spy(bus, "handle", lambda device_id, instruction, params: instruction)
    for args in (["jog", "head_y", "--to", "3.5"], ["jog", "head_y", "0.4"],
                 ["jog", "head_y", "0.1", "--velocity", "6"]):
        result = cli("-p", "mh5", *mh5_targets(mh5_buses), "--hardware", "upper_body", *args,
                     "--yes")
        assert result.exit_code == 5, result.output + result.stderr
    assert received.codes and received.count() == 0


def test_a_refused_jog_on_the_cli_sends_an_arm_nothing(cli):
    profile = load_profile("bioscara-arm")
    smbus = sim_i2c_bus(profile)
    received = Received(set(bioscara.COMMANDS) - BIOSCARA_READS)
    for joint in smbus.devices.values():
        received.spy(joint, "write", lambda data: data[0] if data else -1)
    with I2CSocketServer(smbus) as server:
        for args in (["jog", "j4", "0.1"], ["jog", "j4", "--to", "3.5"]):  # not homed
            result = cli("-p", "bioscara-arm", "-t", server.url, *args, "--yes")
            assert result.exit_code == 5, result.output + result.stderr
        assert received.codes and received.count() == 0


def test_a_refused_jog_on_the_cli_reaches_no_mock(cli, monkeypatch):
    """(Closing stops the mock as it stops every block: the mock holds its last command.)"""
    from deltoctl.families.generic.driver import GenericDriver

    calls = count_calls(monkeypatch, GenericDriver, ("set_command", "move"))
    for args in (["jog", "joint1", "--to", "1.5"], ["jog", "joint1", "0.6"],
                 ["home", "--velocity", "100"]):
        result = cli("-p", "rrbot-gpio", *args, "--yes")
        assert result.exit_code == 5, result.output + result.stderr
    assert calls == []


def test_a_replay_of_the_arm_leaves_the_gripper_holding(cli, tmp_path):
    """A replay stops the blocks it commands on the way out, no others."""
    from deltoctl.app.robot import Robot

    profile = load_profile("bioscara-dg-3f-m")
    firmware = firmware_for_block(profile.hardware[1])
    hand = Received({delto.SET_DUTY})
    hand.spy(firmware, "handle", lambda data: data[2])
    out = tmp_path / "arm.mcap"
    with I2CSocketServer(sim_i2c_bus(profile)) as i2c, DeltoServer(firmware) as tcp:
        targets = [f"i2c={i2c.url}", f"gripper={tcp.endpoint}"]
        cell = ["-p", "bioscara-dg-3f-m", *(a for t in targets for a in ("-t", t)), "--yes"]
        assert cli(*cell, "home", "-j", "j4").exit_code == 0
        result = cli(*cell, "jog", "j4", "-0.2", "--record", str(out))
        assert result.exit_code == 0, result.stderr
        with System(profile, targets) as system:
            system.set_command("j_dg_1_2/effort", 0.1)
            system.read()
            grasp = hand.count()
            assert set(Robot(system).replay(out)["joints"]) == {"j4"}
            system.read()
            assert hand.count() == grasp


def test_a_gripper_never_driven_is_left_as_it_is_unless_set_safe(hand):
    """Closing a session that sent no duty sends none; setting the blocks safe (what the
    fleet's agent does after killing a motion verb) sends duty 0 all the same."""
    system, received = hand
    system.read()
    system.stop()
    system.read()
    assert received.codes.count(delto.SET_DUTY) == 0
    system.make_safe()
    system.read()
    assert received.codes.count(delto.SET_DUTY) == 1


def test_a_system_that_allows_no_motion_refuses_every_command_before_a_byte():
    """What the pytest plugin's robot is on hardware without --deltoctl-allow-motion."""
    from deltoctl.app.robot import Robot

    profile = load_profile("dg-5f-right")
    firmware = firmware_for_block(profile.hardware[0])
    received = Received(DELTO_WRITES)
    received.spy(firmware, "handle", lambda data: data[2])
    with DeltoServer(firmware) as server, \
            System(profile, [server.endpoint], allow_motion=False) as system:
        robot = Robot(system)
        for call in (lambda: system.move({"rj_dg_2_2": 0.2}),
                     lambda: system.set_command("rj_dg_2_2/effort", 0.1),
                     lambda: system.follow({"rj_dg_2_2": (0.2, NAN, NAN)}),
                     lambda: robot.jog({"rj_dg_2_2": "1deg"}), lambda: robot.home(),
                     lambda: robot.set_gpio("gpio/output_1", 1.0),
                     lambda: robot.calibrate_ft(samples=5)):
            refused_without_a_write(system, received, call, "allows no motion or actuation")
        system.make_safe()  # stopping is always allowed
        system.read()
        assert received.count() == 1
