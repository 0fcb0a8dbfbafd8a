"""calibrate ft: tare, residual check, a report named by model, address and time."""

from __future__ import annotations

import json

from deltoctl.families.delto.emulator import DeltoServer, firmware_for_profile
from deltoctl.profile.catalog import load_profile


def test_tare_removes_the_offset_and_writes_a_report(cli, tmp_path):
    with DeltoServer(firmware_for_profile(load_profile("dg-4f"), seed=3)) as server:
        biased = max(abs(v) for row in server.firmware.ft_offset for v in row[:3])
        result = cli("-p", "dg-4f", "-t", server.endpoint, "calibrate", "ft", "--json",
                     "-n", "20", "-o", str(tmp_path))
    assert result.exit_code == 0, result.stderr
    result = json.loads(result.stdout)
    assert result["result"]["pass"] is True
    (report,) = result["blocks"]  # the gripper's one block
    assert report["pass"] is True and report["block"] == load_profile("dg-4f").hardware[0].name
    assert set(report["sensors"]) == {f"fingertip_finger_{n}" for n in range(1, 5)}
    removed = max(abs(v) for s in report["sensors"].values()
                  for k, v in s["offset_removed"].items() if k.startswith("force"))
    assert removed > 0.5 and biased > 0.5
    files = list(tmp_path.glob("calibration-DG-4F-127.0.0.1_*-*Z.json"))
    assert len(files) == 1
    assert json.loads(files[0].read_text())["sensors"] == report["sensors"]
    assert report["report_file"] == str(files[0])


def test_firmware_without_offset_command_fails_the_check(cli, tmp_path):
    with DeltoServer(firmware_for_profile(load_profile("dg-5f-right"), firmware=(2, 2),
                                          seed=1)) as server:
        result = cli("-p", "dg-5f-right", "-t", server.endpoint, "calibrate", "ft", "-n", "10",
                     "-o", str(tmp_path))
    assert result.exit_code == 1
    assert "over tolerance" in result.stderr and "v2.3" in result.stderr
    assert len(list(tmp_path.glob("calibration-*.json"))) == 1  # the failing report is kept


def test_no_ft_sensors(cli, tmp_path):
    result = cli("--sim", "-p", "dg-5f-s15-right", "calibrate", "ft", "-o", str(tmp_path))
    assert result.exit_code == 2
    assert "no F/T sensors" in result.stderr


def test_a_gripper_with_tactile_sensors_where_the_profile_says_ft(cli, tmp_path):
    firmware = firmware_for_profile(load_profile("dg-5f-right"), sensor_type=3)  # TACTILE_M
    with DeltoServer(firmware) as server:
        result = cli("-p", "dg-5f-right", "-t", server.endpoint, "calibrate", "ft", "-n", "3",
                     "-o", str(tmp_path))
    assert result.exit_code == 1, result.stderr
    assert "reports tactile fingertips (TACTILE_M, 5×3 cells), not F/T sensors" in \
        result.stderr and "internal error" not in result.stderr
    assert not list(tmp_path.glob("calibration-*.json"))
