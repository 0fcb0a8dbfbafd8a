"""`jog --record` then `replay`, through the CLI, against the emulators: each family with
motion, and a cell whose blocks on two links move at once; the refusals before anything
moves; a stop on SIGTERM. Tolerances are wide against the differences seen (below 0.002 rad):
a loaded machine shifts a replay's timing, and these tests assert behaviour, not timing."""

from __future__ import annotations

import contextlib
import json
import math
import pathlib
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
    document = json.loads(result.stdout)
    data = document.get("result", document)  # the data inside the envelope
    return {"blocks": document["blocks"], **data} if "blocks" in document else data


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
    assert json.loads(result.stdout)["result"]["exceeded"] == ["j_dg_1_2"]
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


def _held_effort(profile, seconds, effort=7.0):
    """Rows every 5 ms for ``seconds``, each the effort ``effort`` on j_dg_1_2 (its limit is
    7.5) and every position recorded at rest: a joint that moves strays from its recording."""
    base, command = _at_rest(profile)
    t0 = time.time_ns()
    return [(t0 + i * 5_000_000, {**base, **command, "j_dg_1_2/effort_command": effort})
            for i in range(int(seconds / 0.005))]


def test_a_joint_straying_from_its_recording_stops_every_block(cli, gripper, tmp_path):
    """Efforts sent as recorded have no position loop behind them: a joint further from its
    recorded position than --max-deviation stops the replay at once (exit 5)."""
    profile = load_profile("dg-3f-m")
    rows = _held_effort(profile, 10.0)
    out = tmp_path / "pushing.mcap"
    _recording_with(out, profile, rows)
    result = cli("replay", str(out), "--device", "-t", gripper.endpoint, "--yes", "--json")
    assert result.exit_code == 5, result.stderr
    assert "j_dg_1_2 at" in result.stderr and "from its recorded position" in result.stderr
    assert "--max-deviation" in result.stderr and "every block was stopped" in result.stderr
    report = json.loads(result.stdout)["result"]  # the replay until it was stopped
    assert 0 < report["commands"] < len(rows) and report["stopped"]
    assert report["max_deviation"] == 0.2
    assert report["joints"]["j_dg_1_2"]["max"] > 0.2
    assert eventually(lambda: gripper.firmware.duty == [0] * 12)
    assert abs(gripper.firmware.position[1]) < 1.0  # stopped well before 10 s of effort
    assert cli("replay", str(out), "--max-deviation", "-1").exit_code == 2


def test_a_joint_leaving_its_limits_stops_the_replay(cli, gripper, tmp_path):
    """The same push on a gripper that goes to ±90°, replayed with a profile whose j_dg_1_2
    spans ±5°: those limits stop it, whatever --max-deviation allows."""
    source = load_profile("dg-3f-m").source
    text = pathlib.Path(source).read_text()
    wide = "{name: j_dg_1_2, limits: {lower: -90deg, upper: 90deg"
    assert wide in text
    narrow = tmp_path / "dg-3f-m-narrow.yaml"
    narrow.write_text(text.replace(wide, "{name: j_dg_1_2, limits: {lower: -5deg, upper: 5deg"))
    out = tmp_path / "pushing.mcap"
    # recorded under the same narrow profile (a recording looser than -p is refused whole)
    _recording_with(out, load_profile(str(narrow)), _held_effort(load_profile("dg-3f-m"), 10.0))
    result = cli("-p", str(narrow), "replay", str(out), "--max-deviation", "100", "--device",
                 "-t", gripper.endpoint, "--yes")
    assert result.exit_code == 5, result.stderr
    assert "j_dg_1_2 at" in result.stderr and "outside its limits [-0.0873, 0.0873]" \
        in result.stderr
    assert "Traceback" not in result.stderr
    assert eventually(lambda: gripper.firmware.duty == [0] * 12)


def test_a_setpoint_held_longer_than_recorded_is_refused_before_anything_moves(
        cli, gripper, tmp_path):
    profile = load_profile("dg-3f-m")
    rows = _held_effort(profile, 0.05, 0.1)
    t_last, last = rows[-1]
    rows.append((t_last + 800_000_000, last))  # 0.8 s without a command
    out = tmp_path / "gap.mcap"
    _recording_with(out, profile, rows)
    result = cli("replay", str(out), "--device", "-t", gripper.endpoint, "--yes")
    assert result.exit_code == 5, result.stderr
    assert "no command for" in result.stderr and "0.800 s" in result.stderr
    assert "nothing moved" in result.stderr
    assert gripper.firmware.duty == [0] * 12 and gripper.firmware.position[1] == 0.0


