"""LeRobot's calibration file: read as the so_arm101_ros2_control plugin reads it (the block's
calibration_file), positions converted exactly as LeRobot's bus converts them, and written
back in its format at its default location."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from deltoctl import open_robot
from deltoctl.errors import InvalidInput, Refused
from deltoctl.families.feetech import calibration as cal
from deltoctl.profile.catalog import load_profile

SAMPLE = Path(__file__).parent / "assets" / "so101_follower.json"


def test_the_three_modes_convert_as_lerobot_does():
    motors = cal.load(SAMPLE)
    pan, gripper = motors["shoulder_pan"], motors["gripper"]
    assert pan == cal.MotorCalibration(1, 0, 555, 765, 3465)
    # DEGREES: centred on the range's middle, unclamped, 4095 steps to 360°
    assert cal.normalize(2115, pan, cal.DEGREES) == 0.0
    assert cal.normalize(0, pan, cal.DEGREES) == pytest.approx(-2115 * 360 / 4095)
    # RANGE_M100_100 and RANGE_0_100 clamp to the range; drive_mode inverts
    assert cal.normalize(765, pan, cal.RANGE_M100_100) == -100.0
    assert cal.normalize(0, pan, cal.RANGE_M100_100) == -100.0
    assert cal.normalize(2765, gripper, cal.RANGE_0_100) == 50.0
    inverted = cal.MotorCalibration(6, 1, 0, 2030, 3500)
    assert cal.normalize(2765, inverted, cal.RANGE_0_100) == 50.0
    assert cal.normalize(2030, inverted, cal.RANGE_0_100) == 100.0
    # back to steps: bounded, truncated toward zero (LeRobot's int())
    assert cal.unnormalize(150.0, gripper, cal.RANGE_0_100) == 3500
    assert cal.unnormalize(33.3, gripper, cal.RANGE_0_100) == int(33.3 / 100 * 1470 + 2030)
    assert cal.unnormalize(10.0, pan, cal.DEGREES) == int(10 * 4095 / 360 + 2115)
    with pytest.raises(InvalidInput, match="range_min = range_max"):
        cal.normalize(1, cal.MotorCalibration(1, 0, 0, 5, 5), cal.DEGREES)


def test_a_bad_calibration_file_is_one_clear_error(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text('{"gripper": {"id": 6}}')
    with pytest.raises(InvalidInput, match="must have the integers id, drive_mode"):
        cal.load(bad)
    bad.write_text("{")
    with pytest.raises(InvalidInput, match="not a calibration file"):
        cal.load(bad)


def _calibrated_profile(tmp_path: Path) -> Path:
    text = (Path(load_profile("so101-follower").source).read_text()
            .replace("      serial_baudrate: 1000000\n",
                     "      serial_baudrate: 1000000\n"
                     f"      calibration_file: {SAMPLE.name}\n"))
    text = text.replace("params: {id: 6, model: STS3215}",
                        "params: {id: 6, model: STS3215, norm_mode: range_0_100}")
    text = text.replace("{lower: -0.174533, upper: 1.74533,", "{lower: 0, upper: 100,")
    path = tmp_path / "so101.yaml"
    path.write_text(text)
    (tmp_path / SAMPLE.name).write_text(SAMPLE.read_text())
    return path


def test_positions_follow_the_calibration_file(tmp_path):
    with open_robot(_calibrated_profile(tmp_path), sim=True) as robot:
        values = robot.read()
    # the emulated servos sit at step 2048
    assert values["shoulder_pan/position"] == pytest.approx(
        math.radians((2048 - (765 + 3465) / 2) * 360 / 4095))
    assert values["gripper/position"] == pytest.approx((2048 - 2030) / 1470 * 100)


def test_the_servos_calibration_is_written_in_lerobots_format(tmp_path, monkeypatch):
    monkeypatch.setenv("HF_LEROBOT_CALIBRATION", str(tmp_path / "cal"))
    path = cal.default_path("my_awesome_follower_arm")
    assert path == tmp_path / "cal" / "robots" / "so_follower" / "my_awesome_follower_arm.json"
    assert cal.default_path("x", leader=True).parts[-3:] == ("teleoperators", "so_leader",
                                                             "x.json")
    with open_robot("so101-follower", sim=True) as robot:
        driver = robot.blocks[0].driver
        driver.write_register("gripper", "min_position_limit", 2030)
        motors = driver.lerobot_calibration()
    cal.save(path, motors)
    data = json.loads(path.read_text())
    assert list(data) == ["shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex",
                          "wrist_roll", "gripper"]
    assert data["gripper"] == {"id": 6, "drive_mode": 0, "homing_offset": 0,
                               "range_min": 2030, "range_max": 4095}
    assert cal.load(path) == motors


def test_the_robot_saves_the_servos_calibration_after_its_confirmation(tmp_path):
    told: list[str] = []

    def refuse(what: str) -> None:
        told.append(what)
        raise Refused("not now")

    out = tmp_path / "arm.json"
    with open_robot("so101-follower", sim=True) as robot:
        with pytest.raises(Refused):
            robot.calibrate_servos(True, "arm", out, refuse)
        assert not out.exists() and "Homing_Offset" in told[0]
        result = robot.calibrate_servos(False, "arm", out, told.append)
    assert "read the calibration" in told[1]
    assert result["blocks"][0]["file"] == str(out)
    assert set(cal.load(out)) == set(result["blocks"][0]["parts"])
    with open_robot("dg-5f-right", sim=True) as robot, pytest.raises(InvalidInput):
        robot.calibrate_servos(output=tmp_path / "none.json")


def test_calibrate_servos_does_lerobots_half_turn_homing_and_saves_its_file(cli, tmp_path,
                                                                             monkeypatch):
    monkeypatch.setenv("HF_LEROBOT_CALIBRATION", str(tmp_path))
    refused = cli("-p", "so101-follower", "--sim", "calibrate", "servos", "--half-turn")
    assert refused.exit_code == 5  # it writes into the servos: asked first
    result = cli("-p", "so101-follower", "--sim", "--yes", "calibrate", "servos",
                 "--half-turn", "--id", "arm1")
    assert result.exit_code == 0, result.output
    path = tmp_path / "robots" / "so_follower" / "arm1.json"
    motors = cal.load(path)
    # the emulated servos sit at step 2048: offset = 2048 - 2047, as LeRobot computes it
    assert {m.homing_offset for m in motors.values()} == {1}
    assert [m.id for m in motors.values()] == [1, 2, 3, 4, 5, 6]
    leader = cli("-p", "so101-leader", "--sim", "--yes", "calibrate", "servos", "--id", "l1")
    assert leader.exit_code == 0, leader.output
    assert cal.load(tmp_path / "teleoperators" / "so_leader" / "l1.json")["gripper"].id == 6
    out = tmp_path / "here.json"
    assert cli("-p", "so101-follower", "--sim", "--yes", "calibrate", "servos", "-o",
               str(out)).exit_code == 0
    assert set(cal.load(out)) == set(motors)


def test_a_raw_goal_outside_the_calibrated_range_is_refused_not_clamped(tmp_path):
    with open_robot(_calibrated_profile(tmp_path), sim=True) as robot:
        driver = robot.blocks[0].driver
        # 100 steps is below the gripper's range_min (2030): LeRobot's range mode would clamp
        # it to 0 %, inside the envelope, while the servo would go to step 100
        with pytest.raises(Refused, match=r"2030\.\.3500"):
            driver.write_register("gripper", "goal_position", 100)
        assert driver.write_register("gripper", "goal_position", 2050) == 2050


def test_half_turn_homing_is_refused_where_no_motion_is_allowed(tmp_path):
    with open_robot("so101-follower", sim=True, allow_motion=False) as robot:
        with pytest.raises(Refused, match="allows no motion"):
            robot.calibrate_servos(True, "arm", tmp_path / "arm.json")
        assert robot.blocks[0].driver.lerobot_calibration()["gripper"].homing_offset == 0
        # reading the calibration actuates nothing
        robot.calibrate_servos(False, "arm", tmp_path / "arm.json")


def test_a_calibration_path_that_is_no_regular_file_or_too_large_is_refused(tmp_path):
    import os

    with pytest.raises(InvalidInput, match="must be a regular file"):
        cal.load(Path("/dev/zero"))
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    with pytest.raises(InvalidInput, match="must be a regular file"):
        cal.load(fifo)
    big = tmp_path / "big.json"
    big.write_text(" " * ((1 << 20) + 1))
    with pytest.raises(InvalidInput, match="larger than"):
        cal.load(big)


def test_calibrate_servos_keeps_an_existing_file_without_force(cli, tmp_path, monkeypatch):
    monkeypatch.setenv("HF_LEROBOT_CALIBRATION", str(tmp_path))
    run = ("-p", "so101-follower", "--sim", "--yes", "calibrate", "servos")
    assert cli(*run, "--id", "arm").exit_code == 0
    path = tmp_path / "robots" / "so_follower" / "arm.json"
    path.write_text("kept")
    again = cli(*run, "--half-turn", "--id", "arm")
    assert again.exit_code == 2 and "pass --force" in again.stderr, again.stderr
    assert path.read_text() == "kept"
    assert cli(*run, "--id", "arm", "--force").exit_code == 0
    assert cal.load(path)
    for bad in ("../escape", "a/b", ".."):
        refused = cli(*run, "--id", bad)
        assert refused.exit_code == 2 and "plain name" in refused.stderr, refused.stderr
    assert not (tmp_path / "robots" / "escape.json").exists()
