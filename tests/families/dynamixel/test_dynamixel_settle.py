"""A Dynamixel move settles when its servos say they stopped (Moving, 122, reads 0) within
tolerance of their goals, or is unsettled when its time runs out, naming where each joint
ended."""

from __future__ import annotations

import json
import math

import pytest

import deltoctl
from deltoctl.families.dynamixel.emulator import Servo

STEP = 2 * math.pi / 4096  # one raw position step, rad


def _quick_timeout(tmp_path, seconds: float = 0.3):
    """The koch-arm with a short home_timeout: a move that cannot arrive gives up soon."""
    from deltoctl.profile.catalog import resolve

    text = resolve("koch-arm").read_text().replace("home_timeout: 5",
                                                        f"home_timeout: {seconds}")
    path = tmp_path / "koch-arm.yaml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("degrees", [3, 10])
def test_a_jog_ends_at_its_goal_once_the_servo_says_it_stopped(degrees):
    with deltoctl.open_robot("koch-arm", sim=True) as robot:
        robot.home()
        report = robot.jog({"elbow_flex": f"{degrees}deg"})
        joint = report["blocks"][0]["joints"]["elbow_flex"]
        moving = robot.registers("elbow_flex", ["Moving"])["items"][0]["value"]
    assert report["settled"] is True and joint["settled"] is True
    assert joint["target"] == pytest.approx(math.radians(degrees))
    # at the goal, not merely within the profile's 3° tolerance of it
    assert joint["position"] == pytest.approx(math.radians(degrees), abs=2 * STEP)
    assert moving == 0
    assert report["seconds"] >= 0.05  # the profile takes 0.1 s at least: not settled at once


def test_a_stalled_servo_is_unsettled_when_the_time_runs_out(cli, tmp_path):
    profile = str(_quick_timeout(tmp_path))
    result = cli("-p", profile, "--sim", "--sim-option", "stall=elbow_flex", "jog",
                 "elbow_flex", "10deg", "--yes", "--json")
    assert result.exit_code == 1, result.stderr
    envelope = json.loads(result.stdout)
    report, joint = envelope["result"], envelope["blocks"][0]["joints"]["elbow_flex"]
    assert report["settled"] is False and report["unsettled"] == ["elbow_flex"]
    assert joint["settled"] is False and joint["position"] == pytest.approx(0.0, abs=2 * STEP)
    said = cli("-p", profile, "--sim", "--sim-option", "stall=elbow_flex", "jog",
               "elbow_flex", "10deg", "--yes")
    assert said.exit_code == 1
    assert "did not settle: elbow_flex at 0.00°, its target 10.00°" in said.stderr


def test_a_goal_sets_moving_when_it_is_written_however_close():
    servo = Servo(1)
    servo.write(64, bytes([1]))  # torque on
    servo.write(116, (2047 + 1).to_bytes(4, "little"))
    assert servo.memory[122] == 1
    servo.stalled = True
    servo.write(116, (2047 + 100).to_bytes(4, "little"))
    servo.read(132, 4)
    assert servo.memory[122] == 1 and servo.get("Present Position") < 2047 + 100


def test_a_port_lost_during_a_move_ends_it_unsettled_and_reads_raise_link_lost(tmp_path):
    from deltoctl.errors import LinkLost

    with deltoctl.open_robot(_quick_timeout(tmp_path), sim=True) as robot:
        robot.home()
        driver = robot.system.members[0].driver
        result = driver.move({"elbow_flex": math.radians(10)},
                             progress=lambda _: driver._lost(OSError("unplugged")))
        assert result.settled is False and "elbow_flex" in result.unsettled
        assert driver.connected is False and driver.port is None
        with pytest.raises(LinkLost):
            driver.read_registers("elbow_flex", ["Moving"])
        with pytest.raises(LinkLost):
            driver.set_torque(["elbow_flex"], True)
