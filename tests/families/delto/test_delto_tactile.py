"""Tactile fingertips (TACTILE_M 5×3 uint8, TACTILE_S 6×3 uint16) end to end: golden bytes,
the emulator's contact model, detect, stream (NDJSON grids, heat maps), record (one
sensor_msgs/Image per finger), and the Delto fixes (short version reply, exact position
scales, calibrate ft on a gripper without F/T)."""

from __future__ import annotations

import json
import math
import os
import struct
from pathlib import Path

import pytest
import yaml

from deltoctl.families.delto import codec
from deltoctl.families.delto.emulator import (
    DeltoFirmware,
    DeltoServer,
    contact_cells,
    firmware_for_profile,
)
from deltoctl.families.delto.models import (
    CENTI_DEGREE,
    DECI_DEGREE,
    MODELS,
    TACTILE_GRIDS,
    TACTILE_M,
    TACTILE_S,
)
from deltoctl.profile.catalog import load_profile
from tests.conftest import REPO, block_of, ros2_messages

DG1F = MODELS[0x1F02]  # 3 motors, 1 finger: the shortest replies with a sensor block
CODES = (codec.JOINT, codec.CURRENT, codec.TEMPERATURE, codec.VELOCITY, codec.FINGERTIP_SENSOR)
MOTORS = ("01 0384 0096 012c fe"  # 90.0°, 150 mA, 30.0 °C, -2 RPM
          "02 fc7c ff6a 00fa 05"  # -90.0°, -150 mA, 25.0 °C, 5 RPM
          "03 0000 0000 0104 00")  # 0°, 0 mA, 26.0 °C, 0 RPM
GOLDEN_M = bytes.fromhex("002a01" + MOTORS + "000102 101112 202122 303132 4041ff")
GOLDEN_S = bytes.fromhex("003f01" + MOTORS + "0000 0001 0002 0100 0101 0102 0200 0201 0202"
                         "0300 0301 0302 0400 0401 0402 0500 0501 ffff")
ROWS_M = [[0, 1, 2], [16, 17, 18], [32, 33, 34], [48, 49, 50], [64, 65, 255]]
ROWS_S = [[0, 1, 2], [256, 257, 258], [512, 513, 514], [768, 769, 770], [1024, 1025, 1026],
          [1280, 1281, 65535]]


# -- golden byte vectors -----------------------------------------------------------------------

@pytest.mark.parametrize("sensor,golden,rows", [(TACTILE_M, GOLDEN_M, ROWS_M),
                                                (TACTILE_S, GOLDEN_S, ROWS_S)])
def test_golden_reply_decodes_to_known_grids_and_encodes_back(sensor, golden, rows):
    assert codec.data_reply_length(DG1F, CODES, sensor) == len(golden)
    record = codec.decode_data_reply(golden, DG1F, CODES, sensor)
    assert record.position == [900 * DECI_DEGREE, -900 * DECI_DEGREE, 0.0]
    assert record.current == [150, -150, 0]
    assert record.temperature == pytest.approx([30.0, 25.0, 26.0])
    assert record.velocity == pytest.approx([-2 * math.pi / 30, 5 * math.pi / 30, 0.0])
    assert len(record.tactile) == 1 and record.ft == []
    assert codec.tactile_rows(record.tactile[0], sensor) == rows
    assert codec.encode_data_reply(record, DG1F, CODES, sensor) == golden


def test_the_emulator_sends_its_contact_cells_in_wire_order():
    model = MODELS[0x5F44]  # DG-5F-S15-R: 15 motors, 5 fingers, TACTILE_S
    firmware = DeltoFirmware(model, sensor_type=TACTILE_S)
    firmware.pressing[3] = 0.3  # finger 2's first joint, pushing
    codes = codec.data_codes(model, True, False)
    reply = firmware.handle(codec.encode_data_request(codes))
    cells = 18
    at = 3 + model.motors * 8
    grid = TACTILE_GRIDS[TACTILE_S]
    # the firmware's own step resets what it did not press: compute what it last sent
    sent = [struct.unpack_from(f">{cells}H", reply, at + 2 * cells * f) for f in range(5)]
    record = codec.decode_data_reply(reply, model, codes, TACTILE_S)
    assert [tuple(t) for t in record.tactile] == sent
    assert all(len(rows) == grid.rows and all(len(r) == grid.cols for r in rows)
               for rows in (codec.tactile_rows(t, TACTILE_S) for t in record.tactile))


