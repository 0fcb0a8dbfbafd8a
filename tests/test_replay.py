"""`jog --record` then `replay`, through the CLI, against the emulators: each family with
motion, and a cell whose blocks on two links move at once; the refusals before anything
moves; a stop on SIGTERM. Tolerances are wide against the differences seen (below 0.002 rad):
a loaded machine shifts a replay's timing, and these tests assert behaviour, not timing."""

from __future__ import annotations

import contextlib
import json
import math
import signal
import subprocess
import sys
import time

import pytest

from deltoctl.families.delto.emulator import DeltoServer, firmware_for_profile
from deltoctl.profile.catalog import load_profile
from tests.conftest import eventually, joints_of, ros2_messages

TOLERANCE = 0.05  # rad or m


def run_json(cli, *args):
    result = cli(*args, "--json")
    assert result.exit_code == 0, result.stderr
    return json.loads(result.stdout)


def replayed(cli, path, *args):
    """`replay PATH --tolerance TOLERANCE --json`: its report (exit 0 asserted)."""
    report = run_json(cli, "replay", str(path), "--tolerance", str(TOLERANCE), *args)
    assert report["exceeded"] == [] and report["commands"] > 0
    return report


@pytest.fixture
def served():
    """``serve(profile_name)``: the profile's simulated devices as `sim serve` starts them;
    returns the ``-t BUS=URL`` arguments."""
    from deltoctl.sim.serve import ServeOptions, serve_profile

    with contextlib.ExitStack() as stack:
        def serve(name):
            buses = serve_profile(stack, load_profile(name), ServeOptions())["buses"]
            return [a for bus, url in buses.items() for a in ("-t", f"{bus}={url}")]
        yield serve


@pytest.fixture
def gripper():
    with DeltoServer(firmware_for_profile(load_profile("dg-3f-m"))) as server:
        yield server


def test_delto_jog_recorded_then_replayed(cli, tmp_path):
    out = tmp_path / "jog.mcap"
    report = run_json(cli, "-p", "dg-3f-m", "--sim", "jog", "j_dg_1_2", "10deg", "--yes",
                      "--record", str(out))
    assert report["settled"] and report["recording"]["messages"]["/joint_commands"] > 10
    # the setpoints are ROS 2 messages: the effort each cycle sent, NaN elsewhere
    commands = [m for _, m in ros2_messages(out, ["/joint_commands"])]
    assert commands[0].name[:2] == ["j_dg_1_1", "j_dg_1_2"]
    efforts = [m.effort[1] for m in commands]
    assert max(efforts) > 0 and all(math.isnan(m.effort[0]) for m in commands)
    assert commands[0].position[1] == pytest.approx(0.0, abs=0.01)  # the ramp's start
    # replayed on the simulator (the default), the profile taken from the recording
    result = replayed(cli, out)
    assert result["on"] == "simulator" and result["profile"] == "dg-3f-m"
    assert set(result["joints"]) == {"j_dg_1_2"}
    assert result["joints"]["j_dg_1_2"]["samples"] == report["recording"]["cycles"]
    table = cli("replay", str(out))
    assert table.exit_code == 0 and "j_dg_1_2" in table.stdout and "RMS" in table.stdout


def test_dynamixel_jog_recorded_then_replayed(cli, tmp_path):
    out = tmp_path / "mh5.mcap"
    run_json(cli, "-p", "mh5", "--sim", "jog", "head_y", "10deg", "--velocity", "60deg",
             "--yes", "--record", str(out))
    goals = {m.position[1] for _, m in ros2_messages(out, ["/joint_commands"])}
    assert len(goals) == 1  # one goal: the servo runs its own profile to it
    assert goals.pop() == pytest.approx(math.radians(10))
    result = replayed(cli, out)
    assert result["joints"]["head_y"]["block"] == "upper_body"


def test_bioscara_jog_recorded_then_replayed_homes_the_simulator_first(cli, served, tmp_path):
    targets = served("bioscara-arm")
    assert cli("-p", "bioscara-arm", *targets, "home", "-j", "j4", "--yes").exit_code == 0
    out = tmp_path / "arm.mcap"
    run_json(cli, "-p", "bioscara-arm", *targets, "jog", "j4", "-0.2", "--yes", "--record",
             str(out))
    result = cli("replay", str(out), "--tolerance", str(TOLERANCE))
    assert result.exit_code == 0, result.stderr
    assert "homing j4 on the simulator first" in result.stderr
    assert "j4" in result.stdout


