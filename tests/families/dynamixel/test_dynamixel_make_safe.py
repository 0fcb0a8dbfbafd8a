"""Setting the blocks safe (what the fleet's agent does after killing a motion verb): every
servo of the block stops where it is, though this session moved none, and keeps its torque
(an arm must not fall)."""

from __future__ import annotations

from deltoctl.core.system import System
from deltoctl.families.dynamixel.emulator import DynamixelBus, DynamixelPtyServer, Servo
from deltoctl.families.dynamixel.emulator import _model_of as model_of
from deltoctl.families.dynamixel.ros2_control import servo_ids
from deltoctl.profile.catalog import load_profile
from tests.conftest import eventually

TORQUE, PROFILE_VELOCITY, GOAL, PRESENT = 64, 112, 116, 132


def test_set_safe_stops_every_servo_where_it_is_with_its_torque_on():
    profile = load_profile("koch-arm")
    hw = profile.hardware[0]
    bus = DynamixelBus([Servo(i, model=model_of(hw, j))
                        for i, j in servo_ids(profile, hw).items()])
    with DynamixelPtyServer(bus) as server:
        moving = next(iter(bus.servos.values()))
        for address, value in ((TORQUE, b"\x01"), (PROFILE_VELOCITY, (2).to_bytes(4, "little")),
                               (GOAL, (4000).to_bytes(4, "little"))):
            assert moving.write(address, value) == 0  # a slow move a killed process started
        with System(profile, [f"dxl=serial://{server.port}?baud=1000000"]) as system:
            system.stop()  # its own stop: it moved nothing, so it sends nothing
            assert moving.get("Goal Position") == 4000
            system.make_safe()  # a sync write: no reply
            assert eventually(lambda: moving.get("Goal Position") != 4000, timeout=10.0)
            here = int.from_bytes(moving.read(PRESENT, 4)[1], "little")
            assert abs(moving.get("Goal Position") - here) <= 20  # where it was, at 2/s
            assert moving.get("Torque Enable") == 1
