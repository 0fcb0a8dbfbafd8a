"""A six-servo arm from the box to calibrated, as a technician walks it, on one emulated bus
whose servos keep what each step wrote: the Koch arm (Dynamixel) and the SO-101 (Feetech),
factory-new. The scan names the servos colliding at ID 1; setup gives each joint its ID and
rate one servo at a time, refusing two servos connected and a joint the profile lacks; with
every servo connected, identify is clean; calibrate joints takes the middle pose and the range
moved by hand and writes it; identify is clean again; a homing offset changed behind
deltoctl's back is named at the next open; and the vendors' SDKs (dynamixel-sdk, scservo_sdk)
read every ID, rate, homing offset and position limit. Once through the library, on the
``deltoctl_sim`` fixture's buses, and once through the command line, against a ``sim serve
--factory-new`` process moved by control lines on its standard input."""

from __future__ import annotations

import json
import queue
import subprocess
import sys
import threading
from dataclasses import dataclass
from pathlib import Path

import pytest

from deltoctl import open_robot
from deltoctl.app.joint_calibration import PERMISSIONS, calibration_file

ARM = ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper")
WAIT = 0.05  # s a probe waits: generous, a loaded machine answers late
MIDDLE = 20.0  # degrees of each shaft: the arm's middle pose
LOW, HIGH = -30.0, 50.0  # the range a hand moves each joint through
CHANGED = 123  # a homing offset written behind deltoctl's back
REPLY = 60.0  # s to wait for an awaited reply or line: a loaded machine is slow


@dataclass(frozen=True)
class Arm:
    """What differs between the two arms: the profile, its bus and robot type, the servos'
    models, their rate as they come, the homing offset's register name."""

    profile: str
    bus: str
    robot_type: str
    models: tuple[int, ...]
    factory_baud: int
    homing_register: str


KOCH = Arm("koch-arm", "dxl", "koch_follower", (1060, 1060, 1200, 1200, 1200, 1200), 57_600,
           "Homing Offset")
SO101 = Arm("so101-follower", "so_bus", "so_follower", (777,) * 6, 1_000_000,
            "Homing_Offset")
ARMS = pytest.mark.parametrize("arm", [KOCH, SO101], ids=lambda a: a.profile)


@pytest.fixture(autouse=True)
def _data_dirs(tmp_path, monkeypatch):
    """The calibration files (deltoctl's, LeRobot's) in the test's own directory, also for
    the processes it starts."""
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    monkeypatch.setenv("HF_LEROBOT_CALIBRATION", str(tmp_path / "lerobot"))


# -- the vendors' SDKs ------------------------------------------------------------------------

class Peer:
    """The bus through its vendor's SDK at 1 Mbps, each reply awaited 0.5 s (the SDKs' own
    34 ms is short on a loaded machine)."""

    def __init__(self, arm: Arm, url: str) -> None:
        self.arm = arm
        self.dynamixel = arm.profile == "koch-arm"
        self.sdk = pytest.importorskip("dynamixel_sdk" if self.dynamixel else "scservo_sdk")
        self.port = self.sdk.PortHandler(url.split("?")[0].removeprefix("serial://"))
        self.ph = self.sdk.PacketHandler(2.0 if self.dynamixel else 0)

    def __enter__(self) -> Peer:
        port = self.port
        assert port.openPort() and port.setBaudRate(1_000_000)
        port.setPacketTimeout = lambda _length: port.setPacketTimeoutMillis(500)
        return self

    def __exit__(self, *_: object) -> None:
        self.port.closePort()

    def _read(self, device_id: int, address: int, size: int) -> int:
        read = self.ph.read1ByteTxRx if size == 1 else (
            self.ph.read2ByteTxRx if size == 2 else self.ph.read4ByteTxRx)
        value, result, error = read(self.port, device_id, address)
        assert (result, error) == (self.sdk.COMM_SUCCESS, 0), (device_id, address)
        return value

    def registers(self) -> dict[int, tuple[int, int, int, int]]:
        """ID → (model, baud code, homing offset, min, max position limit): every servo
        pinged at its ID, at 1 Mbps, then its registers read."""
        found = {}
        for device_id, model in enumerate(self.arm.models, 1):
            assert self.ph.ping(self.port, device_id) == (model, self.sdk.COMM_SUCCESS, 0)
            if self.dynamixel:  # Baud Rate 3 is 1 Mbps; the offset in two's complement
                offset = self._read(device_id, 20, 4)
                found[device_id] = (self._read(device_id, 8, 1),
                                    offset - (1 << 32) if offset >= 1 << 31 else offset,
                                    self._read(device_id, 52, 4), self._read(device_id, 48, 4))
            else:  # Baud_Rate 0 is 1 Mbps; the offset sign-magnitude, its sign in bit 11
                offset = self._read(device_id, 31, 2)
                found[device_id] = (self._read(device_id, 6, 1),
                                    -(offset & 0x7FF) if offset & 0x800 else offset,
                                    self._read(device_id, 9, 2), self._read(device_id, 11, 2))
        return found

    def write_homing_offset(self, device_id: int, value: int) -> None:
        if self.dynamixel:
            result, error = self.ph.write4ByteTxRx(self.port, device_id, 20, value)
        else:
            result, error = self.ph.write2ByteTxRx(self.port, device_id, 31, value)
        assert (result, error) == (self.sdk.COMM_SUCCESS, 0)


