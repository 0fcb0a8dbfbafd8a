"""Moves end on the drive's word — target reached after the set-point's handshake, or their
time out — and `home` runs the drive's homing mode where the bus file gives a homing method;
through the CLI, on emulated drives whose ramps follow the profile's velocity and
acceleration."""

import json

import pytest

from deltoctl_canopen.drive import Drive402

# a profile acceleration and deceleration of 0.5 rad/s²: at 0.2 rad/s, a move of 0.2 rad
# takes 1.4 s (0.4 s to full speed, 0.6 s at it, 0.4 s braking)
SLOW = ("    - {index: 0x6083, sub_index: 0, value: 50000}",
        "    - {index: 0x6083, sub_index: 0, value: 5000}\n"
        "    - {index: 0x6084, sub_index: 0, value: 5000}")
INCREMENT = 1e-4  # rad: the drive's resolution (scale_pos_from_dev)


def slow(text):
    assert SLOW[0] in text
    return text.replace(*SLOW)


def without_homing_method(text):
    return "\n".join(line for line in text.splitlines() if "0x6098" not in line)


def jog_to(cli, profile, velocity="0.2"):
    return cli("-p", profile, "--sim", "--json", "jog", "axis_1", "--to", "0.2",
               "--velocity", velocity, "--yes")


def test_jog_settles_at_the_target_when_the_drive_says_so(cli, variant):
    result = jog_to(cli, variant(bus=slow))
    assert result.exit_code == 0, result.output + result.stderr
    doc = json.loads(result.stdout)
    joint = doc["blocks"][0]["joints"]["axis_1"]
    assert doc["result"]["settled"] and joint["settled"]
    assert abs(joint["position"] - 0.2) <= INCREMENT  # where it stopped, read after
    assert doc["result"]["seconds"] >= 1.2  # the whole ramp (1.4 s), not its tolerance's worth


def short_timeout(text):
    return text.replace("home_timeout: 10", "home_timeout: 0.3")


def test_a_ramp_longer_than_home_timeout_runs_to_its_end(cli, variant):
    """The move's time is its ramp's and home_timeout more: a 2.2 s ramp is not cut at
    0.3 s."""
    result = jog_to(cli, variant(profile=short_timeout, bus=slow), "0.1")
    assert result.exit_code == 0, result.output + result.stderr
    doc = json.loads(result.stdout)
    assert doc["result"]["settled"] and doc["result"]["seconds"] >= 2.0


@pytest.fixture
def sluggish(monkeypatch):
    """Drives that run at a third of the speed they are asked for."""
    move = Drive402._move

    def slower(self, target, speed, now, homing=False):
        move(self, target, speed / 3, now, homing)

    monkeypatch.setattr(Drive402, "_move", slower)


def test_a_move_longer_than_its_time_is_unsettled(cli, variant, sluggish):
    profile = variant(profile=short_timeout, bus=slow)
    result = jog_to(cli, profile, "0.1")  # a ramp of 2.2 s planned; the drive takes longer
    assert result.exit_code == 1, result.output + result.stderr
    doc = json.loads(result.stdout)
    assert not doc["result"]["settled"] and doc["result"]["unsettled"] == ["axis_1"]
    assert doc["blocks"][0]["joints"]["axis_1"]["position"] < 0.19
    assert "did not settle: axis_1" in result.stderr


@pytest.fixture
def homings(monkeypatch):
    """What each emulated drive was homed with: (mode of operation, method, home offset)."""
    seen = []
    home = Drive402._home

    def spy(self, now):
        seen.append((self.mode, self.params[0x6098, 0], self.params[0x607C, 0]))
        home(self, now)

    monkeypatch.setattr(Drive402, "_home", spy)
    return seen


def home(cli, profile):
    result = cli("-p", profile, "--sim", "--json", "home", "--yes")
    return result, json.loads(result.stdout) if result.stdout else {}


def test_a_homing_method_in_the_bus_file_homes_in_homing_mode(cli, variant, homings):
    profile = variant(bus=lambda t: t.replace(  # the shipped profile: no home interface
        "{index: 0x607C, sub_index: 0, value: 0}", "{index: 0x607C, sub_index: 0, value: 1000}"))
    result, doc = home(cli, profile)
    assert result.exit_code == 0, result.output + result.stderr
    joints = doc["blocks"][0]["joints"]
    assert {j: v["outcome"] for j, v in joints.items()} == {"axis_1": "homed",
                                                            "axis_2": "homed"}
    assert homings == [(6, 35, 1000), (6, 35, 1000)]  # mode 6, the bus file's method
    assert all(abs(v["position"] - 0.1) <= INCREMENT for v in joints.values())  # the offset


def test_without_a_homing_method_home_goes_to_the_home_pose(cli, variant, homings):
    profile = variant(
        profile=lambda t: t.replace("safety:\n", "safety:\n  home_pose: {axis_1: 0.1}\n"),
        bus=without_homing_method)
    result, doc = home(cli, profile)
    assert result.exit_code == 0, result.output + result.stderr
    joints = doc["blocks"][0]["joints"]
    assert "outcome" not in joints["axis_1"] and doc["result"]["settled"]
    assert abs(joints["axis_1"]["position"] - 0.1) <= INCREMENT
    assert homings == []


def test_a_home_interface_still_asks_for_the_homing_mode(cli, variant, homings):
    profile = variant(profile=lambda t: t.replace("command_interfaces: [position]",
                                                  "command_interfaces: [position, home]"),
                      bus=without_homing_method)
    result, doc = home(cli, profile)
    assert result.exit_code == 0, result.output + result.stderr
    assert {v["outcome"] for v in doc["blocks"][0]["joints"].values()} == {"homed"}
    assert [m for m, _, _ in homings] == [6, 6]  # the drive's own method (its EDS: 35)


def test_a_homing_error_fails_the_home(cli, variant):
    profile = variant(bus=lambda t: t.replace(
        "{index: 0x6098, sub_index: 0, value: 35}", "{index: 0x6098, sub_index: 0, value: -1}"))
    result, _ = home(cli, profile)
    assert result.exit_code == 1, result.output + result.stderr
    assert "homing error (method -1)" in result.stderr
