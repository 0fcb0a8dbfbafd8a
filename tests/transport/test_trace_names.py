"""-vv and --log-file name each frame they trace (GET_DATA, SYNC_READ, PING …), not only its
bytes: each family's codec names its frames, found through the family's descriptor."""

from __future__ import annotations

import json

import pytest

from deltoctl import registry, trace
from deltoctl.families.bioscara import codec as bioscara
from deltoctl.families.delto import codec as delto
from deltoctl.families.dynamixel import codec as dxl
from deltoctl.families.lsm6ds3 import codec as imu


@pytest.fixture(autouse=True)
def _trace_off():
    yield
    trace.configure(0, None)


def _frames(log) -> dict[str, set[str]]:
    """Every traced frame's name by bus, from an NDJSON log file."""
    found: dict[str, set[str]] = {}
    for line in log.read_text().splitlines():
        record = json.loads(line)
        if record["logger"] == "deltoctl.wire" and "frame" in record:
            found.setdefault(record["bus"], set()).add(record["frame"])
    return found


def test_vv_names_the_grippers_frames_on_stderr(cli):
    result = cli("--sim", "-p", "dg-5f-right", "-vv", "connect", "-n", "2")
    assert result.exit_code == 0, result.stderr
    assert "GET_VERSION: 00 03 08" in result.stderr
    assert "GET_DATA: " in result.stderr


def test_the_log_file_names_the_grippers_frames(cli, tmp_path):
    log = tmp_path / "wire.ndjson"
    result = cli("--sim", "-p", "dg-5f-right", "--log-file", str(log), "connect", "-n", "2")
    assert result.exit_code == 0, result.stderr
    (names,) = _frames(log).values()
    assert {"GET_VERSION", "GET_DATA"} <= names
    assert "SET_DUTY" not in names  # a connect never drives the gripper, nor stops it


def test_a_dynamixel_bus_and_its_imu_are_named_frame_by_frame(cli, tmp_path):
    log = tmp_path / "mh5.ndjson"
    result = cli("--sim", "-p", "mh5", "--log-file", str(log), "stream", "--duration", "0.3",
                 "--json")
    assert result.exit_code == 0, result.stderr
    frames = _frames(log)
    serial = set().union(*(names for bus, names in frames.items() if bus.startswith("serial:")))
    # a sync read's replies: "6 × STATUS" when one read takes them, "STATUS" each as they come
    assert {"PING", "SYNC_READ"} <= serial and any(n.endswith("STATUS") for n in serial)
    (i2c,) = (names for bus, names in frames.items() if bus.endswith("@0x6a"))
    assert {"WHO_AM_I", "WHO_AM_I reply", "OUT_TEMP_L"} <= i2c


def test_bioscara_joints_name_their_i2c_commands(cli, tmp_path):
    log = tmp_path / "arm.ndjson"
    result = cli("--sim", "-p", "bioscara-arm", "--log-file", str(log), "connect", "-n", "1")
    assert result.exit_code == 0, result.stderr
    frames = _frames(log)
    assert {bus.rsplit("@", 1)[1] for bus in frames} == {"0x11", "0x12", "0x13", "0x14"}
    for names in frames.values():
        assert {"PING", "PING reply"} <= names


def test_every_family_with_a_wire_names_its_frames():
    namers = {f.name: f.frame_namer() for f in registry.families().values() if f.schemes}
    assert all(namers.values()), namers
    assert registry.get("generic").frame_namer() is None  # no wire, nothing to name


@pytest.mark.parametrize(("codec", "frame", "name"), [
    (delto, delto.encode_version_request(), "GET_VERSION"),
    (delto, delto.encode_data_request((1, 2)), "GET_DATA"),
    (delto, delto.encode_duty([0, 0, 0]), "SET_DUTY"),
    (delto, delto.encode_gpio((True, False, False)), "SET_GPIO"),
    (delto, delto.frame(0x7F), "command 0x7f"),
    (delto, b"\x00", None),
    (dxl, dxl.ping(1), "PING"),
    (dxl, dxl.read(1, 132, 4), "READ"),
    (dxl, dxl.write(1, 64, b"\x01"), "WRITE"),
    (dxl, dxl.sync_read(126, 10, [1, 2]), "SYNC_READ"),
    (dxl, dxl.sync_read(126, 10, [1, 2], fast=True), "FAST_SYNC_READ"),
    (dxl, dxl.sync_write(116, 4, {1: b"\0\0\0\0"}), "SYNC_WRITE"),
    (dxl, dxl.reboot(3), "REBOOT"),
    (dxl, dxl.status(1), "STATUS"),
    (dxl, dxl.status(1) + dxl.status(2) + dxl.status(3), "3 × STATUS"),
    (dxl, dxl.ping(1) + dxl.status(1), "PING + STATUS"),
    (dxl, dxl.status(1)[5:], None),  # the rest of a reply read in two parts
    (bioscara, bioscara.read_request(bioscara.ANGLEMOVED), "ANGLEMOVED"),
    (bioscara, bioscara.home(10, 6, 20), "HOME"),
    (bioscara, bioscara.move_steps(100), "MOVESTEPS"),
    (bioscara, bytes([0x01]), "register 0x01"),
    (imu, bytes([imu.WHO_AM_I]), "WHO_AM_I"),
    (imu, bytes([imu.CTRL1_XL, 0x40]), "write CTRL1_XL"),
])
def test_each_codec_names_its_frames(codec, frame, name):
    assert codec.frame_name(frame) == name