def _confirmed(arm: Arm, url: str, rows: list[dict]) -> None:
    """The SDK reads at each joint's ID, at 1 Mbps, the calibration written."""
    with Peer(arm, url) as peer:
        found = peer.registers()
    one_mbps = 3 if arm.profile == "koch-arm" else 0
    assert found == {r["id"]: (one_mbps, r["homing_offset"], r["range_min"], r["range_max"])
                     for r in rows}
    assert [r["id"] for r in rows] == [1, 2, 3, 4, 5, 6]


def _by_hand(control):
    """A ``done`` for calibrate_joints: each joint turned by hand to LOW, then to HIGH once
    a sample saw every one move, then done once a sample saw them all back up."""
    stage = {"step": 0, "first": None}

    def done(rows) -> bool:
        present = [r["present"] for r in rows]
        if stage["step"] == 0:
            stage["first"] = present
            for joint in ARM:
                control(f"hand {joint} {LOW}")
            stage["step"] = 1
        elif stage["step"] == 1 and all(p < f - 100 for p, f in zip(present, stage["first"])):
            for joint in ARM:
                control(f"hand {joint} {HIGH}")
            stage["step"] = 2
        return stage["step"] == 2 and all(p > f + 100 for p, f in zip(present, stage["first"]))

    return done


# -- through the library ----------------------------------------------------------------------

def _counted_writes(monkeypatch) -> list[tuple[int, int]]:
    """Every write a servo of either family takes: (ID, address)."""
    from deltoctl.families.dynamixel import emulator as dxl
    from deltoctl.families.feetech import emulator as feetech

    writes: list[tuple[int, int]] = []
    for module in (dxl, feetech):
        original = module.Servo.write

        def counted(servo, address, data, original=original):
            writes.append((servo.id, address))
            return original(servo, address, data)

        monkeypatch.setattr(module.Servo, "write", counted)
    return writes


