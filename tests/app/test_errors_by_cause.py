"""A script tells failures apart by their class, imported from ``deltoctl``: a refusal of the
envelope, a device that does not answer, one that answers with an error of its own (its
code), each with the CLI's exit code."""

from __future__ import annotations

import pytest

import deltoctl
from deltoctl import DeviceFault, NoAnswer, OutsideEnvelope, Refused


def test_the_errors_are_the_public_api_s():
    from deltoctl import errors

    for name in ("DeltoctlError", "InvalidInput", "DeviceError", "Unreachable", "Refused",
                 "NotHomed", "OutsideEnvelope", "ProtocolError", "NoAnswer", "DeviceFault",
                 "LinkLost", "ProfileError"):
        assert getattr(deltoctl, name) is getattr(errors, name)
        assert name in deltoctl.__all__


@pytest.mark.parametrize("call", [
    lambda robot: robot.move({"rj_dg_2_2": -0.3}),  # outside its limits [0°, 115°]
    lambda robot: robot.move({"rj_dg_2_2": 0.2}, velocity=100.0),  # beyond its velocity limit
])
def test_a_target_outside_the_envelope_is_outside_envelope_exit_5(call):
    with deltoctl.open_robot("dg-5f-right", sim=True) as robot, \
            pytest.raises(OutsideEnvelope) as refused:
        call(robot)
    assert isinstance(refused.value, Refused) and refused.value.exit_code == 5


def test_a_refusal_that_is_no_limit_is_not_outside_envelope():
    with deltoctl.open_robot("bioscara-arm", sim=True) as robot, \
            pytest.raises(Refused) as refused:
        robot.move({robot.profile.joints()[0].name: 0.01})  # not homed yet
    assert not isinstance(refused.value, OutsideEnvelope)


def test_a_missing_servo_is_no_answer():
    with deltoctl.open_robot("mh5", sim={"missing": ("head_y",)}, hardware=["upper_body"]) \
            as robot, pytest.raises(NoAnswer, match=r"head_y \(ID 52\) does not answer") as silent:
        robot.registers("head_y", ["present_temperature"])
    assert silent.value.exit_code == 1


def test_a_servo_s_error_is_a_device_fault_with_its_code():
    with deltoctl.open_robot("mh5", sim=True, hardware=["upper_body"]) as robot:
        robot.torque("head_p", True)  # EEPROM is locked while the torque is on
        with pytest.raises(DeviceFault, match=r"refused to write Max Position Limit") as fault:
            robot.write_register("head_p", "max_position_limit", 3000)
    assert fault.value.code == 7  # Dynamixel's access error
    assert fault.value.exit_code == 1
