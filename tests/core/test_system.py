"""Whole robots: every verb on profiles of several blocks on several links (two DG-5F hands;
a Bioscara arm with a DG-3F-M gripper; the MH5's two buses and IMU), through the CLI and the
real transports of the simulated devices."""

from __future__ import annotations

import json
import math
import socket

import pytest

from tests.conftest import ros2_messages

BIMANUAL = "dg-5f-bimanual"
CELL = "bioscara-dg-3f-m"
LEFT, RIGHT = "DG5FLeftHardware", "DG5FRightHardware"


def _targets(buses: dict[str, str]) -> list[str]:
    return [a for bus, url in buses.items() for a in ("-t", f"{bus}={url}")]


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_connect_identify_detect_report_every_block(cli):
    for profile, blocks in ((BIMANUAL, [LEFT, RIGHT]), (CELL, ["bioscara_arm", "dg3f_m_driver"]),
                            ("mh5", ["upper_body", "lower_body", "i2c"])):
        for verb in ("connect", "identify", "detect"):
            result = cli("-p", profile, "--sim", verb, "--json")
            assert result.exit_code == 0, (profile, verb, result.stderr)
            report = json.loads(result.stdout)
            assert [b["name"] for b in report["blocks"]] == blocks, (profile, verb)
            for b in report["blocks"]:  # one shape whatever the family
                assert {"name", "family", "target", "state"} <= set(b)
    identity = json.loads(cli("-p", BIMANUAL, "--sim", "identify", "--json").stdout)
    models = [b["identity"]["reported_model"] for b in identity["blocks"]]
    assert models == ["DG-5F-L (0x5f12)", "DG-5F-R (0x5f22)"]


def test_people_get_a_table_per_block(cli):
    result = cli("-p", BIMANUAL, "--sim", "identify")
    assert result.exit_code == 0, result.stderr
    assert LEFT in result.stdout and RIGHT in result.stdout


def test_jog_finds_the_block_from_the_joint(cli, deltoctl_sim):
    buses = deltoctl_sim.buses(BIMANUAL)
    for joint, delta in (("rj_dg_1_2", "-5deg"), ("lj_dg_1_2", "5deg")):
        result = cli("-p", BIMANUAL, *_targets(buses), "--yes", "--json", "jog", joint, "--",
                     delta)
        assert result.exit_code == 0, result.stderr
        report = json.loads(result.stdout)
        assert report["result"]["settled"]
        assert [b["name"] for b in report["blocks"]] == [RIGHT if joint[0] == "r" else LEFT]
        moved = report["blocks"][0]["joints"][joint]
        assert abs(moved["position"] - moved["target"]) < math.radians(2)


def test_home_moves_both_hands_at_once(cli):
    result = cli("-p", BIMANUAL, "--sim", "--yes", "--json", "home")
    assert result.exit_code == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["result"]["settled"] and report["result"]["cannot_home"] == []
    assert [b["name"] for b in report["blocks"]] == [LEFT, RIGHT]
    assert sum(len(b["joints"]) for b in report["blocks"]) == 40


def test_cell_homes_the_arm_by_its_routine_then_jogs_both(cli, deltoctl_sim):
    t = _targets(deltoctl_sim.buses(CELL))
    result = cli("-p", CELL, *t, "--yes", "--json", "home")
    assert result.exit_code == 0, result.stderr
    report = json.loads(result.stdout)
    arm, gripper = report["blocks"]
    assert arm["name"] == "bioscara_arm"
    assert {j["outcome"] for j in arm["joints"].values()} == {"homed"}
    assert gripper["name"] == "dg3f_m_driver" and report["result"]["settled"]
    for joint, delta in (("j1", "-0.1"), ("j_dg_1_2", "5deg")):  # I2C, then TCP
        result = cli("-p", CELL, *t, "--yes", "--json", "jog", joint, "--", delta)
        assert result.exit_code == 0, (joint, result.stderr)
        assert json.loads(result.stdout)["result"]["settled"]


def test_gpio_by_name_on_either_hand(cli, deltoctl_sim):
    t = _targets(deltoctl_sim.buses(BIMANUAL))
    assert cli("-p", BIMANUAL, *t, "gpio", "set", "right_gpio/output_2", "on").exit_code == 0
    values = json.loads(cli("-p", BIMANUAL, *t, "--json", "gpio", "get").stdout)["result"]
    assert values["right_gpio/output_2"] == 1.0 and values["left_gpio/output_2"] == 0.0


def test_stream_carries_every_block_with_a_status_each(cli):
    result = cli("-p", CELL, "--sim", "--json", "stream", "--rate", "50", "--duration", "0.2")
    assert result.exit_code == 0, result.stderr
    frames = [json.loads(line) for line in result.stdout.splitlines()]
    last = frames[-1]["values"]
    assert last["bioscara_arm/connection_status"] == 1.0
    assert last["dg3f_m_driver/connection_status"] == 1.0
    assert last["system/connection_status"] == 1.0
    assert all(v is not None for k, v in last.items() if k.endswith("/position"))