# -- the emulator's contact model --------------------------------------------------------------

def test_contact_cells_grow_with_the_pressing_torque():
    for kind, grid in TACTILE_GRIDS.items():
        assert contact_cells(grid, 0, 0.0) == (0,) * grid.cells
        light, hard = contact_cells(grid, 1, 0.05), contact_cells(grid, 1, 0.4)
        assert 0 < max(light) < max(hard)
        assert sum(1 for c in light if c) <= sum(1 for c in hard if c)
        assert max(contact_cells(grid, 1, 10.0)) == (255 if kind == TACTILE_M else 4095)
        assert contact_cells(grid, 2, 0.2) == contact_cells(grid, 2, 0.2)  # deterministic


def _s15(**kwargs) -> DeltoFirmware:
    return firmware_for_profile(load_profile("dg-5f-s15-right"), **kwargs)


def test_a_finger_against_its_stop_presses_a_free_one_does_not():
    firmware = _s15()
    assert firmware.sensor_type == TACTILE_S  # from the profile's 6×3 grids
    for _ in range(50):
        firmware.step(0.001)
    assert all(c == 0 for cells in firmware.record().tactile for c in cells)  # at rest
    # joint_1_2 rests at its upper limit (0°): a positive duty pushes finger 1 into the stop;
    # joint_2_1 (finger 2) is free to move
    firmware.duty[1] = 300
    firmware.duty[3] = 300
    for _ in range(100):
        firmware.step(0.001)
    tactile = firmware.record().tactile
    assert max(tactile[0]) > 0 and firmware.velocity[1] == 0.0
    assert max(tactile[1]) == 0 and firmware.velocity[3] != 0.0
    assert all(max(t) == 0 for t in tactile[2:])
    firmware.duty[1] = 900  # harder: a bigger, wider blob
    for _ in range(10):
        firmware.step(0.001)
    harder = firmware.record().tactile[0]
    assert max(harder) > max(tactile[0])
    assert sum(1 for c in harder if c) >= sum(1 for c in tactile[0] if c)


def test_a_stalled_joint_presses_on_its_object():
    firmware = _s15()
    firmware.faults.stalled.add(7)  # joint_3_2: finger 3
    firmware.duty[7] = 500
    for _ in range(20):
        firmware.step(0.001)
    tactile = firmware.record().tactile
    assert max(tactile[2]) > 0 and [max(t) for i, t in enumerate(tactile) if i != 2] == [0] * 4


# -- profiles, detect, stream ------------------------------------------------------------------

@pytest.mark.parametrize("name", ["dg-5f-s-left", "dg-5f-s-right", "dg-5f-s15-left",
                                  "dg-5f-s15-right"])
def test_tactile_profiles_declare_a_grid_per_finger(name):
    profile = load_profile(name)
    (hw,) = profile.hardware
    assert hw.params["fingertip_sensor"] == "true"
    hand = hw.params["hand_type"]
    assert [s.name for s in hw.sensors] == [f"{hand}_tactile_finger_{n}" for n in range(1, 6)]
    for n, sensor in enumerate(hw.sensors, 1):
        assert [i.name for i in sensor.state_interfaces] == [
            f"cell_{r}_{c}" for r in range(6) for c in range(3)]
        assert sensor.params == {"frame_id": f"{hand}_fingertip_{n}",
                                 "topic": f"tactile/finger_{n}", "encoding": "mono16"}


