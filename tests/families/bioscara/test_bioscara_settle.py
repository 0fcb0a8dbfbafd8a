"""A Bioscara move raises no flag: it settles once each joint is within tolerance, not BUSY
and still, no sooner than its profile could end; or is unsettled when its time runs out,
naming where each joint ended."""

from __future__ import annotations

import json

import pytest

import deltoctl
from deltoctl.profile.catalog import load_profile, resolve
from deltoctl.sim.i2c_bus import I2CSocketServer
from tests.conftest import sim_i2c_bus


def _profile(tmp_path, **safety: float):
    """bioscara-arm with these safety settings (home_tolerance, home_timeout)."""
    text = resolve("bioscara-arm").read_text().replace("  home_timeout: 120\n", "".join(
        f"  {key}: {value}\n" for key, value in safety.items()))
    path = tmp_path / "bioscara-arm.yaml"
    path.write_text(text)
    return path


def test_a_jog_within_a_wide_tolerance_ends_at_its_goal(tmp_path):
    with deltoctl.open_robot(_profile(tmp_path, home_tolerance=0.1, home_timeout=120),
                             sim=True) as robot:
        robot.home(["j4"])
        start = robot.read()["j4/position"]
        report = robot.jog({"j4": -0.05})
    joint = report["blocks"][0]["joints"]["j4"]
    assert report["settled"] is True and joint["settled"] is True
    # at the goal, not where it started within the 0.1 rad tolerance
    assert joint["position"] == pytest.approx(start - 0.05, abs=1e-3)


def test_a_move_whose_time_runs_out_is_unsettled_and_says_where_it_ended(cli, tmp_path):
    profile = _profile(tmp_path, home_timeout=0.3)
    # j4 speeds up at 0.01 rad/s²: far slower than its profile's 0.5 s at 0.1 rad/s
    profile.write_text(profile.read_text().replace("max_acceleration: 30.0", "max_acceleration: 0.01"))
    server = I2CSocketServer(sim_i2c_bus(load_profile("bioscara-arm"))).start()
    try:
        homed = cli("-p", "bioscara-arm", "-t", server.url, "home", "--yes", "-j", "j4")
        assert homed.exit_code == 0, homed.stderr  # the joint keeps its home offset
        args = ("-p", str(profile), "-t", server.url)
        # 0.05 rad at 0.1 rad/s takes 0.5 s, and 0.3 s more is allowed; at 0.01 rad/s² it
        # takes 4.5 s
        result = cli(*args, "jog", "j4", "-0.05", "--velocity", "0.1", "--yes", "--json")
        assert result.exit_code == 1, result.stderr
        envelope = json.loads(result.stdout)
        joint = envelope["blocks"][0]["joints"]["j4"]
        assert envelope["result"]["unsettled"] == ["j4"] and joint["settled"] is False
        assert joint["target"] - 0.001 < joint["position"] < joint["target"] + 0.05
        said = cli(*args, "jog", "j4", "-0.05", "--velocity", "0.1", "--yes")
        assert said.exit_code == 1 and "did not settle: j4 at " in said.stderr
        assert "its target" in said.stderr
    finally:
        server.close()


@pytest.mark.parametrize("speed", ["0", "0.0", "-1.0", ".nan"])
def test_a_max_velocity_that_is_not_a_speed_is_refused_naming_the_joint(cli, tmp_path, speed):
    joint = next(c for hw in load_profile("bioscara-arm").hardware for c in hw.components()
                 if float(c.params.get("max_velocity", 0)) == 1.0)
    text = resolve("bioscara-arm").read_text()
    assert text.count("max_velocity: 1.0}") == 1
    path = tmp_path / "bioscara-arm.yaml"
    path.write_text(text.replace("max_velocity: 1.0}", f"max_velocity: {speed}}}"))
    result = cli("-p", str(path), "--sim", "jog", joint.name, "0.01", "--yes")
    assert result.exit_code == 2, result.stderr
    assert "max_velocity" in result.stderr and f"joint {joint.name}" in result.stderr.replace(
        f"joint '{joint.name}'", f"joint {joint.name}")
    assert "Traceback" not in result.stderr


def test_a_profile_longer_than_home_timeout_runs_to_its_end(cli, tmp_path):
    server = I2CSocketServer(sim_i2c_bus(load_profile("bioscara-arm"))).start()
    try:
        homed = cli("-p", "bioscara-arm", "-t", server.url, "home", "--yes", "-j", "j4")
        assert homed.exit_code == 0, homed.stderr
        with deltoctl.open_robot(_profile(tmp_path, home_timeout=0.2), server.url) as robot:
            # 0.1 rad at 0.2 rad/s takes 0.5 s, and 0.2 s more is allowed
            report = robot.jog({"j4": -0.1}, velocity=0.2)
    finally:
        server.close()
    assert report["settled"] is True, report
