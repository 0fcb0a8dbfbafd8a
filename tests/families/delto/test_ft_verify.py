"""calibrate ft --verify: after the tare, the residual as checks, the drift over --watch, and a
known mass's weight — on the Delto emulator over loopback TCP, the mass put on by the test as
an operator would."""

from __future__ import annotations

import json
import os
import shutil
import sys

import pytest

from deltoctl.families.delto.emulator import DeltoServer, firmware_for_profile
from deltoctl.profile.catalog import load_profile

DELTOCTL = shutil.which("deltoctl", path=os.path.dirname(sys.executable)) or "deltoctl"


@pytest.fixture
def gripper():
    with DeltoServer(firmware_for_profile(load_profile("dg-4f"), seed=5)) as server:
        yield server


def by_id(checks):
    return {c["id"]: c for c in checks}


AXES = ("fx", "fy", "fz", "tx", "ty", "tz")


def test_verify_and_watch_report_each_check(cli, gripper, tmp_path):
    result = cli("-p", "dg-4f", "-t", gripper.endpoint, "calibrate", "ft", "--json", "-n", "20",
                 "--watch", "0.3", "-o", str(tmp_path))
    assert result.exit_code == 0, result.stderr
    checks = by_id(json.loads(result.stdout)["result"]["checks"])
    residual = checks["fingertip_finger_1.residual_force"]
    assert residual["verdict"] == "pass" and residual["limit"] == {"min": None, "max": 0.3}
    assert residual["unit"] == "N"
    # the drift of each axis of each fingertip, a check each with its own unit and limit
    for finger in range(1, 5):
        for axis in AXES:
            drift = checks[f"fingertip_finger_{finger}.drift.{axis}"]
            force = axis.startswith("f")
            assert drift["unit"] == ("N" if force else "N·m") and drift["verdict"] == "pass"
            assert drift["limit"] == ({"min": -0.3, "max": 0.3} if force else
                                      {"min": -0.03, "max": 0.03})
            assert drift["note"].endswith("N/s" if force else "N·m/s")
    assert not any(c.endswith(".drift") for c in checks)


def test_one_creeping_axis_fails_and_the_others_pass(deltoctl_sim, cli, tmp_path):
    """The simulator's drift fault (sim serve --ft-creep FX,FY,FZ,…): Fz creeps by 0.6 N/s;
    its drift check fails on every fingertip, each other axis's passes, in the table and in
    --json; a limit of one axis is set on the command line."""
    (target,) = deltoctl_sim.buses("dg-4f", ft_creep="0,0,0.6").values()
    args = ("-p", "dg-4f", "-t", target, "calibrate", "ft", "-n", "10", "--watch", "1.5",
            "--drift-limit", "tz=0.05", "-o", str(tmp_path))
    result = cli(*args, "--json")
    assert result.exit_code == 1, result.stderr
    checks = by_id(json.loads(result.stdout)["result"]["checks"])
    for finger in range(1, 5):
        verdicts = {a: checks[f"fingertip_finger_{finger}.drift.{a}"]["verdict"] for a in AXES}
        assert verdicts == {a: "fail" if a == "fz" else "pass" for a in AXES}
        fz = checks[f"fingertip_finger_{finger}.drift.fz"]
        assert fz["value"] >= 0.6 * 1.5 * 0.9 and fz["unit"] == "N"  # at least its creep
        assert checks[f"fingertip_finger_{finger}.drift.tz"]["limit"]["max"] == 0.05
    failed = ", ".join(f"fingertip_finger_{f}.drift.fz" for f in range(1, 5))
    assert json.loads(result.stderr)["error"]["message"] == f"F/T checks failed: {failed}"
    table = cli(*args)
    assert table.exit_code == 1 and "Traceback" not in table.stderr
    rows = [line.split() for line in table.stdout.splitlines() if ".drift." in line]
    assert len(rows) == 4 * 6
    assert {r[0].rsplit(".", 1)[1]: r[-1] for r in rows[:6]} == {
        "fx": "pass", "fy": "pass", "fz": "FAIL", "tx": "pass", "ty": "pass", "tz": "pass"}


