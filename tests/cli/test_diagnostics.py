"""Seeing the wire (-v, -vv, --log-file) and ``deltoctl doctor``."""

from __future__ import annotations

import json
import os
import socket
import subprocess

import pytest

from deltoctl import trace
from deltoctl.transport.tcp import TcpLink


@pytest.fixture(autouse=True)
def _trace_off():
    yield
    trace.configure(0, None)


def _packets(lines: list[dict]) -> list[dict]:
    return [line for line in lines if line["logger"] == "deltoctl.wire"]


# -- the trace --------------------------------------------------------------------------------

def test_vv_traces_every_packet_on_stderr_only(cli):
    result = cli("--sim", "-p", "dg-5f-right", "-vv", "identify", "--json")
    assert result.exit_code == 0, result.stderr
    assert json.loads(result.stdout)["blocks"][0]["identity"]["model_match"] is True
    assert "connected in" in result.stderr
    tx = [line for line in result.stderr.splitlines() if " tx 127.0.0.1:" in line]
    rx = [line for line in result.stderr.splitlines() if " rx 127.0.0.1:" in line]
    assert tx and rx and "00 03 08" in tx[0]  # GET_VERSION: length 3, command 0x08


def test_v_shows_links_without_packets(cli):
    result = cli("--sim", "-p", "dg-5f-right", "-v", "connect", "-n", "2")
    assert result.exit_code == 0
    assert "connected in" in result.stderr and "closed" in result.stderr
    assert " tx " not in result.stderr


def test_log_file_is_ndjson_with_every_packet(cli, tmp_path):
    log = tmp_path / "wire.ndjson"
    result = cli("--sim", "-p", "dg-5f-right", "--log-file", str(log), "connect", "-n", "3")
    assert result.exit_code == 0 and result.stderr == ""  # the terminal stays calm
    lines = [json.loads(line) for line in log.read_text().splitlines()]
    packets = _packets(lines)
    assert {p["dir"] for p in packets} == {"tx", "rx"}
    for p in packets:
        assert p["len"] == len(bytes.fromhex(p["hex"])) and p["bus"].startswith("127.0.0.1:")
        assert isinstance(p["t"], int)
    assert any(line["logger"] == "deltoctl.link" for line in lines)


def test_log_file_from_the_environment_and_the_i2c_trace(cli, tmp_path):
    log = tmp_path / "i2c.ndjson"
    result = cli("--sim", "-p", "bioscara-arm", "connect", "-n", "1",
                 env={"DELTOCTL_LOG": str(log)})
    assert result.exit_code == 0, result.stderr
    packets = _packets([json.loads(line) for line in log.read_text().splitlines()])
    assert any(p["bus"].endswith("@0x11") and p["dir"] == "rx" for p in packets)


def test_a_log_file_that_cannot_be_written_is_a_usage_error(cli, tmp_path):
    result = cli("--log-file", str(tmp_path / "no" / "such" / "dir.log"), "profile", "list")
    assert result.exit_code == 2 and "--log-file" in result.stderr


def test_an_untraced_link_keeps_its_methods():
    """Zero cost when off: the class's send and recv_into, no wrapper, no check per packet."""
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]
    try:
        link = TcpLink("127.0.0.1", port)
        assert "send" not in vars(link) and "recv_into" not in vars(link)
        link.close()
        trace.configure(2, None)
        traced = TcpLink("127.0.0.1", port)
        assert "send" in vars(traced) and "recv_into" in vars(traced)
        traced.close()
    finally:
        server.close()


# -- doctor -----------------------------------------------------------------------------------

def test_doctor_passes_on_simulated_devices(cli):
    result = cli("--sim", "-p", "dg-5f-right", "doctor")
    assert result.exit_code == 0, result.stdout
    assert "✘" not in result.stdout and "3 of 3 checks passed" in result.stdout
    doc = json.loads(cli("--sim", "-p", "mh5", "doctor", "--json").stdout)["result"]
    assert doc["ok"] is True and doc["profile"] == "mh5"
    subjects = {c["subject"] for c in doc["checks"]}
    assert {"upper_body", "lower_body", "i2c"} <= subjects


