"""The Feetech instruction table on the kit's session (host and device, no transport), the
models' tables and encodings, and the emulated servos' behaviour."""

from __future__ import annotations

import time

import pytest

from deltoctl.families.feetech import codec
from deltoctl.families.feetech.emulator import OVERLOAD, FeetechBus, Servo
from deltoctl.families.feetech.models import (
    BAUD_RATES,
    BY_NUMBER,
    LEROBOT_BAUD_RATES,
    MODELS,
    by_bytes,
    config_rules,
    item_named,
)
from deltoctl.servo.collision import collide
from deltoctl.servo.session import NEED_DATA, Done

STS3215, SCS0009 = BY_NUMBER[777], BY_NUMBER[1284]


def _exchange(bus: FeetechBus, device_id: int, instruction: int, params: bytes = b""):
    host = codec.session()
    replies = b"".join(packet for size, rs in bus.serve(host.send(device_id, instruction, params))
                       for _, packet in rs)
    if not host.expecting:
        return Done([], [])
    event = host.receive(replies)
    return host.give_up() if event is NEED_DATA else event


def test_host_and_device_sessions_agree_on_who_answers():
    bus = FeetechBus([Servo(i) for i in (1, 2, 3)])
    done = _exchange(bus, 2, codec.PING)
    assert done.replies == [(2, 0, b"")]
    done = _exchange(bus, codec.BROADCAST_ID, codec.SYNC_READ, codec.sync_read_params(56, 2,
                                                                                    [3, 1]))
    assert [(i, e, d) for i, e, d in done.replies] == [(3, 0, b"\x00\x08"), (1, 0, b"\x00\x08")]
    # a sync write, a broadcast: nobody answers
    assert _exchange(bus, codec.BROADCAST_ID, codec.SYNC_WRITE,
                     codec.sync_write_params(41, 1, {1: b"\x05"})).replies == []
    assert bus.servos[0].get("Acceleration") == 5
    # Response_Status_Level 0: a write is not answered, a read is
    bus.servos[1].memory[8] = 0
    host = codec.session()
    host.level = 0
    assert not host.expected(2, codec.WRITE, b"\x29\x01").ids
    assert bus.serve(codec.write(2, 41, b"\x01")) == [(8, [])]
    assert _exchange(bus, 2, codec.READ, codec.read_params(41, 1)).replies == [(2, 0, b"\x01")]


def test_a_host_waits_for_every_servo_of_a_sync_read():
    host = codec.session()
    host.send(codec.BROADCAST_ID, codec.SYNC_READ, codec.sync_read_params(56, 2, [1, 2]))
    assert host.receive(codec.FRAMES.status(1, 0, b"\x00\x08")) is NEED_DATA
    assert host.waiting == [2]
    done = host.receive(codec.FRAMES.status(2, 0x20, b"\x00\x08"))
    assert done.complete and done.replies[1] == (2, 0x20, b"\x00\x08")  # the error byte kept


def test_models_bytes_and_encodings():
    assert {m.name: m.model_bytes() for m in MODELS} == {
        "STS3215": b"\x09\x03", "STS3250": b"\x09\x0b", "SM8512BL": b"\x08\x2c",
        "SCS0009": b"\x05\x04"}
    assert by_bytes(b"\x05\x04") is SCS0009 and by_bytes(b"\x04\x05") is None
    goal = item_named("goal_position", STS3215)
    assert goal.encode(-100) == (0x8064).to_bytes(2, "little")  # sign-magnitude, bit 15
    assert goal.decode(b"\x64\x80") == -100
    offset = item_named("Homing_Offset", STS3215)
    assert offset.span() == (-2047, 2047)
    with pytest.raises(OverflowError):
        offset.encode(2114)  # LeRobot's "Magnitude 2114 exceeds 2047"
    assert item_named("present_load", STS3215).sign_bit == 10
    assert item_named("Lock", STS3215).address == 55 and item_named("lock", SCS0009).address == 48
    assert item_named("goal_position", SCS0009).encode(512) == b"\x02\x00"
    # one baud table: LeRobot's codes 5-7 kept beside Feetech's, which the servos follow
    assert [BAUD_RATES[c] for c in (5, 6, 7)] == [76_800, 57_600, 38_400]
    assert [LEROBOT_BAUD_RATES[c] for c in (5, 6, 7)] == [57_600, 38_400, 19_200]
    assert config_rules()["Homing_Offset"][2] == "homing-offset"  # a safety item: --allow


def test_eeprom_is_kept_only_while_unlocked():
    servo = Servo(1)
    servo.write(9, b"\x64\x00")  # Min_Position_Limit with Lock 1: applies, not saved
    assert servo.get("Min_Position_Limit") == 100
    servo.power_cycle()
    assert servo.get("Min_Position_Limit") == 0
    servo.write(55, b"\x00")
    servo.write(9, b"\x64\x00")
    servo.write(55, b"\x01")
    servo.power_cycle()
    assert servo.get("Min_Position_Limit") == 100


