"""CAN interfaces in ``deltoctl ports`` and in doctor's checks of a SocketCAN target: up or
down from a laid-out /sys/class/net, the bit rate, state and error counters from the ip
command's ``-details -statistics -json`` (an ip on PATH that prints iproute2's document), and
through the kernel's vcan where this machine has one."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from deltoctl.transport.adapters import ROOT_ENV
from tests.transport.adapter_tree import CANDLE, Tree, can_record, fake_ip

pytest.importorskip("deltoctl_canopen")
TARGET = "can://socketcan/can0?bitrate=500000"


@pytest.fixture
def tree(tmp_path, monkeypatch):
    laid = Tree(tmp_path / "root")
    laid.root.mkdir()
    monkeypatch.setenv(ROOT_ENV, str(laid.root))
    yield laid
    laid.close()


@pytest.fixture
def ip(tmp_path, monkeypatch):
    """``ip(records)``: the ip command on PATH prints those interfaces' details."""
    def install(records: list[dict]) -> None:
        folder = fake_ip(tmp_path / "bin", records)
        monkeypatch.setenv("PATH", f"{folder}{os.pathsep}{os.environ['PATH']}")
    return install


def _can_check(cli, *targets: str) -> tuple[int, dict]:
    result = cli("-p", "cia402-two-axis", "-t", *targets, "doctor", "--json")
    checks = json.loads(result.stdout)["result"]["checks"]
    return result.exit_code, next(c for c in checks if c["check"] == "can bus")


def test_ports_lists_a_can_adapter_with_its_bit_rate_and_counters(cli, tree, ip):
    tree.can("can0", up=True, usb=CANDLE)
    ip([can_record("can0", 500_000, state="ERROR-PASSIVE", tx=128, rx=3, restart_ms=100,
                   bus_off=2)])
    (can,) = json.loads(cli("ports", "--json").stdout)["result"]["can"]
    assert can["up"] and can["known"] == "candleLight / CANable (gs_usb)"
    assert (can["bitrate"], can["state"], can["restart_ms"]) == (500_000, "ERROR-PASSIVE", 100)
    assert (can["tx_errors"], can["rx_errors"], can["bus_off"]) == (128, 3, 2)
    text = cli("ports").stdout
    assert "can0  CAN  1d50:606f = candleLight / CANable (gs_usb)  up  ERROR-PASSIVE" in text
    assert "bitrate 500000" in text and "errors tx 128 rx 3" in text and "bus-off 2×" in text


def test_doctor_brings_a_down_interface_up_at_the_targets_rate(cli, tree, ip):
    tree.can("can0", up=False, usb=CANDLE)
    ip([])
    code, check = _can_check(cli, TARGET)
    assert code == 4 and not check["ok"] and check["detail"] == "can0 is down"
    assert check["fix"] == ("sudo ip link set can0 down && sudo ip link set can0 up type can "
                            "bitrate 500000 restart-ms 100")


def test_doctor_names_an_interface_at_another_bit_rate(cli, tree, ip):
    tree.can("can0", up=True, usb=CANDLE)
    ip([can_record("can0", 250_000)])
    code, check = _can_check(cli, TARGET)
    assert code == 1 and "runs at 250000 bit/s, the target at 500000" in check["detail"]
    assert "type can bitrate 500000 restart-ms 100" in check["fix"]


def test_doctor_names_a_bus_off_interface(cli, tree, ip):
    tree.can("can0", up=True, usb=CANDLE)
    ip([can_record("can0", 500_000, state="BUS-OFF", tx=255)])
    code, check = _can_check(cli, TARGET)
    assert code == 1 and "bus-off" in check["detail"]
    assert "termination" in check["fix"] and "restart-ms 100" in check["fix"]


def test_doctor_names_a_missing_interface(cli, tree, ip):
    ip([])
    code, check = _can_check(cli, TARGET)
    assert code == 4 and check["detail"] == "no network interface can0"
    assert "deltoctl ports" in check["fix"]


@pytest.mark.skipif(not Path("/sys/class/net/vcan0").exists(),
                    reason="no vcan0 (ip link add dev vcan0 type vcan)")
def test_ports_and_doctor_on_the_kernels_vcan():
    env = {k: v for k, v in os.environ.items() if k != ROOT_ENV}
    run = [sys.executable, "-m", "deltoctl"]
    ports = subprocess.run([*run, "ports", "--json"], env=env, capture_output=True, text=True,
                           timeout=60)
    vcan = next(c for c in json.loads(ports.stdout)["result"]["can"] if c["name"] == "vcan0")
    assert vcan["kind"] == "vcan"
    doctor = subprocess.run([*run, "-p", "cia402-two-axis", "-t", "can://socketcan/vcan0",
                             "doctor", "--json"], env=env, capture_output=True, text=True,
                            timeout=60)
    check = next(c for c in json.loads(doctor.stdout)["result"]["checks"]
                 if c["check"] == "can bus")
    assert check["ok"] == vcan["up"], check