def test_a_cell_with_blocks_on_two_links_recorded_and_replayed(cli, served, tmp_path):
    """The arm (I2C) and the gripper (TCP) move at once, each in its own loop: one recording
    holds both blocks' cycles, and the replay drives both."""
    targets = served("bioscara-dg-3f-m")
    cell = ("-p", "bioscara-dg-3f-m", *targets)
    assert cli(*cell, "home", "-j", "j4", "--yes").exit_code == 0
    out = tmp_path / "cell.mcap"
    report = run_json(cli, *cell, "jog", "j4", "-0.2", "j_dg_1_2", "10deg", "--yes",
                      "--record", str(out))
    assert set(joints_of(report, "settled")) == {"j4", "j_dg_1_2"}
    commanded = {n for _, m in ros2_messages(out, ["/joint_commands"])
                 for n, p, e in zip(m.name, m.position, m.effort)
                 if not (math.isnan(p) and math.isnan(e))}
    assert commanded == {"j4", "j_dg_1_2"}
    result = replayed(cli, out)
    assert {j: d["block"] for j, d in result["joints"].items()} == {
        "j4": "bioscara_arm", "j_dg_1_2": "dg3f_m_driver"}
    assert all(d["samples"] > 1 for d in result["joints"].values())


def test_replay_on_a_device_needs_its_confirmation_and_then_moves_it(cli, gripper, tmp_path):
    out = tmp_path / "jog.mcap"
    run_json(cli, "-p", "dg-3f-m", "--sim", "jog", "j_dg_1_2", "10deg", "--yes", "--record",
             str(out))
    device = ("replay", str(out), "--device", "-t", gripper.endpoint)
    refused = cli(*device)  # no terminal, no --yes
    assert refused.exit_code == 5 and "pass --yes" in refused.stderr
    assert gripper.firmware.position[1] == 0.0 and not any(gripper.firmware.duty)
    unsaid = cli("replay", str(out), "-t", gripper.endpoint, "--yes")  # a target, no --device
    assert unsaid.exit_code == 2 and "--device" in unsaid.stderr
    result = replayed(cli, out, "--device", "-t", gripper.endpoint, "--yes")
    assert result["on"] == "device"
    assert gripper.firmware.position[1] == pytest.approx(math.radians(10), abs=math.radians(3))
    assert eventually(lambda: gripper.firmware.duty == [0] * 12)  # stopped at the end


def test_a_difference_beyond_the_tolerance_exits_3(cli, tmp_path):
    out = tmp_path / "jog.mcap"
    run_json(cli, "-p", "dg-3f-m", "--sim", "jog", "j_dg_1_2", "10deg", "--yes", "--record",
             str(out))
    result = cli("replay", str(out), "--tolerance", "0", "--json")
    assert result.exit_code == 3
    assert json.loads(result.stdout)["exceeded"] == ["j_dg_1_2"]
    assert cli("replay", str(out), "--tolerance", "lots").exit_code == 2


def test_recordings_without_commands_and_bad_files_are_clear_errors(cli, tmp_path):
    plain = tmp_path / "plain.mcap"
    assert cli("-p", "dg-3f-m", "--sim", "record", str(plain), "--duration", "0.1"
               ).exit_code == 0
    result = cli("replay", str(plain))
    assert result.exit_code == 2 and "no recorded commands" in result.stderr
    assert "jog" in result.stderr  # the hint says how to record them
    assert cli("replay", str(tmp_path / "none.mcap")).exit_code == 2
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(plain.read_bytes()[:200])
    result = cli("replay", str(cut))
    assert result.exit_code == 2 and "truncated" in result.stderr
    assert "Traceback" not in result.stderr + result.stdout


def _recording_with(path, profile, rows, metadata=None):
    """A recording with commands, written by the recorder: ``rows`` of (t_ns, values)."""
    from deltoctl.record.mcap_recorder import McapRecorder

    with open(path, "wb") as f:
        recorder = McapRecorder(f, profile, metadata or {}, commands=True)
        for t_ns, values in rows:
            recorder.write(values, t_ns)
        recorder.close()


def _at_rest(profile):
    """A row of a DG-3F-M at rest, and one with no command for j_dg_1_2."""
    nan = float("nan")
    base = {f"{j.name}/{k}": 0.0 for j in profile.joints() for k in ("position", "velocity")}
    return base, {f"j_dg_1_2/{k}_command": nan for k in ("position", "velocity", "effort")}


