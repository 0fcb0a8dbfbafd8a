"""The MH5's LSM6DS3: registers and scaling, the emulator, and the IMU in detect, stream and
record on the mh5 profile."""

from __future__ import annotations

import json
import math

import pytest

from deltoctl.errors import InvalidInput, ProtocolError
from deltoctl.families.lsm6ds3 import codec
from tests.conftest import block_of, mh5_targets, ros2_messages


def test_settings_and_scaling():
    assert codec.ctrl1_xl(416, 2, 100) == 0x62  # what the MH5 writes
    assert codec.ctrl2_g(416, 245) == 0x60
    assert codec.ctrl1_xl(104, 8, 50) == 0x4F
    with pytest.raises(InvalidInput, match="range"):
        codec.ctrl2_g(416, 300)
    assert codec.accel_scale(2) == pytest.approx(0.061e-3 * 9.80665)
    assert codec.accel_scale(16) == pytest.approx(8 * 0.061e-3 * 9.80665)
    assert codec.gyro_scale(245) == pytest.approx(math.radians(8.75e-3))
    assert codec.gyro_scale(2000) == pytest.approx(math.radians(70e-3))
    assert codec.chip_name(0x69) == "LSM6DS3" and codec.chip_name(0x6A) == "LSM6DS3TR-C"
    with pytest.raises(ProtocolError, match="WHO_AM_I reads 0x12"):
        codec.chip_name(0x12)


def test_axis_remap_and_temperature():
    # raw: temp 96 (31 °C), gyro x y z = 1 2 3, accel x y z = 10 20 30
    block = bytes.fromhex("6000" "0100" "0200" "0300" "0a00" "1400" "1e00")
    temperature, gyro, accel = codec.decode(block, accel=1.0, gyro=1.0)
    assert temperature == 31.0
    assert gyro == (-3.0, 2.0, -1.0)  # (−gz, gy, −gx)
    assert accel == (-30.0, 20.0, -10.0)  # (−az, ay, −ax)
    assert codec.encode(31.0, gyro, accel, 1.0, 1.0) == block


def test_low_pass_lets_the_first_sample_through():
    lpf = codec.LowPass(0.1)
    assert lpf((10.0,)) == (10.0,)
    assert lpf((0.0,)) == pytest.approx((9.0,))


def imu_values(cli, mh5_buses, *extra):
    result = cli("-p", "mh5", *mh5_targets(mh5_buses), *extra, "stream", "-d", "0.1", "--json",
                 "-i", "imu/*")
    assert result.exit_code == 0, result.stderr
    return json.loads(result.stdout.splitlines()[-1])["values"]


def test_stream_follows_gravity_and_orientation(cli, mh5_buses):
    values = imu_values(cli, mh5_buses)
    assert values["imu/linear_acceleration.z"] == pytest.approx(9.80665, abs=0.2)
    assert abs(values["imu/angular_velocity.x"]) < 0.05
    assert values["imu/orientation.w"] == 1.0
    chip = mh5_buses["i2c"].bus.devices[0x6A]
    assert chip.registers[codec.CTRL1_XL] == 0x62 and chip.registers[codec.CTRL2_G] == 0x60
    assert chip.registers[codec.CTRL4_C] & codec.BW_SCAL_ODR
    chip.set_orientation(math.radians(90), 0.0)  # lying on its side
    values = imu_values(cli, mh5_buses)
    assert values["imu/linear_acceleration.y"] == pytest.approx(9.80665, abs=0.2)
    assert values["imu/linear_acceleration.z"] == pytest.approx(0.0, abs=0.2)


def test_detect_names_the_chip_and_a_wrong_one_is_a_clear_error(cli, mh5_buses):
    chip = mh5_buses["i2c"].bus.devices[0x6A]
    chip.registers[codec.WHO_AM_I] = 0x69
    result = cli("-p", "mh5", *mh5_targets(mh5_buses), "detect", "--json")
    assert result.exit_code == 0, result.stderr
    assert block_of(json.loads(result.stdout), "i2c")["details"]["chip"] == "LSM6DS3"
    chip.registers[codec.WHO_AM_I] = 0x12
    result = cli("-p", "mh5", *mh5_targets(mh5_buses), "detect")
    assert result.exit_code == 1
    assert "imu at 0x6a" in result.stderr and "WHO_AM_I reads 0x12" in result.stderr
    assert "Traceback" not in result.stderr


def test_an_unreachable_imu_bus_leaves_the_servos_working(cli, mh5_buses):
    targets = [t if not t.startswith("i2c=") else "i2c=i2c:///dev/i2c-99"
               for t in mh5_targets(mh5_buses)]
    result = cli("-p", "mh5", *targets, "identify")
    assert result.exit_code == 3
    assert "i2c left out: no I2C bus /dev/i2c-99" in result.stderr


def test_record_writes_sensor_msgs_imu(cli, mh5_buses, tmp_path):
    out = tmp_path / "mh5.mcap"
    result = cli("-p", "mh5", *mh5_targets(mh5_buses), "record", str(out), "-d", "0.3")
    assert result.exit_code == 0, result.stderr
    imu = [m for _, m in ros2_messages(out, ["/imu/data_raw"])]
    assert len(imu) >= 10
    msg = imu[0]
    assert type(msg).__name__ == "Imu" and msg.header.frame_id == "chest"
    assert msg.linear_acceleration.z == pytest.approx(9.80665, abs=0.2)
    assert msg.orientation_covariance[0] == -1.0  # no orientation estimate