def test_a_creeping_sensor_fails_the_drift_check(cli, gripper, tmp_path):
    gripper.firmware.ft_creep = (0.6, 0.0, 0.0)  # N/s
    result = cli("-p", "dg-4f", "-t", gripper.endpoint, "calibrate", "ft", "-n", "10",
                 "--watch", "1.5", "-o", str(tmp_path))
    assert result.exit_code == 1
    assert "F/T checks failed: fingertip_finger_1.drift.fx" in result.stderr
    assert "Traceback" not in result.stderr


def test_a_known_mass_reads_its_weight(gripper, tmp_path):
    from deltoctl import open_robot
    from deltoctl.app.calibrate import verify_ft

    with open_robot("dg-4f", gripper.endpoint) as robot:
        tare = robot.calibrate_ft(20, output_dir=tmp_path)
        right = verify_ft(robot.system, tare, mass=0.2, sensor="fingertip_finger_2",
                          ask=lambda text: gripper.firmware.put_mass(1, 0.2))
        gripper.firmware.put_mass(1, 0.0)
        # the operator puts 300 g where 200 g was asked for
        wrong = verify_ft(robot.system, tare, mass=0.2, sensor="fingertip_finger_2",
                          ask=lambda text: gripper.firmware.put_mass(1, 0.3))
    check = by_id(right)["fingertip_finger_2.known_mass"]
    assert check["verdict"] == "pass" and check["unit"] == "N"
    assert check["value"] == pytest.approx(0.2 * 9.80665, abs=0.1)
    assert check["limit"]["min"] < 1.96 < check["limit"]["max"]
    check = by_id(wrong)["fingertip_finger_2.known_mass"]
    assert check["verdict"] == "fail" and check["value"] == pytest.approx(2.94, abs=0.1)


def test_the_terminal_asks_for_the_mass(gripper, tmp_path):
    pexpect = pytest.importorskip("pexpect")
    child = pexpect.spawn(DELTOCTL, ["-p", "dg-4f", "-t", gripper.endpoint, "calibrate", "ft",
                                     "-n", "20", "--mass", "0.5", "-o", str(tmp_path)],
                          encoding="utf-8", timeout=60)
    try:
        child.expect(r"put 0\.5 kg on fingertip_finger_1 and let it rest")
        gripper.firmware.put_mass(0, 0.5)
        child.expect(pexpect.EOF)
    finally:
        child.close()
    assert child.exitstatus == 0, child.before
    assert "fingertip_finger_1.known_mass" in child.before


def test_no_mass_is_a_clear_error(cli, gripper, tmp_path):
    result = cli("-p", "dg-4f", "-t", gripper.endpoint, "calibrate", "ft", "-n", "10",
                 "--mass", "0.2", "--timeout", "0.5", "-o", str(tmp_path))
    assert result.exit_code == 1
    assert "no steady load on fingertip_finger_1 within 0.5 s" in result.stderr


@pytest.mark.parametrize("args, message", [
    (("--mass", "-1"), "--mass must be 0.01 to 50 kg"),
    (("--mass", "nan"), "--mass must be"),
    (("--watch", "0"), "--watch must be a positive number"),
    (("--mass", "0.2", "--sensor", "palm"), "--sensor palm: not an F/T sensor"),
    (("--watch", "1", "--drift-limit", "fw=0.1"), "--drift-limit fw: the axes are fx, fy"),
    (("--watch", "1", "--drift-limit", "fz=-1"), "--drift-limit fz=-1: a positive number"),
    (("--watch", "1", "--drift-limit", "fz"), "--drift-limit 'fz' is not of the form"),
    (("--watch", "1", "--drift-limit", "fz=abc"), "--drift-limit fz"),
])
def test_bad_options_are_one_clear_error(cli, gripper, tmp_path, args, message):
    result = cli("-p", "dg-4f", "-t", gripper.endpoint, "calibrate", "ft", "-n", "5",
                 "--timeout", "1", *args, "-o", str(tmp_path))
    assert result.exit_code == 2, result.stderr
    assert message in result.stderr and "Traceback" not in result.stderr