def test_detect_reports_the_tactile_type_and_grid(cli):
    result = cli("--sim", "-p", "dg-5f-s-right", "detect", "--json")
    assert result.exit_code == 0, result.stderr
    block = block_of(json.loads(result.stdout))
    assert block["details"]["tactile"] == {"type": "tactile_s", "rows": 6, "cols": 3,
                                           "cells": 18, "cell_bits": 16, "encoding": "mono16"}
    checks = {c["what"]: c for c in block["checks"]}
    assert checks["fingertip tactile grids"]["device"] == 5
    assert checks["tactile grid (rows×cols)"]["device"] == "6×3"
    assert all(c["match"] for c in block["checks"])
    table = cli("--sim", "-p", "dg-5f-s-right", "detect")
    assert table.exit_code == 0
    assert "TACTILE_S (6×3 cells per finger)" in table.stdout
    assert "tactile grid (rows×cols)" in table.stdout


def test_detect_flags_a_grid_the_device_does_not_have(cli, tmp_path):
    path = _tactile_m_profile(tmp_path)
    firmware = firmware_for_profile(load_profile(str(path)), sensor_type=TACTILE_S)
    with DeltoServer(firmware) as server:
        result = cli("-p", str(path), "-t", server.endpoint, "detect", "--json")
    assert result.exit_code == 3
    checks = {c["what"]: c for c in block_of(json.loads(result.stdout))["checks"]}
    grid = checks["tactile grid (rows×cols)"]
    assert (grid["profile"], grid["device"], grid["match"]) == ("5×3", "6×3", False)


def test_stream_shows_every_cell_and_each_grid_as_rows(cli):
    result = cli("--sim", "-p", "dg-5f-s15-right", "stream", "--json", "-d", "0.1", "-r", "40")
    assert result.exit_code == 0, result.stderr
    line = json.loads(result.stdout.splitlines()[-1])
    names = [f"right_tactile_finger_{n}" for n in range(1, 6)]
    assert all(f"{s}/cell_5_2" in line["values"] for s in names)
    assert list(line["grids"]) == names
    for rows in line["grids"].values():
        assert len(rows) == 6 and all(len(r) == 3 for r in rows)
        assert all(isinstance(c, int) for r in rows for c in r)


def test_stream_grids_follow_a_pushing_finger_over_tcp(cli):
    firmware = _s15()
    firmware.duty[1] = 600  # finger 1 pushes joint_1_2 into its stop
    with DeltoServer(firmware) as server:
        result = cli("-p", "dg-5f-s15-right", "-t", server.endpoint, "stream", "--json",
                     "-d", "0.2", "-r", "20", "-i", "right_tactile_finger_*/*")
    assert result.exit_code == 0, result.stderr
    grids = json.loads(result.stdout.splitlines()[-1])["grids"]
    peaks = [max(max(r) for r in grids[f"right_tactile_finger_{n}"]) for n in range(1, 6)]
    assert peaks[0] > 0 and peaks[1:] == [0, 0, 0, 0]
    cells = json.loads(result.stdout.splitlines()[-1])["values"]
    assert grids["right_tactile_finger_1"][2][1] == cells["right_tactile_finger_1/cell_2_1"]


def test_the_live_view_draws_each_grid_as_a_heat_map(cli):
    from rich.console import Console

    from deltoctl.render.stream import live_tables

    firmware = _s15()
    firmware.duty[1] = 600
    with DeltoServer(firmware) as server:
        out = cli("-p", "dg-5f-s15-right", "-t", server.endpoint, "stream", "-d", "0.1")
    sample = json.loads(out.stdout.splitlines()[-1])["values"]
    with open(os.devnull, "w") as devnull:
        console = Console(record=True, width=80, file=devnull, color_system="truecolor")
        console.print(live_tables(sample, "tactile"))
    text = console.export_text(clear=False)
    html = console.export_html(inline_styles=True)
    lines = text.splitlines()
    assert max(len(line) for line in lines) <= 80 and "…" not in text
    assert "right_tactile_finger" in text and "cell_0_0" not in text  # maps, not columns
    assert "joint_1_2" in text  # the joints' table is still there
    assert "background-color: #" in html  # the cells are coloured by their value
    peak = max(sample[f"right_tactile_finger_1/cell_{r}_{c}"] for r in range(6)
               for c in range(3))
    assert peak > 0 and str(peak) in text


# -- record --------------------------------------------------------------------------------------