@ARMS
def test_from_the_box_to_calibrated_through_the_library(deltoctl_sim, arm, monkeypatch):
    from deltoctl.app.scan import scan
    from deltoctl.app.setup import open_setup
    from deltoctl.errors import InvalidInput, Refused

    buses = deltoctl_sim.buses(arm.profile, factory_new=True)
    url = buses[arm.bus]
    found = scan(url.split("?")[0], WAIT)  # (a) six servos at ID 1: they collide
    assert found["colliding"] == [1]
    assert [(s["id"], s["baud"]) for s in found["servos"]] == [(1, arm.factory_baud)]

    with open_setup(arm.profile, [f"{arm.bus}={url}"], wait=WAIT) as run:  # (b)
        writes = _counted_writes(monkeypatch)
        deltoctl_sim.control("connect shoulder_pan shoulder_lift")
        with pytest.raises(Refused, match="several servos answer at ID 1"):
            run.plan_one("shoulder_pan")
        with pytest.raises(InvalidInput, match="no servo joint 'elbow'"):
            run.plan_one("elbow")
        assert writes == []
        walked = []  # as a walk: a joint at the factory's ID and rate last (so101's pan)
        for joint in (w.joint for w in run.walk_order()):
            deltoctl_sim.control(f"connect {joint}")
            done = run.apply_one(joint, run.plan_one(joint, walked=walked))
            walked.append(joint)
            [row] = done.joints
            assert row["verified"] and row["from"]["baud"] == arm.factory_baud
            assert (row["to"]["id"], row["to"]["baud"]) == (ARM.index(joint) + 1, 1_000_000)
        assert run.bus_seconds > 0
    assert deltoctl_sim.control("connect all").endswith(", ".join(ARM))

    with open_robot(arm.profile, buses) as robot:  # (c) identify clean
        assert robot.identify()["blocks"]
        assert robot.warnings() == []

    for joint in ARM:  # (d) the arm in its middle pose, then moved by hand
        deltoctl_sim.control(f"hand {joint} {MIDDLE}")
    with open_robot(arm.profile, buses) as robot:
        result = robot.calibrate_joints(done=_by_hand(deltoctl_sim.control), seconds=REPLY,
                                        allow=PERMISSIONS, lerobot="walk")
    assert result["written"] and {r["written"] for r in result["joints"]} == {"verified"}
    assert result["lerobot_file"].endswith(f"robots/{arm.robot_type}/walk.json")
    assert result["file"] == str(calibration_file(arm.profile))

    with open_robot(arm.profile, buses) as robot:  # (e) the registers match the file
        robot.identify()
        assert robot.calibration_warnings == [] and robot.warnings() == []

    with Peer(arm, url) as peer:  # (f) a homing offset changed behind deltoctl's back
        peer.write_homing_offset(4, CHANGED)
    with open_robot(arm.profile, buses) as robot:
        [warning] = robot.calibration_warnings
    assert warning.startswith(f"wrist_flex: {arm.homing_register} is {CHANGED}, its "
                              "calibration")
    with Peer(arm, url) as peer:  # put back as calibrated
        peer.write_homing_offset(4, _sdk_offset(arm, result["joints"][3]["homing_offset"]))
    _confirmed(arm, url, result["joints"])  # (g)


def _sdk_offset(arm: Arm, value: int) -> int:
    """A homing offset as the SDK's write takes it (two's complement, or sign-magnitude)."""
    if arm.profile == "koch-arm":
        return value & 0xFFFFFFFF
    return value if value >= 0 else 0x800 | -value


# -- through the command line -----------------------------------------------------------------

class Served:
    """``deltoctl sim serve PROFILE --factory-new --json``, its control lines ours."""

    def __init__(self, profile: str) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "deltoctl", "sim", "serve", profile, "--json",
             "--factory-new", "--private"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
            text=True)
        self.lines = _lines(self.proc.stdout)
        [(self.bus, self.url)] = json.loads(self.lines.get(timeout=REPLY))["buses"].items()
        self.target = f"{self.bus}={self.url}"

    def send(self, lines: list[str]) -> list[str]:
        """Control lines written at once, then their replies."""
        self.proc.stdin.write("".join(line + "\n" for line in lines))
        self.proc.stdin.flush()
        replies = [json.loads(self.lines.get(timeout=REPLY)) for _ in lines]
        assert [r["control"] for r in replies] == lines
        return [r["reply"] for r in replies]

    def control(self, line: str) -> str:
        [reply] = self.send([line])
        return reply

    def stop(self) -> None:
        self.proc.terminate()
        self.proc.wait(timeout=10)


def _lines(stream) -> queue.Queue:
    """A stream's lines, as they come."""
    lines: queue.Queue = queue.Queue()
    threading.Thread(target=lambda: [lines.put(line) for line in stream],
                     daemon=True).start()
    return lines


def _setup(cli, arm: Arm, served: Served, *args: str):
    return cli("-p", arm.profile, "-t", served.target, *args, "--wait", str(WAIT))


