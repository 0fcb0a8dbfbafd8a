"""calibrate imu: the LSM6DS3's self-test, the gravity check at rest, the six-position tumble
and its calibration file, applied by stream and record — on the emulated chip behind its real
I2C transport (loopback), turned by the test as an operator would."""

from __future__ import annotations

import json
import math
import os
import shutil
import sys
from pathlib import Path

import pytest

from deltoctl.families.lsm6ds3 import codec
from tests.conftest import sim_i2c_bus

DELTOCTL = shutil.which("deltoctl", path=os.path.dirname(sys.executable)) or "deltoctl"
INTERFACES = ("[orientation.x, orientation.y, orientation.z, orientation.w, angular_velocity.x, "
              "angular_velocity.y, angular_velocity.z, linear_acceleration.x, "
              "linear_acceleration.y, linear_acceleration.z]")


def imu_profile(path, calibration=None):
    """A robot of one LSM6DS3 (the MH5's chest IMU), optionally naming a calibration file."""
    params = f"{{calibration: {calibration}}}" if calibration else "{}"
    path.write_text(f"""name: imu-bench
buses: {{i2c: i2c:///dev/i2c-1}}
ros2_control:
  - name: chest
    type: sensor
    plugin: mh5_hardware/MH5I2CInterface
    family: lsm6ds3
    bus: i2c
    sensors:
      - name: imu
        address: 0x6A
        state_interfaces: {INTERFACES}
        params: {params}
""")
    return str(path)


@pytest.fixture
def imu_server():
    """The IMU on a simulated I2C bus served on loopback; ``.chip`` is the emulated part."""
    from deltoctl.profile.catalog import load_profile
    from deltoctl.sim.i2c_bus import I2CSocketServer

    server = I2CSocketServer(sim_i2c_bus(load_profile("mh5"))).start()
    server.chip = server.bus.devices[0x6A]
    yield server
    server.close()


def run(cli, server, profile, *args):
    return cli("-p", profile, "-t", f"i2c={server.url}", "--yes", *args)


def checks_of(result):
    assert result.stdout, result.stderr
    (block,) = json.loads(result.stdout)["blocks"]
    return {c["id"]: c for c in block["checks"]}


def test_self_test_and_gravity_pass_on_a_sound_part(cli, imu_server, tmp_path):
    result = run(cli, imu_server, imu_profile(tmp_path / "p.yaml"), "calibrate", "imu", "--json")
    assert result.exit_code == 0, result.stderr
    checks = checks_of(result)
    assert checks["imu.self_test.accel.x"]["value"] == pytest.approx(600, abs=30)
    assert checks["imu.self_test.accel.x"]["limit"] == {"min": 90.0, "max": 1700.0}
    assert checks["imu.self_test.gyro.z"]["value"] == pytest.approx(300, abs=10)
    assert checks["imu.self_test.gyro.z"]["unit"] == "dps"
    assert checks["imu.gravity"]["value"] == pytest.approx(9.80665, abs=0.05)
    assert all(c["verdict"] == "pass" for c in checks.values())
    # the self-test left the chip as the driver set it
    chip = imu_server.chip
    assert chip.registers[codec.CTRL5_C] == 0
    assert chip.registers[codec.CTRL1_XL] == 0x62 and chip.registers[codec.CTRL2_G] == 0x60


def test_a_dead_self_test_fails_naming_the_axes(cli, imu_server, tmp_path):
    imu_server.chip.self_test = (20.0, 300.0)  # the accelerometer's proof mass barely moves
    result = run(cli, imu_server, imu_profile(tmp_path / "p.yaml"), "calibrate", "imu")
    assert result.exit_code == 1
    assert "imu.self_test.accel.x" in result.stderr and "gyro" not in result.stderr.split(
        "failed:")[1].split("\n")[0]
    assert "Traceback" not in result.stderr