def test_doctor_on_the_fixture_target(cli, deltoctl_sim):
    target = deltoctl_sim("bioscara-arm")
    result = cli("-p", "bioscara-arm", "-t", target, "doctor", "--json")
    assert result.exit_code == 0 and json.loads(result.stdout)["result"]["ok"] is True


def test_doctor_names_a_refused_target_and_the_fix(cli):
    result = cli("-p", "dg-5f-right", "-t", "tcp://127.0.0.1:1", "doctor")
    assert result.exit_code == 4
    assert "✘ gripper" in result.stdout and "refused" in result.stdout
    assert "fix: switch the gripper to developer mode" in result.stdout


def test_doctor_finds_a_host_without_a_link_local_address(cli, monkeypatch):
    from deltoctl.transport import doctor

    monkeypatch.setattr(doctor, "source_address", lambda host, port: "192.168.1.20")
    monkeypatch.setattr(doctor, "reach", lambda target, host, port:
                        doctor.check("reachable", target.bus, False, "no connection", "ping"))
    doc = json.loads(cli("-p", "dg-5f-right", "doctor", "--json").stdout)["result"]
    route = next(c for c in doc["checks"] if c["check"] == "route")
    assert not route["ok"] and "no 169.254.x.x address" in route["detail"]
    assert route["fix"].startswith("sudo ip addr add 169.254.")
    monkeypatch.setattr(doctor, "source_address", lambda host, port: "169.254.186.1")
    doc = json.loads(cli("-p", "dg-5f-right", "doctor", "--json").stdout)["result"]
    assert next(c for c in doc["checks"] if c["check"] == "route")["ok"]


def test_doctor_finds_missing_buses_and_bad_targets(cli):
    result = cli("-p", "bioscara-arm", "-t", "i2c:///dev/i2c-99", "doctor", "--json")
    assert result.exit_code == 4
    present = json.loads(result.stdout)["result"]["checks"][1]
    assert present["check"] == "present" and "modprobe i2c-dev" in present["fix"]
    result = cli("-p", "dg-5f-right", "-t", "tcp://127.0.0.1:1?baud=9600", "doctor")
    assert result.exit_code == 2 and "unknown key 'baud'" in result.stdout
    result = cli("-p", "dg5f", "doctor")
    assert result.exit_code == 2 and "✘ dg5f" in result.stdout


def test_doctor_names_the_process_holding_a_serial_port(cli):
    master, slave = os.openpty()
    path = os.ttyname(slave)
    holder = subprocess.Popen(["sleep", "30"], stdin=slave)
    try:
        doc = json.loads(cli("-t", f"serial://{path}?baud=1000000", "doctor", "--json").stdout)["result"]
        checks = {c["check"]: c for c in doc["checks"]}
        assert checks["present"]["ok"] and checks["permission"]["ok"]
        assert not checks["free"]["ok"] and f"{holder.pid} (sleep)" in checks["free"]["detail"]
        assert checks["free"]["fix"] == f"close it, or: kill {holder.pid}"
    finally:
        holder.kill()
        holder.wait()
        os.close(master)
        os.close(slave)


def test_doctor_names_a_permission_problem(cli, monkeypatch):
    from deltoctl.transport import doctor

    master, slave = os.openpty()
    monkeypatch.setattr(doctor.os, "access", lambda path, mode: False)
    try:
        doc = json.loads(cli("-t", f"serial://{os.ttyname(slave)}", "doctor", "--json").stdout)["result"]
    finally:
        os.close(master)
        os.close(slave)
    permission = next(c for c in doc["checks"] if c["check"] == "permission")
    assert not permission["ok"] and permission["fix"].startswith("sudo usermod -aG ")
