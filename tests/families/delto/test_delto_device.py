"""Every verb end to end: CLI → driver → real TCP socket → the gripper emulator."""

from __future__ import annotations

import json
import math
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from deltoctl.core.system import System
from deltoctl.families.delto.emulator import DeltoServer, firmware_for_profile
from deltoctl.profile.catalog import load_profile
from tests.conftest import block_of

DELTO = ["dg-3f-b", "dg-3f-m", "dg-4f", "dg-5f-left", "dg-5f-right", "dg-5f-s-left",
         "dg-5f-s-right", "dg-5f-s15-left", "dg-5f-s15-right"]


@pytest.fixture
def gripper():
    """An emulated gripper for a profile, served on loopback; yields (server, profile name)."""
    servers = []

    def start(name: str, **options):
        server = DeltoServer(firmware_for_profile(load_profile(name), **options)).start()
        servers.append(server)
        return server

    yield start
    for server in servers:
        server.close()


@pytest.mark.parametrize("name", DELTO)
def test_identify_every_model(cli, gripper, name):
    server = gripper(name)
    result = cli("-p", name, "-t", server.endpoint, "identify", "--json")
    assert result.exit_code == 0, result.stderr
    entry = block_of(json.loads(result.stdout))
    assert entry["family"] == "delto" and entry["target"] == server.endpoint
    ident = entry["identity"]
    assert ident["model_match"] is True
    assert ident["reported_model"].startswith(load_profile(name).model)
    # the emulator reports firmware 3.0: revised everywhere but on the DG-3F-B (from 3.6)
    assert ident["direction_map"] == ("legacy" if name == "dg-3f-b" else "revised")


@pytest.mark.parametrize("name", DELTO)
def test_connect_detect_and_stream_every_model(cli, name):
    result = cli("--sim", "-p", name, "connect", "--json", "-n", "3")
    assert result.exit_code == 0, result.stderr
    assert block_of(json.loads(result.stdout))["lifecycle"][-1] == "finalized"
    result = cli("--sim", "-p", name, "detect", "--json")
    assert result.exit_code == 0, result.stderr
    checks = block_of(json.loads(result.stdout))["checks"]
    assert checks and all(c["match"] for c in checks)
    result = cli("--sim", "-p", name, "stream", "--json", "--duration", "0.1", "--rate", "40")
    assert result.exit_code == 0, result.stderr
    lines = [json.loads(line) for line in result.stdout.splitlines()]
    assert len(lines) >= 2
    profile = load_profile(name)
    assert set(lines[-1]["values"]) == set(profile.state_interfaces()) | {
        f"{hw.name}/connection_status" for hw in profile.hardware} | {
        "system/connection_status"}
    assert all(v is not None for v in lines[-1]["values"].values())


def test_stream_selects_interfaces(cli):
    result = cli("--sim", "-p", "dg-5f-right", "stream", "-d", "0.05",
                 "-i", "rj_dg_1_*/position", "-i", "right_fingertip_finger_1/force.z")
    assert result.exit_code == 0
    names = set(json.loads(result.stdout.splitlines()[0])["values"])
    assert names == {f"rj_dg_1_{j}/position" for j in range(1, 5)} | {
        "right_fingertip_finger_1/force.z"}
    assert cli("--sim", "-p", "dg-5f-right", "stream", "-d", "0.05", "-i", "nope*").exit_code == 2


def test_the_live_table_has_a_row_per_part(cli):
    from rich.console import Console

    from deltoctl.render.stream import live_tables

    result = cli("--sim", "-p", "dg-5f-right", "stream", "-d", "0.05")
    sample = json.loads(result.stdout.splitlines()[-1])["values"]
    console = Console(record=True, width=120)
    console.print(live_tables(sample, "3 samples at 50 Hz"))
    lines = [line for line in console.export_text().splitlines() if line.strip()]
    assert "3 samples at 50 Hz · links up" in lines[0]
    assert lines[1].split() == ["position", "velocity", "effort", "temperature"]
    assert lines[2].split() == ["(°C)"]  # the joints' types not given: no unit for position
    rows = {line.split()[0]: line.split()[1:] for line in lines if line.strip()[:3] in
            ("rj_", "rig", "gpi")}
    assert len(rows) == 20 + 5 + 1  # joints, fingertips, the GPIO block
    assert rows["rj_dg_1_1"][3] == f"{sample['rj_dg_1_1/temperature']:.1f}"
    assert len(rows["right_fingertip_finger_3"]) == 6 and len(rows["gpio"]) == 4