def test_gravity_is_checked_only_at_rest(cli, imu_server, tmp_path):
    profile = imu_profile(tmp_path / "p.yaml")
    imu_server.chip.accel_noise = 1.0  # carried about
    checks = checks_of(run(cli, imu_server, profile, "calibrate", "imu", "--json", "-n", "30"))
    assert checks["imu.at_rest"]["verdict"] == "fail"
    assert checks["imu.gravity"]["verdict"] == "skip" == checks["imu.zero_rate"]["verdict"]
    assert "hold the IMU still" in checks["imu.gravity"]["note"]
    imu_server.chip.accel_noise = 0.02
    imu_server.chip.rates = (0.5, 0.0, 0.0)  # still, but its gyroscope reads a turn
    result = run(cli, imu_server, profile, "calibrate", "imu", "--json", "-n", "30")
    assert result.exit_code == 1
    checks = checks_of(result)
    assert checks["imu.zero_rate"]["verdict"] == "fail"
    assert checks["imu.zero_rate"]["value"] == pytest.approx(0.5, abs=0.02)
    assert checks["imu.gravity"]["verdict"] == "pass"


def faulty(chip):
    chip.accel_bias = (0.3, -0.2, 0.4)
    chip.accel_scale = (1.02, 0.98, 1.03)
    chip.gyro_bias = (0.01, -0.02, 0.005)


def test_the_tumble_finds_bias_and_scale_and_stream_applies_them(cli, imu_server, tmp_path):
    from deltoctl import open_robot
    from deltoctl.app.imu_calibration import calibrate_imu

    chip = imu_server.chip
    faulty(chip)
    asked = []

    def operator(text):  # turns the IMU as the instruction says
        asked.append(text)
        chip.point_up(text.split("(")[1].split(" ")[0].lower())

    profile = imu_profile(tmp_path / "p.yaml")
    with open_robot(profile, {"i2c": imu_server.url}) as robot:
        result = calibrate_imu(robot.system, samples=20, ask=operator, output_dir=tmp_path)
    assert len(asked) == 6 and asked[0].startswith("put the IMU's -Z face down (+Z axis up)")
    (block,) = result["blocks"]
    # before its calibration, the part's errors fail the gravity check; the tumble passes
    assert [c["id"] for c in block["checks"] if c["verdict"] != "pass"] == ["imu.gravity"]
    cal = json.loads(Path(block["calibration_file"]).read_text())
    assert block["calibration_file"].endswith(".json") and "LSM6DS3TR-C-0x6a" in \
        block["calibration_file"]
    assert cal["kind"] == "imu_calibration" and cal["pass"] is True
    assert cal["accel_bias"] == pytest.approx([0.3, -0.2, 0.4], abs=0.03)
    assert cal["accel_scale"] == pytest.approx([1.02, 0.98, 1.03], abs=0.005)
    assert cal["gyro_bias"] == pytest.approx([0.01, -0.02, 0.005], abs=0.003)

    chip.point_up("+z")
    raw = json.loads(run(cli, imu_server, profile, "stream", "-d", "0.1", "--json", "-i",
                         "imu/linear*").stdout.splitlines()[-1])["values"]
    assert raw["imu/linear_acceleration.z"] == pytest.approx(1.03 * 9.80665 + 0.4, abs=0.1)
    calibrated = imu_profile(tmp_path / "calibrated.yaml",
                             os.path.basename(block["calibration_file"]))
    values = json.loads(run(cli, imu_server, calibrated, "stream", "-d", "0.1", "--json", "-i",
                            "imu/linear*").stdout.splitlines()[-1])["values"]
    assert values["imu/linear_acceleration.z"] == pytest.approx(9.80665, abs=0.08)
    assert values["imu/linear_acceleration.x"] == pytest.approx(0.0, abs=0.08)
    # the gravity check passes on the corrected readings
    checks = checks_of(run(cli, imu_server, calibrated, "calibrate", "imu", "--json"))
    assert checks["imu.gravity"]["value"] == pytest.approx(9.80665, abs=0.05)

    # a recording says which calibration its IMU values carry
    run_file = tmp_path / "run.mcap"
    result = run(cli, imu_server, calibrated, "record", str(run_file), "--duration", "0.2")
    assert result.exit_code == 0, result.stderr
    info = json.loads(cli("info", str(run_file), "--json").stdout)["result"]
    (chest,) = [b for b in info["blocks"] if b["name"] == "chest"]
    applied = chest["identity"]["calibration"]
    assert applied["applied"] is True and applied["file"] == block["calibration_file"]
    assert len(applied["sha256"]) == 64