def _counts(path: Path) -> dict[str, int]:
    from mcap.reader import make_reader

    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    return {summary.channels[c].topic: n
            for c, n in summary.statistics.channel_message_counts.items()}


def test_a_dg_5f_s_recording_has_an_image_per_finger_at_the_loop_rate(cli, tmp_path):
    out = tmp_path / "s.mcap"
    result = cli("--sim", "-p", "dg-5f-s-right", "-q", "record", str(out), "-r", "50",
                 "-d", "1")
    assert result.exit_code == 0, result.stderr
    counts = _counts(out)
    joint_states = counts["/joint_states"]
    assert joint_states >= 10
    assert {t: n for t, n in counts.items() if t.startswith("/tactile/")} == {
        f"/tactile/finger_{n}": joint_states for n in range(1, 6)}
    for _, msg in ros2_messages(out, topics=["/tactile/finger_3"]):
        assert (msg.height, msg.width, msg.step, msg.encoding, msg.is_bigendian) == \
            (6, 3, 6, "mono16", 0)
        assert msg.header.frame_id == "right_fingertip_3" and len(msg.data) == 36


def test_recorded_images_carry_the_cells_little_endian(cli, tmp_path):
    from rosbags.highlevel import AnyReader

    firmware = _s15()
    firmware.duty[1] = 600
    out = tmp_path / "press.mcap"
    with DeltoServer(firmware) as server:
        result = cli("-p", "dg-5f-s15-right", "-t", server.endpoint, "-q", "record", str(out),
                     "-r", "50", "-d", "0.3")
    assert result.exit_code == 0, result.stderr
    with AnyReader([out]) as reader:
        images = {}
        for connection, _, raw in reader.messages():
            if connection.msgtype == "sensor_msgs/msg/Image":
                images[connection.topic] = reader.deserialize(raw, connection.msgtype)
    assert sorted(images) == [f"/tactile/finger_{n}" for n in range(1, 6)]
    last = images["/tactile/finger_1"]
    cells = struct.unpack("<18H", bytes(last.data))
    expected = contact_cells(TACTILE_GRIDS[TACTILE_S], 0, max(firmware.pressing))
    assert cells == expected and max(cells) > 0
    assert all(not any(images[f"/tactile/finger_{n}"].data) for n in range(2, 6))


def _tactile_m_profile(tmp_path: Path) -> Path:
    """dg-5f-right with TACTILE_M fingertips (5×3 uint8 cells) instead of F/T."""
    data = yaml.safe_load((REPO / "profiles" / "dg-5f-right.yaml").read_text())
    data["name"] = "dg-5f-right-tactile-m"
    data["ros2_control"][0]["sensors"] = [
        {"name": f"right_tactile_finger_{n}",
         "params": {"frame_id": f"right_fingertip_{n}", "topic": f"tactile/finger_{n}",
                    "encoding": "mono8"},
         "state_interfaces": [f"cell_{r}_{c}" for r in range(5) for c in range(3)]}
        for n in range(1, 6)]
    path = tmp_path / "dg-5f-right-tactile-m.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def test_a_tactile_m_hand_records_mono8_images(cli, tmp_path):
    from rosbags.highlevel import AnyReader

    profile = _tactile_m_profile(tmp_path)
    result = cli("--sim", "-p", str(profile), "detect", "--json")
    assert result.exit_code == 0, result.stderr
    assert block_of(json.loads(result.stdout))["details"]["tactile"]["encoding"] == "mono8"
    out = tmp_path / "m.mcap"
    result = cli("--sim", "-p", str(profile), "-q", "record", str(out), "-r", "50", "-d", "0.3")
    assert result.exit_code == 0, result.stderr
    counts = _counts(out)
    assert counts["/tactile/finger_5"] == counts["/joint_states"]
    with AnyReader([out]) as reader:
        for connection, _, raw in reader.messages():
            if connection.topic == "/tactile/finger_2":
                msg = reader.deserialize(raw, connection.msgtype)
                assert (msg.height, msg.width, msg.step, msg.encoding) == (5, 3, 3, "mono8")
                assert msg.header.frame_id == "right_fingertip_2" and len(msg.data) == 15