def test_old_firmware_selects_the_legacy_direction_map(cli, gripper):
    server = gripper("dg-5f-right", firmware=(2, 7))
    ident = block_of(json.loads(cli("-p", "dg-5f-right", "-t", server.endpoint, "identify",
                                    "--json").stdout))["identity"]
    assert ident["direction_map"] == "legacy"
    assert ident["direction"][:4] == [1, 1, -1, -1]
    # a positive effort still moves joint 3 (wired reversed on this firmware) positive
    profile = load_profile("dg-5f-right")
    with System(profile, [server.endpoint]) as system:
        (member,) = system.members
        member.driver.write_efforts({"rj_dg_1_3": 0.3})
        time.sleep(0.2)
        assert server.firmware.duty[2] < 0
        assert system.read()["rj_dg_1_3/position"] > 0.01


def test_short_version_reply_of_old_firmware(cli, gripper):
    server = gripper("dg-3f-m", firmware=(2, 2), short_version=True)
    ident = block_of(json.loads(cli("-p", "dg-3f-m", "-t", server.endpoint, "identify",
                                    "--json").stdout))["identity"]
    assert ident["short_version_reply"] is True
    assert ident["sensor_type"] == "ft_6axis"  # assumed from the profile's fingertip sensors
    assert ident["direction_map"] == "legacy"


def test_model_mismatch_is_a_clear_error_or_a_warning(cli, gripper):
    server = gripper("dg-5f-right", model_id=0x4F02)
    result = cli("-p", "dg-5f-right", "-t", server.endpoint, "identify")
    assert result.exit_code == 1
    assert "model mismatch" in result.stderr and "DG-4F" in result.stderr
    assert "--allow-model-mismatch" in result.stderr
    result = cli("-p", "dg-5f-right", "-t", server.endpoint, "identify", "--json",
                 "--allow-model-mismatch")
    assert result.exit_code == 3
    assert block_of(json.loads(result.stdout))["identity"]["reported_model"] == "DG-4F (0x4f02)"
    assert "model mismatch" in result.stderr  # the warning behind exit 3


def test_unreachable_device_exits_4(cli):
    result = cli("-p", "dg-4f", "-t", "tcp://127.0.0.1:9", "identify")
    assert result.exit_code == 4
    assert "cannot connect" in result.stderr


def test_a_silent_peer_exits_4_naming_developer_mode(cli):
    # something accepts the connection (a gripper in Modbus mode, another service) and
    # closes it without a version reply
    with socket.create_server(("127.0.0.1", 0)) as listener:
        port = listener.getsockname()[1]
        closer = threading.Thread(target=lambda: listener.accept()[0].close())
        closer.start()
        result = cli("-p", "dg-4f", "-t", f"tcp://127.0.0.1:{port}", "identify")
        closer.join()
    assert result.exit_code == 4
    assert "no version reply" in result.stderr and "developer mode" in result.stderr