def test_phase_bit_4_and_the_homing_offset():
    servo = Servo(1)
    servo.actual = 100.0
    servo.write(55, b"\x00")
    servo.write(31, item_named("Homing_Offset", STS3215).encode(300))
    servo.write(18, bytes([servo.get("Phase") | 0x10]))  # full angle: below zero
    assert servo.read(56, 2) == item_named("Present_Position", STS3215).encode(-200)
    servo.write(18, bytes([servo.get("Phase") & ~0x10]))  # one turn: wrapped
    assert servo.read(56, 2) == (4096 - 200).to_bytes(2, "little")
    servo.write(40, b"\x80")  # Torque_Enable 128: the present pose becomes mid-turn
    assert servo.read(56, 2) == (2048).to_bytes(2, "little")
    assert servo.get("Homing_Offset") == 100 - 2048


def test_overload_latches_until_the_power_is_cycled_and_a_voltage_error():
    bus = FeetechBus([Servo(1), Servo(2, volts=16.0)])
    bus.servos[0].latch_overload()
    bus.serve(codec.write(1, 42, (3000).to_bytes(2, "little")))
    time.sleep(0.05)
    done = _exchange(bus, 1, codec.READ, codec.read_params(40, 1))
    assert done.replies == [(1, OVERLOAD, b"\x00")]  # still limp, the error in every status
    assert codec.error_names(OVERLOAD) == ["overload"]
    assert "power is cycled" in codec.error_advice(OVERLOAD)
    bus.servos[0].power_cycle()
    assert _exchange(bus, 1, codec.PING).replies == [(1, 0, b"")]
    assert _exchange(bus, 2, codec.PING).replies == [(2, 0x01, b"")]  # 16 V > 14.0 V limit


def test_servos_sharing_an_id_collide():
    twin = Servo(1)
    twin.actual += 300
    bus = FeetechBus([Servo(1), twin])
    assert _exchange(bus, 1, codec.PING).replies == [(1, 0, b"")]  # identical: they agree
    assert _exchange(bus, 1, codec.READ, codec.read_params(56, 2)).replies == []  # garbled
    assert collide([b"\xff\x0f", b"\xf0\xff\x01"]) == b"\xf0\x0f\x01"


@pytest.fixture
def so101():
    """The SO-101 follower's driver on its emulated bus, and the bus."""
    from deltoctl.families.feetech.driver import FeetechDriver
    from deltoctl.families.feetech.emulator import FeetechPtyServer
    from deltoctl.profile.catalog import load_profile
    from tests.conftest import block_for

    profile = load_profile("so101-follower")
    [hw] = profile.hardware
    bus = FeetechBus([Servo(i) for i in range(1, 7)], baud=1_000_000)
    with FeetechPtyServer(bus) as server:
        driver = FeetechDriver(block_for(profile, hw, f"serial://{server.port}?baud=1000000"))
        driver.configure()
        yield driver, bus
        driver.cleanup()


def test_an_eeprom_write_is_unlocked_and_locked_again_so_the_servo_keeps_it(so101):
    driver, bus = so101
    assert driver.write_register("gripper", "Max_Torque_Limit", 500) == 500
    gripper = bus.servos[5]
    assert gripper.get("Lock") == 1  # locked again
    gripper.power_cycle()
    assert gripper.get("Max_Torque_Limit") == 500  # saved: it was written unlocked
    # a RAM item needs no unlock
    assert driver.write_register("gripper", "acceleration", 254) == 254


def test_a_write_to_a_servo_in_fault_is_a_named_device_fault(so101):
    from deltoctl.errors import DeviceFault

    driver, bus = so101
    bus.servos[2].latch_overload()
    with pytest.raises(DeviceFault, match="overload error") as raised:
        driver.write_register("elbow_flex", "acceleration", 10)
    assert raised.value.code == OVERLOAD and "power is cycled" in raised.value.hint


def test_a_move_settles_once_the_servo_has_stopped_not_when_it_is_near(so101):
    driver, bus = so101
    driver.read()
    result = driver.move({"gripper": 0.3})
    assert result.settled
    assert bus.servos[5].read(66, 1) == b"\x00"  # Moving: arrived, not on its way
    driver.make_safe()  # every servo holds where it is, the torque left on
    assert bus.servos[5].get("Torque_Enable") == 1


def test_a_refused_half_turn_homing_writes_nothing(so101):
    from deltoctl.errors import DeviceError

    driver, bus = so101
    driver.set_torque(["shoulder_pan", "elbow_flex"], True)
    bus.servos[0].set("Homing_Offset", 5)
    elbow = bus.servos[2]
    elbow.set("Phase", elbow.get("Phase") | 0x10)  # full angle: beyond one turn
    elbow.actual = 2048 + 4000.0
    with pytest.raises(DeviceError, match="elbow_flex: its present position 6048"):
        driver.half_turn_homing()
    assert bus.servos[0].get("Homing_Offset") == 5
    assert bus.servos[0].get("Torque_Enable") == 1 and elbow.get("Torque_Enable") == 1


