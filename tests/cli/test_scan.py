"""deltoctl scan: servos found on an emulated bus at a rate and in a protocol the scan is not
told, colliding replies named, the JSON document, and a link that is not serial refused."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from deltoctl.families.dynamixel.emulator import DynamixelBus, DynamixelPtyServer, Servo
from deltoctl.families.dynamixel.emulator1 import Protocol1Bus, Servo1
from deltoctl.families.feetech import emulator as fe
from deltoctl.families.feetech.models import BY_NUMBER

WAIT = "0.05"  # s a probe waits for a reply: generous, a loaded machine answers late
ARM = ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper")
STS3215 = next(m for m in BY_NUMBER.values() if m.name == "STS3215")


def _scan(cli, port, *more):
    result = cli("--json", "scan", port, "--wait", WAIT, *more)
    return result, json.loads(result.stdout) if result.stdout.strip() else None


def test_a_dynamixel_2_servo_at_115200(cli):
    with DynamixelPtyServer(DynamixelBus([Servo(7)], baud=115_200)) as server:
        result, doc = _scan(cli, server.port)
    assert result.exit_code == 0, result.output
    assert doc["result"]["servos"] == [{"id": 7, "model": "XL430-W250", "firmware": "46",
                                      "protocol": "Dynamixel 2.0", "baud": 115_200,
                                      "colliding": False}]
    assert doc["result"]["bus_seconds"] > 0 and doc["result"]["probes"] >= 1


def test_a_dynamixel_1_servo_by_a_sweep(cli):
    with DynamixelPtyServer(Protocol1Bus([Servo1(4)], baud=1_000_000)) as server:
        result, doc = _scan(cli, server.port)
    assert result.exit_code == 0, result.output
    [servo] = doc["result"]["servos"]
    assert (servo["id"], servo["model"], servo["protocol"], servo["baud"]) == \
        (4, "AX-12A", "Dynamixel 1.0", 1_000_000)


def test_a_feetech_servo_at_500k_as_a_table(cli):
    with fe.FeetechPtyServer(fe.FeetechBus([fe.Servo(3, STS3215)], baud=500_000)) as server:
        result = cli("scan", server.port, "--wait", WAIT)
    assert result.exit_code == 0, result.output
    assert result.stdout.splitlines()[0].split() == ["ID", "MODEL", "FIRMWARE", "BAUD",
                                                     "PROTOCOL"]
    assert result.stdout.splitlines()[1].split() == ["3", "STS3215", "3.10", "500000",
                                                     "Feetech"]
    assert "s of bus time" in result.stdout


def test_two_servos_at_one_id_are_named_colliding(cli):
    twin = fe.Servo(1, STS3215)
    twin.actual += 300  # another pose: their replies differ, so they garble
    bus = fe.FeetechBus([fe.Servo(1, STS3215), twin], baud=1_000_000)
    with fe.FeetechPtyServer(bus) as server:
        result, doc = _scan(cli, server.port)
    assert result.exit_code == 3, result.output
    assert doc["result"]["colliding"] == [1]
    assert "several servos at ID 1" in result.stderr and "one at a time" in result.stderr


@pytest.mark.parametrize(("bus", "found"), [
    (Protocol1Bus([Servo1(1)], baud=9_600), (1, "AX-12A", "Dynamixel 1.0", 9_600)),
    (Protocol1Bus([Servo1(42)], baud=57_600), (42, "AX-12A", "Dynamixel 1.0", 57_600)),
    (fe.FeetechBus([fe.Servo(1, STS3215)], baud=38_400), (1, "STS3215", "Feetech", 38_400)),
], ids=["ax-12a-at-9600", "ax-12a-at-id-42", "sts3215-at-38400"])
def test_a_servo_on_a_paced_bus_is_found_clean_at_a_slow_rate(cli, bus, found):
    """On a bus that takes the wire's time, the scan listens for as long as the wire takes
    (a read of a servo's model at 9,600 bps outlasts the wait) and its sweep of every ID
    finds a servo away from the factory's ID."""
    server = (fe.FeetechPtyServer if isinstance(bus, fe.FeetechBus) else DynamixelPtyServer)
    with server(bus, pace=True) as served:
        result, doc = _scan(cli, served.port)
    assert result.exit_code == 0, result.output
    [servo] = doc["result"]["servos"]
    assert (servo["id"], servo["model"], servo["protocol"], servo["baud"]) == found
    assert not servo["colliding"] and doc["result"]["colliding"] == []


def test_two_protocol_1_servos_at_one_id_found_by_the_sweep_are_named_colliding(cli):
    """Two AX-12A at ID 9 (not the factory's: only the sweep of every ID reaches them), in
    poses of their own: their replies garble."""
    from deltoctl.families.dynamixel.emulator1 import MixedBus

    twin = Servo1(9)
    twin.position += 25
    bus = MixedBus(Protocol1Bus([Servo1(9)], baud=1_000_000),
                   Protocol1Bus([twin], baud=1_000_000))
    with DynamixelPtyServer(bus, pace=True) as server:
        result, doc = _scan(cli, server.port)
    assert result.exit_code == 3, result.output
    assert doc["result"]["colliding"] == [9]
    assert "several servos at ID 9" in result.stderr


def test_nothing_answers_is_unreachable(cli):
    with fe.FeetechPtyServer(fe.FeetechBus([], baud=1_000_000)) as server:
        result = cli("scan", server.port, "--wait", "0.001")
    assert result.exit_code == 4
    assert "nothing answers" in result.stderr


@pytest.mark.parametrize("link", ["tcp://169.254.186.72:502", "can0", "serial://dev/ttyUSB0"])
def test_a_link_that_is_not_serial_is_a_usage_error(cli, link):
    result = cli("scan", link)
    assert result.exit_code == 2
    assert "Traceback" not in result.output


def _served(profile, *faults):
    """`deltoctl sim serve PROFILE --factory-new …` in its own process: (process, bus URL)."""
    proc = subprocess.Popen([sys.executable, "-m", "deltoctl", "sim", "serve", profile,
                             "--json", "--factory-new", *faults], stdout=subprocess.PIPE,
                            text=True)
    [url] = json.loads(proc.stdout.readline())["buses"].values()
    return proc, url


@pytest.mark.parametrize(("profile", "joints", "found"), [
    ("koch-arm", ARM, ("XL430-W250", "Dynamixel 2.0", 57_600)),
    ("so101-follower", ARM, ("STS3215", "Feetech", 1_000_000)),
    ("phantomx-arm", ("waist", "shoulder", "elbow", "wrist", "gripper"),
     ("AX-12A", "Dynamixel 1.0", 1_000_000)),  # an AX's factory rate
])
def test_factory_new_servos_collide_at_id_1_and_one_alone_is_found(cli, profile, joints, found):
    proc, url = _served(profile)
    try:
        result, doc = _scan(cli, url.split("?")[0])
    finally:
        proc.terminate()
        proc.wait(timeout=5)
    assert result.exit_code == 3, result.output
    assert doc["result"]["colliding"] == [1]
    assert "several servos at ID 1" in result.stderr
    missing = [a for j in joints[1:] for a in ("--missing", j)]
    proc, url = _served(profile, *missing)
    try:
        result, doc = _scan(cli, url.split("?")[0])
    finally:
        proc.terminate()
        proc.wait(timeout=5)
    assert result.exit_code == 0, result.output
    [servo] = doc["result"]["servos"]
    assert (servo["id"], servo["model"], servo["protocol"], servo["baud"]) == (1, *found)


def test_a_port_that_is_not_there_is_unreachable(cli, tmp_path):
    result = cli("scan", str(tmp_path / "ttyUSB9"))
    assert result.exit_code == 4
    assert "cannot open" in result.stderr


def link_scan(url, wait, every):
    """A family's scan of a link of its own scheme (test_a_family_scans_a_link_of_its_scheme)."""
    part = {"id": None, "model": "part", "firmware": "", "baud": 0, "protocol": "toy",
            "colliding": False}
    return {"target": url, "servos": [part], "probes": 1, "of": 1, "refused_bauds": [],
            "bus_seconds": 0.0, "colliding": []}


def test_a_family_scans_a_link_of_its_scheme(cli, monkeypatch):
    from deltoctl import registry

    known = registry.families()
    toy = registry.Family("toylink", driver="tests.toyfamily.driver:ToyDriver",
                          schemes=("toylink",), link_scan="tests.cli.test_scan:link_scan")
    monkeypatch.setattr(registry, "families", lambda: {**known, "toylink": toy})
    result = cli("scan", "toylink://bus0")
    assert result.exit_code == 0, result.output
    assert "none  part" in result.stdout and "1 answered on toylink://bus0" in result.stdout
    result = cli("scan", "tcp://169.254.186.72:502")
    assert result.exit_code == 2 and "toylink://" in result.stderr