def test_the_terminal_says_which_face_to_put_down(imu_server, tmp_path):
    """The verb on a real terminal (pty): each instruction appears, the test turns the chip,
    the verb waits until the readings settle and goes on."""
    pexpect = pytest.importorskip("pexpect")
    chip = imu_server.chip
    chip.accel_bias, chip.accel_scale = (0.1, 0.0, 0.05), (1.0, 1.0, 1.02)
    chip.point_up("-y")  # where the operator left it
    child = pexpect.spawn(DELTOCTL, ["-p", imu_profile(tmp_path / "p.yaml"), "-t",
                                     f"i2c={imu_server.url}", "calibrate", "imu", "--tumble",
                                     "-n", "20", "-o", str(tmp_path), "--yes"],
                          encoding="utf-8", timeout=60, cwd=str(tmp_path))
    try:
        for axis in ("+z", "-z", "+x", "-x", "+y", "-y"):
            child.expect(r"put the IMU's ([+-][XYZ]) face down \(([+-][XYZ]) axis up\)")
            assert child.match.group(2).lower() == axis
            chip.point_up(axis)
        child.expect(pexpect.EOF)
    finally:
        child.close()
    assert child.exitstatus == 0, child.before
    (path,) = tmp_path.glob("calibration-LSM6DS3TR-C-0x6a-*.json")
    assert json.loads(path.read_text())["accel_scale"][2] == pytest.approx(1.02, abs=0.005)


def test_an_imu_never_turned_is_a_clear_error(cli, imu_server, tmp_path):
    result = run(cli, imu_server, imu_profile(tmp_path / "p.yaml"), "calibrate", "imu",
                 "--tumble", "--timeout", "0.5", "-n", "10", "-o", str(tmp_path))
    assert result.exit_code == 1
    assert "did not hold still with its -z axis up within 0.5 s" in result.stderr
    assert "Traceback" not in result.stderr and not list(tmp_path.glob("calibration-*"))


@pytest.mark.parametrize("content, message", [
    ("{not json", "not JSON"),
    ('{"kind": "ft_tare"}', "not an IMU calibration"),
    ('{"kind": "imu_calibration", "pass": false}', "failed its checks"),
    ('{"kind": "imu_calibration", "pass": true, "accel_bias": [0, 0, 0], '
     '"accel_scale": [1, 1e308, 1], "gyro_bias": [0, 0, 0]}', "accel_scale must be three"),
    ('{"kind": "imu_calibration", "pass": true, "accel_bias": [0, 0], '
     '"accel_scale": [1, 1, 1], "gyro_bias": [0, 0, 0]}', "accel_bias must be three"),
])
def test_a_bad_calibration_file_is_one_clear_error(cli, imu_server, tmp_path, content,
                                                  message):
    (tmp_path / "cal.json").write_text(content)
    result = run(cli, imu_server, imu_profile(tmp_path / "p.yaml", "cal.json"), "stream",
                 "-d", "0.05")
    assert result.exit_code == 2, result.stderr
    assert "imu: calibration" in result.stderr and message in result.stderr
    assert "Traceback" not in result.stderr


def test_a_calibration_that_is_not_a_file_is_refused(cli, imu_server, tmp_path):
    result = run(cli, imu_server, imu_profile(tmp_path / "p.yaml", "/dev/zero"), "stream",
                 "-d", "0.05")
    assert result.exit_code == 2 and "not a regular file" in result.stderr


def test_the_emulated_self_test_follows_ctrl5_c():
    from deltoctl.families.lsm6ds3.emulator import Lsm6ds3Chip

    chip = Lsm6ds3Chip()
    chip.accel_noise = chip.gyro_noise = 0.0
    chip.write(bytes([codec.CTRL1_XL, 0x38, 0x5C]))  # 52 Hz ±4 g; 208 Hz 2000 dps

    def raw(register):
        chip.write(bytes([register]))
        return codec.raw_axes(chip.read(6))

    off = raw(codec.OUTX_L_XL)
    chip.write(bytes([codec.CTRL5_C, codec.ST_XL_POSITIVE]))
    on = raw(codec.OUTX_L_XL)
    assert [round((b - a) * 0.122) for a, b in zip(off, on)] == [600, 600, 600]
    chip.write(bytes([codec.CTRL5_C, codec.ST_G_NEGATIVE]))
    assert [round(v * 0.07) for v in raw(codec.OUTX_L_G)] == [-300, -300, -300]
    assert math.isclose(off[2] * 0.122, 0.0, abs_tol=1)  # +Z up: chip −X reads 1 g
    assert off[0] * 0.122 == pytest.approx(-1000, abs=1)
