"""The emulated drive: a real CANopen slave that canopen's own client drives, and the CiA 402
model behind it."""

import time

import pytest

from deltoctl_canopen import codec
from deltoctl_canopen.drive import FAULT, FOLLOWING_ERROR, Drive402
from deltoctl_canopen.nodes import GENERIC_EDS


def test_canopen_base_node_402_drives_it_to_operation_enabled(drives, client):
    from canopen.profiles.p402 import BaseNode402

    node = BaseNode402(2, str(GENERIC_EDS))
    client.add_node(node)
    assert node.sdo[0x1018][1].raw == 0xDE7
    assert node.sdo[0x1018][2].raw == 0x40201
    assert node.sdo[0x1008].raw == "deltoctl generic CiA 402 drive"
    node.nmt.state = "PRE-OPERATIONAL"
    node.setup_402_state_machine()
    node.nmt.state = "OPERATIONAL"
    client.sync.start(0.01)
    try:
        node.state = "OPERATION ENABLED"
        assert node.state == "OPERATION ENABLED"
        node.sdo[0x607A].raw = 3000
        node.controlword = 0x1F
        deadline = time.monotonic() + 2
        while node.sdo[0x6064].raw != 3000 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert node.sdo[0x6064].raw == 3000
        while node.tpdo_values[0x6064] != 3000 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert node.tpdo_values[0x6064] == 3000  # the TPDO on SYNC carries it too
        node.state = "SWITCH ON DISABLED"
        assert node.state == "SWITCH ON DISABLED"
    finally:
        client.sync.stop()


def test_heartbeat_and_nmt(drives, client):
    node = client.add_node(3, str(GENERIC_EDS))
    node.sdo[0x1017].raw = 20
    node.nmt.wait_for_heartbeat(1)
    assert node.nmt.state == "PRE-OPERATIONAL"
    node.nmt.state = "OPERATIONAL"
    node.nmt.wait_for_heartbeat(1)
    node.nmt.wait_for_heartbeat(1)
    assert node.nmt.state == "OPERATIONAL"


def enabled(drive, now=0.0):
    for word in (0x06, 0x07, 0x0F):
        drive.command(word, now)
    assert drive.state == "OPERATION ENABLED"


def test_state_machine_and_fault_reset():
    drive = Drive402(0.0)
    assert codec.state_of(drive.statusword(0.0)) == "SWITCH ON DISABLED"
    drive.command(0x0F, 0.0)  # enable from Switch On Disabled: not a transition
    assert drive.state == "SWITCH ON DISABLED"
    enabled(drive)
    drive.command(0x02, 0.0)  # quick stop, option code 2: on to Switch On Disabled
    assert drive.state == "SWITCH ON DISABLED"
    drive.params[0x605A, 0] = 6
    enabled(drive)
    drive.command(0x02, 0.0)
    assert drive.state == "QUICK STOP ACTIVE"
    drive.fault(0x2310, 0.0)
    assert codec.state_of(drive.statusword(0.0)) == "FAULT"
    drive.command(0x00, 0.0)
    drive.command(0x80, 0.0)  # the rising edge of bit 7
    assert drive.state == "SWITCH ON DISABLED" and drive.error_code == 0


def test_profile_position_ramps_at_the_profile_velocity_and_acceleration():
    drive = Drive402(0.0)
    enabled(drive)
    drive.write(0x607A, 0, 1000, 0.0)
    drive.write(0x6081, 0, 2000, 0.0)  # increments/s
    drive.write(0x6083, 0, 10000, 0.0)  # increments/s²: 0.2 s to full speed
    drive.write(0x6084, 0, 10000, 0.0)
    drive.command(0x1F, 0.0)
    assert drive.statusword(0.0) & codec.SW_SETPOINT_ACK
    assert drive.read(0x6064, 0, 0.1) == 50  # accelerating: a·t²/2
    assert drive.read(0x606C, 0, 0.1) == 1000
    assert drive.read(0x6064, 0, 0.3) == 400  # 200 to full speed, then 2000/s
    assert not drive.statusword(0.69) & codec.SW_TARGET_REACHED  # braking (ends at 0.7 s)
    assert drive.read(0x6064, 0, 0.7) == 1000
    assert drive.statusword(0.7) & codec.SW_TARGET_REACHED
    drive.command(0x0F, 1.0)
    drive.write(0x607A, 0, 500, 1.0)
    drive.command(0x5F, 1.0)  # relative
    assert drive.read(0x6064, 0, 5.0) == 1500


def test_a_new_set_point_while_moving_brakes_and_comes_back():
    from deltoctl_canopen.ramp import Ramp

    ramp = Ramp.plan(0.0, 2000.0, -100.0, 2000, 10000, 10000, 0.0)  # 200 to stop
    positions = [ramp.at(t / 100)[0] for t in range(0, 200)]
    assert max(positions) == pytest.approx(200, abs=1)  # it stops past, then turns
    assert ramp.at(ramp.end) == (-100.0, 0.0)
    assert min(positions) >= -100 - 1e-9  # never beyond the target


def test_homing_current_position_and_error():
    drive = Drive402(0.0)
    enabled(drive)
    drive.write(0x607A, 0, 800, 0.0)
    drive.command(0x1F, 0.0)
    drive.command(0x0F, 1.0)
    drive.write(0x6060, 0, 6, 1.0)
    drive.write(0x607C, 0, 100, 1.0)
    drive.command(0x1F, 1.0)
    word = drive.statusword(1.0)
    assert word & codec.SW_HOMING_ATTAINED and word & codec.SW_TARGET_REACHED
    assert drive.read(0x6064, 0, 1.0) == 100
    drive.command(0x0F, 1.0)
    drive.write(0x6098, 0, 99, 1.0)
    drive.command(0x1F, 1.0)
    assert drive.statusword(1.0) & codec.SW_HOMING_ERROR


def test_a_stalled_axis_faults_on_its_following_error():
    codes = []
    drive = Drive402(0.0, on_fault=codes.append)
    drive.stalled = True
    enabled(drive)
    drive.write(0x607A, 0, 5000, 0.0)
    drive.write(0x6081, 0, 10000, 0.0)
    drive.command(0x1F, 0.0)
    drive.update(0.05)
    assert drive.state == "OPERATION ENABLED"  # 500 behind, within the 1000 window
    drive.update(0.2)
    assert drive.state == FAULT and codes == [FOLLOWING_ERROR]
    assert drive.read(0x603F, 0, 0.2) == FOLLOWING_ERROR