def test_gpio_get_and_set(cli, gripper, tmp_path):
    server = gripper("dg-5f-right")
    server.firmware.input_1 = True
    target = ("-p", "dg-5f-right", "-t", server.endpoint)
    state = json.loads(cli(*target, "gpio", "get", "--json").stdout)["result"]
    assert state == {"gpio/output_1": 0.0, "gpio/output_2": 0.0, "gpio/output_3": 0.0,
                     "gpio/input_1": 1.0}
    result = cli("--yes", *target, "gpio", "set", "output_2", "on", "--json")
    assert result.exit_code == 0, result.stderr
    assert json.loads(result.stdout)["result"]["gpio/output_2"] == 1.0
    assert server.firmware.gpio_out == [False, True, False]
    cli("--yes", *target, "gpio", "set", "output_1", "on")
    assert server.firmware.gpio_out == [True, True, False]  # the others keep their state
    assert cli(*target, "gpio", "set", "output_9", "on").exit_code == 2
    assert cli(*target, "gpio", "set", "output_1", "maybe").exit_code == 2
    no_gpio = cli("--sim", "-p", "dg-5f-s15-right", "gpio", "get")
    assert no_gpio.exit_code == 2 and "has no GPIO" in no_gpio.stderr  # none in the profile
    # GPIO in the profile, but IO false: the gripper sends none
    custom = tmp_path / "no-io.yaml"
    text = Path(load_profile("dg-5f-right").source).read_text()
    assert "IO: true" in text
    custom.write_text(text.replace("IO: true", "IO: false"))
    silent = cli("-p", str(custom), "-t", server.endpoint, "gpio", "get")
    assert silent.exit_code == 1 and "send no GPIO values" in silent.stderr


def test_reconnect_after_the_link_drops(gripper):
    server = gripper("dg-5f-right")
    profile = load_profile("dg-5f-right")
    statuses = []
    with System(profile, [server.endpoint]) as system:
        (member,) = system.members
        driver = member.driver
        statuses.append(system.read()["system/connection_status"])
        server.drop_connections()
        deadline = time.monotonic() + 5
        seen_down = False
        while time.monotonic() < deadline:
            values = system.read()
            status = values["system/connection_status"]
            assert values[member.status_key] == status  # the one block's link is the system's
            seen_down = seen_down or status == 0.0
            if seen_down and status == 1.0:
                break
            time.sleep(0.05)
        statuses.append(status)
    assert seen_down and statuses == [1.0, 1.0]
    assert driver.stats["reconnects"] == 1


def test_a_reopened_link_is_stopped_and_counted_before_it_is_used(gripper, monkeypatch):
    """The moment a read sees the link back, its reconnect is counted and duty 0 has
    reached the gripper (however slowly the stop is built): motion never resumes by itself,
    and nothing reads a link whose reconnect is not yet counted."""
    from deltoctl.families.delto import codec

    server = gripper("dg-5f-right")
    with System(load_profile("dg-5f-right"), [server.endpoint]) as system:
        driver = system.members[0].driver
        driver.write_efforts({"rj_dg_2_2": 0.5})
        system.read()
        assert server.firmware.duty[5] != 0
        encode_duty = codec.encode_duty

        def slow_encode_duty(duties: list[int]) -> bytes:
            time.sleep(0.3)
            return encode_duty(duties)

        monkeypatch.setattr(codec, "encode_duty", slow_encode_duty)
        server.drop_connections()
        deadline = time.monotonic() + 10
        seen_down = False
        while time.monotonic() < deadline:
            status = system.read()["system/connection_status"]
            seen_down = seen_down or status == 0.0
            if seen_down and status == 1.0:
                break
            time.sleep(0.02)
        assert seen_down and status == 1.0
        assert driver.stats["reconnects"] == 1
        assert server.firmware.duty == [0] * 20  # a reply on the new link: its stop came first


def test_leaving_a_system_sets_duty_zero(gripper):
    server = gripper("dg-5f-right")
    with System(load_profile("dg-5f-right"), [server.endpoint]) as system:
        system.members[0].driver.write_efforts({"rj_dg_2_2": 0.5})
        system.read()
        assert server.firmware.duty[5] != 0
    time.sleep(0.05)
    assert server.firmware.duty == [0] * 20