def test_a_recording_with_too_many_commands_is_refused_before_they_are_read(
        cli, tmp_path, monkeypatch):
    """The count comes from the file's summary: not one command row is read (the bound is
    lowered here; the real one, millions of rows, would take a test minutes to write)."""
    import deltoctl.app.replay as replay

    out = tmp_path / "jog.mcap"
    run_json(cli, "-p", "dg-3f-m", "--sim", "jog", "j_dg_1_2", "10deg", "--yes", "--record",
             str(out))

    def never(rec, topic):
        raise AssertionError(f"{topic} read")

    monkeypatch.setattr(replay, "MAX_COMMAND_ROWS", 10)
    monkeypatch.setattr(replay, "_rows", never)
    result = cli("replay", str(out))
    assert result.exit_code == 2, result.stderr
    assert "recorded commands, more than the 10 a replay takes" in result.stderr


def test_jog_record_to_a_file_that_cannot_be_written_is_refused_before_anything_opens(
        cli, tmp_path):
    unreachable = ("-p", "dg-3f-m", "-t", "tcp://127.0.0.1:9", "jog", "j_dg_1_2", "1deg",
                   "--yes", "--record")
    result = cli(*unreachable, str(tmp_path))  # a directory: refused, nothing reached
    assert result.exit_code == 2, result.stderr
    assert "cannot write" in result.stderr and "Traceback" not in result.stderr
    result = cli(*unreachable, str(tmp_path / "none" / "jog.mcap"))
    assert result.exit_code == 2 and "cannot write" in result.stderr
    # a file that can be written, then a device that cannot be reached: no empty file left
    out = tmp_path / "jog.mcap"
    result = cli(*unreachable, str(out))
    assert result.exit_code == 4, result.stderr
    assert not out.exists()


def test_record_and_jog_record_write_the_same_metadata(cli, tmp_path):
    from deltoctl.record.reader import read_recording

    plain, jogged = tmp_path / "plain.mcap", tmp_path / "jog.mcap"
    assert cli("-p", "dg-3f-m", "--sim", "record", str(plain), "--duration", "0.1"
               ).exit_code == 0
    run_json(cli, "-p", "dg-3f-m", "--sim", "jog", "j_dg_1_2", "1deg", "--yes", "--record",
             str(jogged))
    a, b = (read_recording(p).metadata for p in (plain, jogged))
    assert a["profile"] == b["profile"] and a["deltoctl"] == b["deltoctl"]
    assert set(a["identify"]) == set(b["identify"]) == {"dg3f_m_driver"}


def test_a_block_whose_commands_end_first_stops_then_not_at_the_end(cli, gripper, tmp_path):
    """The gripper's commands end after 0.05 s, the arm's go on for 2 s: the gripper's last
    effort is not held for those 2 s (its recorded move loop stopped it)."""
    from deltoctl.sim.serve import ServeOptions, serve_profile

    profile = load_profile("bioscara-dg-3f-m")
    nan = float("nan")
    base = {f"{j.name}/{k}": 0.0 for j in profile.joints() for k in ("position", "velocity")}
    blank = {f"{j}/{k}_command": nan for j in ("j4", "j_dg_1_2")
             for k in ("position", "velocity", "effort")}
    t0 = time.time_ns()
    rows = [(t0 + i * 5_000_000, {**base, **blank, "j_dg_1_2/effort_command": 0.5})
            for i in range(10)]
    rows += [(t0 + i * 5_000_000, {**base, **blank, "j4/position_command": 0.0})
             for i in range(10, 410)]
    out = tmp_path / "cell.mcap"
    _recording_with(out, profile, rows)
    writes = []  # (time, largest duty) of each message the gripper handles
    handle = gripper.firmware.handle

    def watch(data):
        reply = handle(data)
        writes.append((time.monotonic(), max(map(abs, gripper.firmware.duty))))
        return reply

    with contextlib.ExitStack() as stack:
        buses = serve_profile(stack, load_profile("bioscara-arm"), ServeOptions())["buses"]
        targets = ["-t", f"i2c={buses['i2c']}", "-t", f"gripper={gripper.endpoint}"]
        cell = ("-p", "bioscara-dg-3f-m", *targets)
        assert cli(*cell, "home", "-j", "j4", "--yes").exit_code == 0
        gripper.firmware.handle = watch
        result = cli(*cell, "replay", str(out), "--device", "--yes", "--json")
    assert result.exit_code == 0, result.stderr
    pushed = [t for t, duty in writes if duty > 0]
    assert pushed, "the gripper was never pushed"
    stopped = next(t for t, duty in writes if t > pushed[-1] and duty == 0)
    # stopped with the next row, not after the arm's 2 s (a wide margin for a loaded machine)
    assert stopped - pushed[-1] < 1.0