def _calibrate(arm: Arm, served: Served) -> dict:
    """``calibrate joints --range-seconds`` in a process of its own: the arm in its middle
    pose as it starts; once it says the pose is read, each joint swept by hand through its
    range (well within the seconds given)."""
    for joint in ARM:
        served.control(f"hand {joint} {MIDDLE}")
    proc = subprocess.Popen(
        [sys.executable, "-m", "deltoctl", "-p", arm.profile, "-t", served.target, "--yes",
         "--json", "calibrate", "joints", "--range-seconds", "8", "--format", "lerobot",
         "--id", "walk", *(a for p in PERMISSIONS for a in ("--allow", p))],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        err = _lines(proc.stderr)
        said = []
        while not any("the middle pose is read" in line for line in said):
            said.append(err.get(timeout=REPLY))
        replies = served.send([f"sweep {joint} {LOW} {HIGH} 1" for joint in ARM])
        assert all("swept by hand" in r for r in replies)
        proc.wait(timeout=REPLY)
        said += list(err.queue)
        document = json.loads(proc.stdout.read())
    finally:
        if proc.poll() is None:
            proc.terminate()
            proc.wait(timeout=10)
    # the range moved is short of the profile's limits: a warning per joint, nothing else
    assert proc.returncode == 3, "".join(said)
    assert {w.split(":")[0] for w in document["warnings"]} == set(ARM)
    assert all("the range moved" in w for w in document["warnings"])
    return document["result"]


@ARMS
def test_from_the_box_to_calibrated_through_the_cli(cli, arm):
    served = Served(arm.profile)
    try:
        _walk(cli, arm, served)
    finally:
        served.stop()


def _walk(cli, arm: Arm, served: Served) -> None:
    result = cli("--json", "scan", served.url.split("?")[0], "--wait", str(WAIT))  # (a)
    assert result.exit_code == 3, result.output
    assert json.loads(result.stdout)["result"]["colliding"] == [1]
    assert "several servos at ID 1" in result.stderr

    result = _setup(cli, arm, served, "setup", "shoulder_pan", "--yes")  # (b) all six on
    assert result.exit_code == 5 and "their replies collide" in result.stderr, result.output
    assert "nothing was written" in result.stderr
    served.control("connect shoulder_pan shoulder_lift")
    result = _setup(cli, arm, served, "setup", "shoulder_lift", "--yes")
    assert result.exit_code == 5 and "several servos answer at ID 1" in result.stderr
    result = _setup(cli, arm, served, "setup", "elbow", "--yes")
    assert result.exit_code == 2 and "no servo joint 'elbow'" in result.stderr
    bus_seconds = 0.0
    for k, joint in enumerate(ARM, 1):
        assert served.control(f"connect {joint}") == f"on the wire: {joint}"
        result = _setup(cli, arm, served, "--json", "setup", joint, "--yes")
        if arm.profile == "so101-follower" and joint != "shoulder_pan":
            # at shoulder_pan's ID and rate (the factory's): a new servo or pan's is not
            # known; alone, a new one is given its joint's ID in place
            assert result.exit_code == 5 and f"--map 1={joint}" in result.stderr
            result = _setup(cli, arm, served, "--json", "setup", "--in-place", "--map",
                            f"1={joint}", "--yes")
            assert result.exit_code == 3, result.output  # the others: not connected
        else:
            assert result.exit_code == 0, result.output
        done = json.loads(result.stdout)["result"]
        row = next(r for r in done["joints"] if r["joint"] == joint)
        assert row["verified"] and (row["to"]["id"], row["to"]["baud"]) == (k, 1_000_000)
        # where the factory left it: the refusals above wrote nothing
        assert (row["from"]["id"], row["from"]["baud"]) == (1, arm.factory_baud)
        bus_seconds += done["bus_seconds"]
    assert bus_seconds > 0
    assert served.control("connect all") == f"on the wire: {', '.join(ARM)}"

    result = cli("-p", arm.profile, "-t", served.target, "identify")  # (c)
    assert result.exit_code == 0, result.output

    calibrated = _calibrate(arm, served)  # (d)
    assert {r["written"] for r in calibrated["joints"]} == {"verified"}
    assert calibrated["lerobot_file"].endswith(f"robots/{arm.robot_type}/walk.json")
    lerobot = json.loads(Path(calibrated["lerobot_file"]).read_text())
    assert lerobot["wrist_flex"]["homing_offset"] == calibrated["joints"][3]["homing_offset"]

    result = cli("-p", arm.profile, "-t", served.target, "identify")  # (e)
    assert result.exit_code == 0, result.output

    with Peer(arm, served.url) as peer:  # (f)
        peer.write_homing_offset(4, CHANGED)
    result = cli("-p", arm.profile, "-t", served.target, "identify")
    assert result.exit_code == 3, result.output
    assert f"wrist_flex: {arm.homing_register} is {CHANGED}, its calibration" in result.stderr
    with Peer(arm, served.url) as peer:
        peer.write_homing_offset(4, _sdk_offset(arm, calibrated["joints"][3]["homing_offset"]))
    _confirmed(arm, served.url, calibrated["joints"])  # (g)