def test_info_and_plot_read_a_tactile_recording(cli, tmp_path):
    out = tmp_path / "s15.mcap"
    assert cli("--sim", "-p", "dg-5f-s15-right", "-q", "record", str(out), "-r", "50",
               "-d", "0.3").exit_code == 0
    info = cli("info", str(out), "--json")
    assert info.exit_code == 0, info.stderr
    topics = {t["topic"]: t for t in json.loads(info.stdout)["result"]["topics"]}
    assert topics["/tactile/finger_1"]["type"] == "sensor_msgs/msg/Image"
    assert topics["/tactile/finger_1"]["messages"] == topics["/joint_states"]["messages"]
    assert cli("info", str(out)).exit_code == 0
    plot = cli("plot", str(out), "joint_1_2/position", "-o", str(tmp_path / "p.png"))
    assert plot.exit_code == 0, plot.stderr
    assert (tmp_path / "p.png").stat().st_size > 0


def test_a_bad_tactile_param_is_one_clear_message(cli, tmp_path):
    data = yaml.safe_load((REPO / "profiles" / "dg-5f-s15-right.yaml").read_text())
    data["ros2_control"][0]["sensors"][0]["params"]["encoding"] = "rgb8"
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    result = cli("--sim", "-p", str(path), "stream", "--json", "-d", "0.05")
    assert result.exit_code == 2
    assert "encoding 'rgb8' is not mono8 or mono16" in result.stderr
    assert "Traceback" not in result.stderr


# -- fixes -----------------------------------------------------------------------------------------

def _profile_without_fingertip_sensor(tmp_path: Path) -> Path:
    data = yaml.safe_load((REPO / "profiles" / "dg-5f-right.yaml").read_text())
    data["ros2_control"][0]["params"]["fingertip_sensor"] = False
    del data["ros2_control"][0]["sensors"]
    path = tmp_path / "no-sensor.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def test_short_version_reply_without_fingertip_sensor_gives_mask_0(cli, tmp_path):
    path = _profile_without_fingertip_sensor(tmp_path)
    firmware = firmware_for_profile(load_profile(str(path)), short_version=True)
    with DeltoServer(firmware) as server:
        result = cli("-p", str(path), "-t", server.endpoint, "identify", "--json")
    assert result.exit_code == 0, result.stderr
    ident = block_of(json.loads(result.stdout))["identity"]
    assert ident["short_version_reply"] is True
    assert (ident["sensor_type"], ident["finger_mask"]) == ("none", 0)
    with DeltoServer(firmware_for_profile(load_profile("dg-5f-right"),
                                          short_version=True)) as server:
        result = cli("-p", "dg-5f-right", "-t", server.endpoint, "identify", "--json")
    ident = block_of(json.loads(result.stdout))["identity"]
    assert (ident["sensor_type"], ident["finger_mask"]) == ("ft_6axis", 31)


@pytest.mark.parametrize("model_id,exact", [(0x5F14, math.pi / 18000), (0x5F24, math.pi / 18000),
                                            (0x5F34, math.pi / 18000), (0x5F44, math.pi / 18000),
                                            (0x5F22, math.pi / 1800), (0x3F01, math.pi / 1800)])
def test_positions_are_bit_exact_with_the_vendor_over_every_raw_value(model_id, exact):
    model = MODELS[model_id]
    assert model.position_scale() == exact == (CENTI_DEGREE if exact < 1e-3 else DECI_DEGREE)
    codes = codec.data_codes(model, False, False)
    stride = model.bytes_per_motor
    n = model.motors
    for start in range(-32768, 32768, n):
        raws = [max(-32768, min(32767, start + k)) for k in range(n)]
        body = b"".join(bytes([k + 1]) + struct.pack(">h", raw) + bytes(stride - 3)
                        for k, raw in enumerate(raws))
        record = codec.decode_data_reply(codec.frame(codec.GET_DATA, body), model, codes, 0)
        assert record.position == [raw * exact for raw in raws]