def test_each_cycles_efforts_reach_the_gripper_held_changed_or_zero(gripper):
    """The cycle's write by interface: a held effort, a change, zero everywhere and a NaN
    each reach the gripper as the duties they stand for."""
    from deltoctl.families.delto.models import effort_to_duty_percent
    from tests.conftest import eventually

    server = gripper("dg-5f-right")
    with System(load_profile("dg-5f-right"), [server.endpoint]) as system:
        driver = system.members[0].driver
        keys = [f"{j.name}/effort" for j in driver.hw.joints]
        zero = dict.fromkeys(keys, 0.0)
        for efforts, joint, effort in [({keys[3]: 0.2}, 3, 0.2), ({keys[3]: 0.2}, 3, 0.2),
                                       ({keys[3]: -0.1}, 3, -0.1), ({}, 3, 0.0),
                                       ({keys[7]: 0.2}, 7, 0.2), ({keys[7]: math.nan}, 7, 0.0),
                                       ({keys[7]: 0.2}, 7, 0.2)]:
            server.firmware.duty[:] = [99] * 20  # what the gripper had: each write resets it
            driver.write({**zero, **efforts})
            duty = int(effort_to_duty_percent(effort) * 10)
            expected = [duty if i == joint else 0 for i in range(20)]
            assert eventually(lambda expected=expected: server.firmware.duty == expected)


def test_sim_serve_in_another_process(tmp_path):
    proc = subprocess.Popen([sys.executable, "-m", "deltoctl", "sim", "serve", "dg-5f-left",
                             "--json"], stdout=subprocess.PIPE, text=True)
    try:
        endpoint = json.loads(proc.stdout.readline())["endpoint"]
        out = subprocess.run([sys.executable, "-m", "deltoctl", "-p", "dg-5f-left", "-t",
                              endpoint, "identify", "--json"], capture_output=True, text=True)
        assert out.returncode == 0, out.stderr
        identity = block_of(json.loads(out.stdout))["identity"]
        assert identity["reported_model"] == "DG-5F-L (0x5f12)"
    finally:
        proc.terminate()
        assert proc.wait(timeout=5) == 0


def test_truncated_and_late_replies_are_counted_and_recovered(gripper):
    server = gripper("dg-4f")
    with System(load_profile("dg-4f"), [server.endpoint]) as system:
        driver = system.members[0].driver
        system.read()
        server.firmware.faults.truncate_next = True
        assert system.read()["system/connection_status"] == 0.0  # half a frame: timed out
        assert not driver.connected and driver.stats["errors"] == 1
        deadline = time.monotonic() + 5
        while system.read()["system/connection_status"] == 0.0 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert driver.connected
        server.firmware.faults.delay = 0.7  # beyond the 0.5 s data timeout
        driver.read()
        assert driver.stats["errors"] == 2
        server.firmware.faults.delay = 0.0


def test_sim_serve_faults_from_the_command_line(cli):
    result = cli("sim", "serve", "dg-4f", "--stall", "j_dg_9_9")
    assert result.exit_code == 2 and "no joint 'j_dg_9_9'" in result.stderr


def _a_joint(system: System) -> str:
    return next(k.split("/")[0] for k in system.read() if k.endswith("/position"))


def test_a_link_lost_during_a_move_raises_link_lost(gripper):
    from deltoctl.errors import LinkLost

    server = gripper("dg-4f")
    with System(load_profile("dg-4f"), [server.endpoint]) as system:
        driver, joint = system.members[0].driver, _a_joint(system)
        with pytest.raises(LinkLost, match="lost during the move"):
            driver.move({joint: 0.2}, progress=lambda _: driver._lost(OSError("unplugged")))


def test_a_gripper_that_does_not_answer_a_move_raises_no_answer(gripper):
    from deltoctl.errors import NoAnswer

    server = gripper("dg-4f")
    with System(load_profile("dg-4f"), [server.endpoint]) as system:
        driver, joint = system.members[0].driver, _a_joint(system)
        server.firmware.faults.delay = 0.7  # beyond the 0.5 s data timeout
        with pytest.raises(NoAnswer, match="not answering"):
            driver.move({joint: 0.2})
        server.firmware.faults.delay = 0.0


def test_a_move_halted_before_its_first_cycle_ends_unsettled(gripper):
    server = gripper("dg-4f")
    with System(load_profile("dg-4f"), [server.endpoint]) as system:
        driver, joint = system.members[0].driver, _a_joint(system)
        driver.halted.set()
        try:
            result = driver.move({joint: 0.2})
        finally:
            driver.halted.clear()
    assert result.settled is False and result.unsettled == [joint]