def test_half_turn_homing_resets_the_position_limits(so101):
    driver, bus = so101
    bus.servos[0].set("Min_Position_Limit", 500)
    bus.servos[0].set("Max_Position_Limit", 3000)
    driver.half_turn_homing()
    for servo in bus.servos:
        assert (servo.get("Min_Position_Limit"), servo.get("Max_Position_Limit")) == (0, 4095)
        assert servo.get("Homing_Offset") == 1 and servo.get("Present_Position") == 2047


def test_a_new_id_or_baud_rate_is_locked_again_where_the_servo_now_answers(so101):
    driver, bus = so101
    gripper, wrist = bus.servos[5], bus.servos[4]
    assert driver.write_register("gripper", "ID", 9) == 9
    assert gripper.id == 9 and gripper.get("Lock") == 1
    code = next(c for c, b in BAUD_RATES.items() if b == 500_000)
    assert driver.write_register("wrist_roll", "Baud_Rate", code) == code
    assert wrist.baud == 500_000 and wrist.get("Lock") == 1
    assert driver.port.baudrate == 1_000_000  # the bus's other servos stay at its rate


def test_register_set_keeps_to_an_items_documented_range(so101):
    from deltoctl.errors import InvalidInput

    driver, bus = so101
    with pytest.raises(InvalidInput, match=r"Torque_Enable 128 is outside .*range 0\.\.1"):
        driver.write_register("gripper", "Torque_Enable", 128)
    assert bus.servos[5].get("Homing_Offset") == 0  # 128 would have re-centred it


def test_an_inverse_joints_velocity_and_effort_turn_with_its_position(so101):
    import dataclasses

    driver, _ = so101
    items = driver.model(6).by_name
    data = (items["Present_Position"].encode(2148) + items["Present_Velocity"].encode(100)
            + items["Present_Load"].encode(200))
    driver._take_pvl([(6, 0, data)])
    plain = {k: driver.values[f"gripper/{k}"] for k in ("position", "velocity", "effort")}
    driver.joints[6] = dataclasses.replace(driver.joints[6], inverse=True)
    driver._take_pvl([(6, 0, data)])
    for key in ("velocity", "effort"):
        assert plain[key] > 0 and driver.values[f"gripper/{key}"] == -plain[key]


def test_an_scs_servo_answers_no_sync_read():
    bus = FeetechBus([Servo(1), Servo(2, SCS0009)])
    done = _exchange(bus, codec.BROADCAST_ID, codec.SYNC_READ,
                     codec.sync_read_params(56, 2, [1, 2]))
    assert [i for i, _, _ in done.replies] == [1]  # the STS only
    assert _exchange(bus, 2, codec.READ, codec.read_params(56, 2)).replies == [
        (2, 0, b"\x02\x00")]  # a READ it answers: 512, big-endian


def test_the_driver_reads_an_scs_servo_one_read_at_a_time(tmp_path):
    from deltoctl.families.feetech.driver import FeetechDriver
    from deltoctl.families.feetech.emulator import FeetechPtyServer
    from deltoctl.profile.catalog import load_profile
    from tests.conftest import block_for
    from tests.families.feetech.test_feetech_cli import MIXED

    path = tmp_path / "mixed.yaml"
    path.write_text(MIXED)
    profile = load_profile(path)
    [hw] = profile.hardware
    bus = FeetechBus([Servo(1), Servo(2, SCS0009)], baud=1_000_000)
    heard = []
    serve = bus.serve
    bus.serve = lambda data: heard.append(data) or serve(data)
    with FeetechPtyServer(bus) as server:
        driver = FeetechDriver(block_for(profile, hw, f"serial://{server.port}?baud=1000000"))
        driver.configure()
        try:
            heard.clear()
            values = driver.read()
            assert (values["sts/position"], values["scs/position"]) == (0.0, 0.0)
            assert driver.stats["errors"] == 0
        finally:
            driver.cleanup()
    requests = [r for data in heard for r in codec.session(codec.DEVICE).receive_requests(data)]
    synced = [r for r in requests if r.instruction == codec.SYNC_READ]
    assert synced and all(r.params[2:] == b"\x01" for r in synced)  # the STS's ID alone
    assert any(r.instruction == codec.READ and r.id == 2 for r in requests)


def test_a_move_of_a_servo_not_in_position_mode_is_refused_with_nothing_written(so101):
    from deltoctl.errors import Refused

    driver, bus = so101
    elbow = bus.servos[2]
    elbow.set("Operating_Mode", 1)  # constant speed
    goal = elbow.get("Goal_Position")
    with pytest.raises(Refused, match=r"elbow_flex \(Operating_Mode 1: constant speed\)"):
        driver.move({"elbow_flex": 0.1, "gripper": 0.1})
    assert elbow.get("Goal_Position") == goal and elbow.get("Torque_Enable") == 0
    assert bus.servos[5].get("Torque_Enable") == 0  # nothing moved, the others neither
    elbow.set("Operating_Mode", 0)
    assert driver.move({"elbow_flex": 0.1}).settled