def test_record_of_two_hands_decodes_with_40_finite_joints(cli, tmp_path):
    out = tmp_path / "hands.mcap"
    result = cli("-p", BIMANUAL, "--sim", "record", str(out), "--rate", "100",
                 "--duration", "0.5")
    assert result.exit_code == 0, result.stderr
    states = [m for topic, m in ros2_messages(out, ["/joint_states"])]
    assert states
    for msg in states:
        assert len(msg.name) == 40
        assert all(math.isfinite(p) for p in msg.position)
    assert {n[0] for n in states[0].name} == {"l", "r"}
    wrenches = {topic for topic, _ in ros2_messages(out) if topic.endswith("/wrench")}
    assert len(wrenches) == 10


def test_one_block_unreachable_is_named_and_hardware_narrows(cli, deltoctl_sim):
    buses = deltoctl_sim.buses(BIMANUAL)
    buses["right"] = f"tcp://127.0.0.1:{_closed_port()}"
    result = cli("-p", BIMANUAL, *_targets(buses), "connect", "-n", "2")
    assert result.exit_code == 4
    assert RIGHT in result.stderr and "--hardware DG5FLeftHardware" in result.stderr
    result = cli("-p", BIMANUAL, *_targets(buses), "--hardware", LEFT, "--json", "connect")
    assert result.exit_code == 0, result.stderr
    assert [b["name"] for b in json.loads(result.stdout)["blocks"]] == [LEFT]


def test_a_joint_outside_the_chosen_blocks_is_a_usage_error(cli):
    result = cli("-p", BIMANUAL, "--sim", "--hardware", LEFT, "--yes", "jog", "rj_dg_1_2",
                 "--", "-5deg")
    assert result.exit_code == 2
    assert RIGHT in result.stderr and "--hardware" in result.stderr
    result = cli("-p", BIMANUAL, "--sim", "--hardware", "nope", "connect")
    assert result.exit_code == 2 and LEFT in result.stderr


def test_sim_serve_serves_every_block(cli):
    import contextlib

    from deltoctl.profile.catalog import load_profile
    from deltoctl.sim.serve import ServeOptions, serve_profile

    with contextlib.ExitStack() as stack:
        served = serve_profile(stack, load_profile(BIMANUAL), ServeOptions())
        assert set(served["buses"]) == {"left", "right"}
        assert "endpoint" not in served  # two buses: no single endpoint
        assert served["blocks"][RIGHT]["model"] == "DG-5F-R"
        served = serve_profile(stack, load_profile(CELL), ServeOptions(),
                               hardware=["dg3f_m_driver"])
        assert set(served["buses"]) == {"gripper"}


def test_a_bare_target_is_ambiguous_on_two_buses(cli):
    result = cli("-p", BIMANUAL, "-t", "tcp://127.0.0.1:1", "connect")
    assert result.exit_code == 2 and "--target BUS=URL" in result.stderr


def test_serve_options_are_checked_against_the_profiles_families(cli):
    result = cli("sim", "serve", "mh5", "--firmware", "2.7")
    assert result.exit_code == 2 and "--firmware" in result.stderr


@pytest.mark.parametrize("option", ["--rate", "--duration"])
@pytest.mark.parametrize("value", ["nan", "inf", "-5", "0"])
def test_loop_options_must_be_finite_and_positive(cli, option, value):
    result = cli("-p", BIMANUAL, "--sim", "stream", option, value)
    assert result.exit_code == 2, result.stdout


def test_the_cell_bringup_script_runs_every_verb(tmp_path):
    import os
    import subprocess
    import sys
    from pathlib import Path

    from tests.conftest import REPO

    deltoctl = Path(sys.executable).parent / "deltoctl"
    if not deltoctl.exists():
        pytest.skip("the deltoctl script is not installed")
    env = {**os.environ, "DELTOCTL": str(deltoctl), "OUT": str(tmp_path)}
    result = subprocess.run(["bash", str(REPO / "examples" / "bringup-cell.sh")], env=env,
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    assert (tmp_path / "cell.mcap").stat().st_size > 0


def test_calibrate_tares_every_hand_and_writes_a_report_each(cli, tmp_path):
    result = cli("-p", BIMANUAL, "--sim", "--json", "calibrate", "ft", "-n", "5",
                 "-o", str(tmp_path))
    assert result.exit_code == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["result"]["pass"] and [r["block"] for r in report["blocks"]] == [LEFT, RIGHT]
    assert len(list(tmp_path.glob("calibration-*.json"))) == 2
    assert all(len(r["sensors"]) == 5 for r in report["blocks"])


def test_mh5_torque_reboot_register_reach_both_buses(cli, deltoctl_sim):
    t = _targets(deltoctl_sim.buses("mh5"))
    result = cli("-p", "mh5", *t, "--yes", "--json", "torque", "on", "all")
    assert result.exit_code == 0, result.stderr
    assert len(json.loads(result.stdout)["result"]["joints"]) == 22
    result = cli("-p", "mh5", *t, "--json", "reboot", "legs")
    assert result.exit_code == 0, result.stderr
    assert len(json.loads(result.stdout)["result"]["rebooted"]) == 12
    result = cli("-p", "mh5", *t, "--json", "register", "get", "r_ank_r", "present_temperature")
    assert result.exit_code == 0, result.stderr
    assert json.loads(result.stdout)["result"]["values"] == {"Present Temperature": 30}