@pytest.mark.parametrize("sensor,what", [
    (TACTILE_S, "reports tactile fingertips (TACTILE_S, 6×3 cells), not F/T sensors"),
    (TACTILE_M, "reports tactile fingertips (TACTILE_M, 5×3 cells), not F/T sensors"),
    (0, "reports no fingertip sensors (sensor type NONE)")])
def test_calibrate_ft_says_what_the_gripper_has(cli, tmp_path, sensor, what):
    firmware = firmware_for_profile(load_profile("dg-5f-right"), sensor_type=sensor)
    with DeltoServer(firmware) as server:
        result = cli("-p", "dg-5f-right", "-t", server.endpoint, "calibrate", "ft", "-n", "3",
                     "-o", str(tmp_path))
    assert result.exit_code == 1, result.stderr
    assert what in result.stderr
    assert "Traceback" not in result.stderr and "internal error" not in result.stderr
    assert not list(tmp_path.glob("calibration-*.json"))


def test_fingertip_sensors_declared_without_fingertip_sensor_is_a_warning(cli, tmp_path):
    data = yaml.safe_load((REPO / "profiles" / "dg-5f-s15-right.yaml").read_text())
    data["ros2_control"][0]["params"]["fingertip_sensor"] = False
    path = tmp_path / "off.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    result = cli("--sim", "-p", str(path), "stream", "--json", "-d", "0.05")
    assert result.exit_code == 3, result.stderr
    assert "fingertip_sensor is not true" in result.stderr
    grids = json.loads(result.stdout.splitlines()[-1])["grids"]
    assert grids["right_tactile_finger_1"][0] == [None, None, None]  # nothing was sent


def test_packed_cells_are_rounded_and_saturated_to_their_type():
    from deltoctl.record.cdr import CdrTemplate, grid_cells

    t = CdrTemplate().header("f").const_u8(0).var_packed("H", ["a", "b", "c", "d", "e"]).done()
    values = {"@sec": 1, "@nanosec": 2, "a": 2.6, "b": -1.0, "c": 70000.0,
              "d": float("nan"), "e": 513}
    data = t.layout.pack(*[f if isinstance(f, bytes) else values[f] for f in t.fields])
    assert data[-14:] == struct.pack("<I5H", 10, 3, 0, 65535, 0, 513)
    assert grid_cells(["cell_1_0", "cell_0_0", "cell_0_1", "cell_1_1"]) == (
        2, 2, ["cell_0_0", "cell_0_1", "cell_1_0", "cell_1_1"])
    assert grid_cells(["cell_0_0", "cell_1_1"]) is None  # not a full grid
    assert grid_cells(["cell_0_0", "force.x"]) is None


def test_a_non_finite_effort_sends_duty_zero_not_full_duty():
    from deltoctl.core.system import System
    from tests.conftest import eventually

    firmware = _s15()
    with DeltoServer(firmware) as server, \
            System(load_profile("dg-5f-s15-right"), [server.endpoint]) as system:
        driver = system.member("joint_1_1").driver
        driver.write_efforts({"joint_1_1": 0.2, "joint_1_2": 0.2})
        assert eventually(lambda: firmware.duty[0] > 0 and firmware.duty[1] > 0)
        driver.write_efforts({"joint_1_1": float("nan"), "joint_1_2": float("inf")})
        assert eventually(lambda: firmware.duty[:2] == [0, 0])
        driver.stop()


def test_detect_says_what_to_declare_for_a_tactile_gripper(cli):
    firmware = firmware_for_profile(load_profile("dg-5f-right"), sensor_type=TACTILE_M)
    with DeltoServer(firmware) as server:
        result = cli("-p", "dg-5f-right", "-t", server.endpoint, "detect", "--json")
    assert result.exit_code == 3
    block = block_of(json.loads(result.stdout))
    assert "TACTILE_M (5×3 cells per finger)" in block["summary"]
    assert "declares no tactile grids" in block["summary"]
    checks = {c["what"]: c for c in block["checks"]}
    assert checks["fingertip F/T sensors"]["match"] is False
    assert (checks["fingertip tactile grids"]["profile"],
            checks["fingertip tactile grids"]["device"]) == (0, 5)
