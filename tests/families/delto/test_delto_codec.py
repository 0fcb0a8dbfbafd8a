"""Golden byte vectors for every Delto frame type (reference §1), and bad bytes."""

from __future__ import annotations

import math
import re

import pytest

from deltoctl.errors import ProtocolError
from deltoctl.families.delto import codec
from deltoctl.families.delto.models import FT_6AXIS, MODELS, SENSOR_NONE, TACTILE_M, TACTILE_S

DG5F_R, DG3F_B, DG5F_S = MODELS[0x5F22], MODELS[0x3F01], MODELS[0x5F24]


def test_request_frames():
    assert codec.encode_version_request() == bytes.fromhex("000308")
    assert codec.encode_data_request(codec.data_codes(DG3F_B, True, True)) == \
        bytes.fromhex("0005010102")
    assert codec.encode_data_request(codec.data_codes(DG5F_R, False, False)) == \
        bytes.fromhex("00070101020304")
    assert codec.encode_data_request(codec.data_codes(DG5F_R, True, False)) == \
        bytes.fromhex("0008010102030405")
    assert codec.encode_data_request(codec.data_codes(DG5F_R, True, True)) == \
        bytes.fromhex("000901010203040506")
    assert codec.encode_gpio((True, False, True)) == bytes.fromhex("000606010001")
    assert codec.encode_ft_offset() == bytes.fromhex("00030b")


def test_duty_frame_layout_and_clamp():
    frame = codec.encode_duty([1000, -1, 2000] + [0] * 9)
    assert len(frame) == 39  # 3 + 3·12
    assert frame[:12] == bytes.fromhex("002705" "0103e8" "02ffff" "0303e8")
    assert len(codec.encode_duty([0] * 20)) == 63
    assert len(codec.encode_duty([0] * 18)) == 57
    assert len(codec.encode_duty([0] * 15)) == 48
    assert codec.decode_duty(frame)[3] == 1000


def test_version_reply_long_and_short():
    golden = bytes.fromhex("0009" "08" "5f22" "03" "00" "01" "1f")  # DG-5F-R, FW 3.0, FT 6-axis
    info = codec.decode_version_reply(golden)
    assert (info.model_id, info.firmware) == (0x5F22, (3, 0))
    assert (info.sensor_type, info.finger_mask) == (FT_6AXIS, 0x1F)
    assert codec.encode_version_reply(info) == golden
    short = codec.decode_version_reply(bytes.fromhex("0007083f010205"))  # old firmware
    assert (short.model_id, short.firmware, short.sensor_type) == (0x3F01, (2, 5), None)


def test_data_reply_golden_dg5f():
    # motor 1: pos 12.3° (123), −150 mA, 31.5 °C, −2 RPM; the rest zero; F/T finger 1:
    # Fx 1.5 N, Fz −0.5 N, Tz 0.012 N·m; GPIO out1 on, input on.
    motor1 = bytes.fromhex("01" "007b" "ff6a" "013b" "fe")
    motors = motor1 + b"".join(bytes([i + 1]) + bytes(7) for i in range(1, 20))
    ft1 = bytes.fromhex("000f" "0000" "fffb" "0000" "0000" "000c")
    body = motors + ft1 + bytes(12 * 4) + bytes.fromhex("01000001")
    frame = (len(body) + 3).to_bytes(2, "big") + b"\x01" + body
    assert len(frame) == 227
    codes = codec.data_codes(DG5F_R, True, True)
    rec = codec.decode_data_reply(frame, DG5F_R, codes, FT_6AXIS)
    assert math.isclose(rec.position[0], math.radians(12.3))
    assert rec.current[0] == -150 and math.isclose(rec.temperature[0], 31.5)
    assert math.isclose(rec.velocity[0], -2 * math.pi / 30)
    assert rec.ft[0] == pytest.approx((1.5, 0.0, -0.5, 0.0, 0.0, 0.012))
    assert rec.gpio == (True, False, False, True)
    assert codec.encode_data_reply(rec, DG5F_R, codes, FT_6AXIS) == frame


