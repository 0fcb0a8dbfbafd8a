"""A Delto move settles once its ramp has reached the targets and each joint then stays within
tolerance and still (the gripper has no moving flag), or is unsettled when its time runs out,
naming where each joint ended."""

from __future__ import annotations

import json
import math

import pytest

import deltoctl
from deltoctl.profile.catalog import resolve


def test_a_slow_jog_within_the_tolerance_moves_before_it_settles():
    with deltoctl.open_robot("dg-5f-right", sim=True) as robot:
        report = robot.jog({"rj_dg_1_2": "-1deg"}, velocity="2deg/s")
    joint = report["blocks"][0]["joints"]["rj_dg_1_2"]
    assert report["settled"] is True and joint["settled"] is True
    # it went most of the way (its 2° tolerance held it at the start before)
    assert joint["position"] < math.radians(-0.5)
    assert report["seconds"] >= 0.4  # the ramp alone takes 0.5 s


def test_a_jog_at_the_default_speed_smaller_than_the_tolerance_goes_all_the_way():
    with deltoctl.open_robot("dg-5f-right", sim=True) as robot:
        start = robot.read()["rj_dg_1_2/position"]
        report = robot.jog({"rj_dg_1_2": "-0.5deg"})
    joint = report["blocks"][0]["joints"]["rj_dg_1_2"]
    assert report["settled"] is True and joint["settled"] is True
    # most of the 0.5° (the ramp ends at once; the 2° tolerance held it near the start before)
    assert joint["position"] - start < math.radians(-0.25)  # it reads in steps of 0.1°


def test_a_stalled_joint_runs_out_of_time_and_says_where_it_ended(cli, tmp_path):
    text = resolve("dg-5f-right").read_text().replace("home_timeout: 10", "home_timeout: 0.5")
    profile = tmp_path / "dg-5f-right.yaml"
    profile.write_text(text)
    args = ("-p", str(profile), "--sim", "--sim-option", "stall=rj_dg_1_2", "jog",
            "rj_dg_1_2", "-10deg", "--yes")
    result = cli(*args, "--json")
    assert result.exit_code == 1, result.stderr
    envelope = json.loads(result.stdout)
    joint = envelope["blocks"][0]["joints"]["rj_dg_1_2"]
    assert envelope["result"]["unsettled"] == ["rj_dg_1_2"] and joint["settled"] is False
    assert joint["position"] == pytest.approx(0.0, abs=math.radians(0.5))
    said = cli(*args)
    assert said.exit_code == 1
    assert "did not settle: rj_dg_1_2 at 0.00°, its target -10.00°" in said.stderr


def test_a_ramp_longer_than_home_timeout_runs_to_its_end(tmp_path):
    text = resolve("dg-5f-right").read_text().replace("home_timeout: 10", "home_timeout: 0.2")
    profile = tmp_path / "dg-5f-right.yaml"
    profile.write_text(text)
    with deltoctl.open_robot(profile, sim=True) as robot:
        # a 0.5 s ramp (1° at 2°/s), and 0.2 s more allowed
        report = robot.jog({"rj_dg_1_2": "-1deg"}, velocity="2deg/s")
    assert report["settled"] is True, report