def test_a_command_beyond_the_limits_is_refused_before_anything_moves(cli, gripper, tmp_path):
    profile = load_profile("dg-3f-m")
    base, command = _at_rest(profile)
    t0 = time.time_ns()
    rows = [(t0 + i * 5_000_000, {**base, **command, "j_dg_1_2/effort_command": 0.1})
            for i in range(3)]
    rows.append((t0 + 20_000_000, {**base, **command, "j_dg_1_2/position_command": 2.0}))
    out = tmp_path / "beyond.mcap"
    _recording_with(out, profile, rows)
    result = cli("replay", str(out), "--device", "-t", gripper.endpoint, "--yes")
    assert result.exit_code == 5, result.stderr
    assert "at 0.020 s" in result.stderr and "outside its limits" in result.stderr
    assert gripper.firmware.duty == [0] * 12 and gripper.firmware.position[1] == 0.0
    too_hard = [(t0, {**base, **command, "j_dg_1_2/effort_command": 50.0})]
    _recording_with(out, profile, too_hard)
    result = cli("replay", str(out))
    assert result.exit_code == 5 and "effort command 50.0000 is beyond" in result.stderr
    # a profile that lacks the joint: invalid input
    result = cli("-p", "mh5", "replay", str(out))
    assert result.exit_code == 2 and "no joint of mh5" in result.stderr


def test_sigterm_during_a_replay_stops_the_device(cli, gripper, tmp_path):
    out = tmp_path / "slow.mcap"
    run_json(cli, "-p", "dg-3f-m", "--sim", "jog", "j_dg_1_2", "10deg", "--velocity", "5deg",
             "--yes", "--record", str(out))
    proc = subprocess.Popen(
        [sys.executable, "-m", "deltoctl", "replay", str(out), "--device", "-t",
         gripper.endpoint, "--yes"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 20
    while not any(gripper.firmware.duty) and time.monotonic() < deadline:
        time.sleep(0.02)
    assert any(gripper.firmware.duty), "the replay never started"
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=20)
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    assert eventually(lambda: gripper.firmware.duty == [0] * 12)
    assert gripper.firmware.position[1] < math.radians(8)


def test_the_profile_in_a_recording_is_untrusted_input(cli, tmp_path):
    profile = load_profile("dg-3f-m")
    row = {"j_dg_1_2/position": 0.0, "j_dg_1_2/effort_command": 0.1}
    out = tmp_path / "odd.mcap"
    bomb = "a: &a [x, x, x, x, x, x, x, x, x, x]\n" + "".join(
        f"{k}: &{k} [*{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}]\n"
        for p, k in zip("abcdefg", "bcdefgh"))
    for text, what in (("name: [unclosed", "not valid YAML"), (bomb, "YAML nodes"),
                       ("name: x\nros2_control: []\n", "at least one block")):
        _recording_with(out, profile, [(time.time_ns(), row)], {"profile": {"yaml": text}})
        result = cli("replay", str(out))
        assert result.exit_code == 2, result.stderr
        assert "(profile metadata)" in result.stderr and what in result.stderr
        assert "Traceback" not in result.stderr


def test_a_recorded_jog_interrupted_leaves_a_recording_that_replays(cli, gripper, tmp_path):
    out = tmp_path / "cut-short.mcap"
    proc = subprocess.Popen(
        [sys.executable, "-m", "deltoctl", "-p", "dg-3f-m", "-t", gripper.endpoint, "jog",
         "j_dg_1_2", "10deg", "--velocity", "5deg", "--yes", "--record", str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 20
    while not any(gripper.firmware.duty) and time.monotonic() < deadline:
        time.sleep(0.02)
    time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=20)
    assert proc.returncode == 130, err
    assert eventually(lambda: gripper.firmware.duty == [0] * 12)
    result = replayed(cli, out)  # what was recorded until the interrupt
    assert result["joints"]["j_dg_1_2"]["samples"] > 5


def test_delto_efforts_replayed_are_clamped_to_the_current_cap(cli, gripper, tmp_path):
    """An effort within the joint's limit but beyond the profile's current cap goes out as
    the cap's duty, as a jog's PD loop would send it (a hand-made file cannot push harder)."""
    from deltoctl.families.delto.models import effort_to_duty_percent
    from deltoctl.families.delto.motion import DEFAULT_CURRENT_CAP, KT

    profile = load_profile("dg-3f-m")
    cap = (profile.safety.current_cap or DEFAULT_CURRENT_CAP) / 1000.0 * KT
    base, command = _at_rest(profile)
    t0 = time.time_ns()
    rows = [(t0 + i * 5_000_000, {**base, **command, "j_dg_1_2/effort_command": 5.0})
            for i in range(20)]
    out = tmp_path / "hard.mcap"
    _recording_with(out, profile, rows)
    seen = []
    handle = gripper.firmware.handle

    def watch(data):
        reply = handle(data)
        seen.append(max(map(abs, gripper.firmware.duty)))
        return reply

    gripper.firmware.handle = watch
    result = cli("replay", str(out), "--device", "-t", gripper.endpoint, "--yes")
    assert result.exit_code in (0, 3), result.stderr
    assert max(seen) > 0
    assert max(seen) <= int(effort_to_duty_percent(cap) * 10) + 1