def test_data_reply_dg3f_b_and_s_scale():
    body = bytes.fromhex("01" "ff9c" "0064") + b"".join(bytes([i]) + bytes(4) for i in range(2, 13))
    frame = (len(body) + 3).to_bytes(2, "big") + b"\x01" + body
    assert len(frame) == 63
    rec = codec.decode_data_reply(frame, DG3F_B, codec.data_codes(DG3F_B, True, True), SENSOR_NONE)
    assert math.isclose(rec.position[0], math.radians(-10.0)) and rec.current[0] == 100
    # the S models count position in 0.01°
    s_motors = bytes.fromhex("01" "0064" "0000" "0000" "00") + bytes(8 * 19)
    s_frame = (len(s_motors) + 3).to_bytes(2, "big") + b"\x01" + s_motors
    rec = codec.decode_data_reply(s_frame, DG5F_S, codec.data_codes(DG5F_S, False, False), 0)
    assert math.isclose(rec.position[0], math.radians(1.0))


@pytest.mark.parametrize("model,sensor", [(DG5F_R, FT_6AXIS), (DG3F_B, SENSOR_NONE),
                                          (DG5F_S, TACTILE_S)])
def test_a_connections_unpacker_reads_and_refuses_as_unpack_data_reply(model, sensor):
    codes = codec.data_codes(model, True, True)
    unpack = codec.data_reply_unpacker(model, codes, sensor)
    size = codec.data_reply_length(model, codes, sensor)
    good = size.to_bytes(2, "big") + b"\x01" + bytes(i % 251 for i in range(size - 3))
    assert unpack(good) == codec.unpack_data_reply(good, model, codes, sensor)
    for bad in (good[:2], good[:-1], good + b"\x00", good[:2] + b"\x02" + good[3:],
                (size + 1).to_bytes(2, "big") + good[2:], bytes.fromhex("000401ff")):
        with pytest.raises(ProtocolError) as expected:
            codec.unpack_data_reply(bad, model, codes, sensor)
        with pytest.raises(ProtocolError, match=re.escape(str(expected.value))):
            unpack(bad)


@pytest.mark.parametrize("sensor,size", [(TACTILE_M, 15), (TACTILE_S, 36), (FT_6AXIS, 12)])
def test_sensor_block_sizes(sensor, size):
    codes = codec.data_codes(DG5F_R, True, False)
    assert codec.data_reply_length(DG5F_R, codes, sensor) == 3 + 160 + 5 * size


def test_bad_bytes_raise_protocol_error():
    codes = codec.data_codes(DG5F_R, False, False)
    with pytest.raises(ProtocolError, match="expected 163"):
        codec.decode_data_reply(bytes.fromhex("000401ff"), DG5F_R, codes, 0)
    with pytest.raises(ProtocolError, match="command byte"):
        codec.decode_version_reply(bytes.fromhex("0009015f220300011f"))
    with pytest.raises(ProtocolError, match="LEN says"):
        codec.decode_version_reply(bytes.fromhex("0010085f220300011f"))
    with pytest.raises(ProtocolError, match="multiple of 3"):
        codec.decode_duty(bytes.fromhex("00050501ff"))


def test_direction_maps_follow_firmware():
    assert DG5F_R.direction((2, 7))[:4] == (1, 1, -1, -1)
    assert DG5F_R.direction((2, 8)) == (1,) * 20
    assert DG3F_B.direction((3, 5)) == (-1,) * 12
    assert DG3F_B.direction((3, 6)) == (1,) * 12
    assert MODELS[0x4F02].direction((1, 0)) == (1,) * 18


def test_effort_to_duty_and_current_limiter():
    from deltoctl.families.delto.models import CurrentLimiter, effort_to_duty_percent

    assert effort_to_duty_percent(0.5) == pytest.approx(0.5 * 13.875 / 1.15 / 12.0 * 100)
    assert effort_to_duty_percent(2.0) == 100.0 and effort_to_duty_percent(-2.0) == -100.0
    limiter = CurrentLimiter()
    assert limiter(0.2, 100.0) == 0.2  # below the limit: untouched
    shrunk = [limiter(0.2, 400.0) for _ in range(3)]  # latched above 170 mA: shrinking
    assert shrunk[0] < 0.2 and shrunk[2] < shrunk[0]
    assert limiter(0.2, 50.0) == 0.2  # released below 130 mA, integral cleared
