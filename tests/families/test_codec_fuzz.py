"""Fuzz every codec: any bytes give a record or a ProtocolError, nothing else (no IndexError,
struct.error, ValueError …); what an encoder writes, its decoder reads back.

Inputs are drawn both as plain bytes and as bytes shaped enough to pass the first checks
(a right length field, a right command byte, a right CRC), so the decoders' later stages are
reached too. Each test states its number of examples (``EXAMPLES``)."""

from __future__ import annotations

import math
import struct

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from deltoctl.errors import ProtocolError
from deltoctl.families.bioscara import codec as bioscara
from deltoctl.families.delto import codec as delto
from deltoctl.families.delto.models import MODELS
from deltoctl.families.delto.session import NEED_DATA, Role, Session
from deltoctl.families.dynamixel import codec as dxl
from deltoctl.families.lsm6ds3 import codec as imu

SOME, MANY = 400, 1000
quick = settings(max_examples=SOME, deadline=None, suppress_health_check=[HealthCheck.too_slow])
thorough = settings(max_examples=MANY, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
slow = pytest.mark.slow

MODEL_LIST = sorted(MODELS.values(), key=lambda m: m.id)
CODE_SETS = sorted({delto.data_codes(m, ft, io) for m in MODEL_LIST
                    for ft in (False, True) for io in (False, True)})


def decoded(decode, *args):  # type: ignore[no-untyped-def]
    """The decoder's record, or None for a ProtocolError; anything else fails the test."""
    try:
        return decode(*args)
    except ProtocolError as exc:
        assert str(exc)  # a message that says what was wrong
        return None


def chunks(data: bytes, cuts: list[int]) -> list[bytes]:
    """``data`` split where ``cuts`` say, as a stream arrives."""
    at = sorted({c % (len(data) + 1) for c in cuts})
    return [data[a:b] for a, b in zip([0, *at], [*at, len(data)])]


# -- Delto --------------------------------------------------------------------------------------

def delto_frames(cmd: int) -> st.SearchStrategy[bytes]:
    """Plain bytes, frames with any command, and frames of ``cmd`` with any payload."""
    return st.one_of(
        st.binary(max_size=64),
        st.builds(delto.frame, st.integers(0, 255), st.binary(max_size=64)),
        st.builds(delto.frame, st.just(cmd), st.binary(max_size=64)),
    )


def delto_requests(session: Session, data: bytes) -> list[bytes]:
    """The request frames ``data`` completes, as the device's session gives them."""
    session.receive_data(data)
    frames = []
    while (event := session.next_event()) is not NEED_DATA:
        frames.append(event.frame)
    return frames


@quick
@given(st.lists(st.binary(max_size=48), max_size=12))
def test_delto_session_takes_any_stream(pieces):
    session = Session(Role.DEVICE)
    for piece in pieces:
        frames = decoded(delto_requests, session, piece) or []
        for f in frames:
            assert len(f) == (f[0] << 8 | f[1]) >= 3


@quick
@given(st.lists(st.binary(max_size=40), max_size=6), st.lists(st.integers(0, 4096)))
def test_delto_session_gives_back_frames_however_split(payloads, cuts):
    frames = [delto.frame(delto.GET_DATA, p) for p in payloads]
    session = Session(Role.DEVICE)
    got = [f for piece in chunks(b"".join(frames), cuts) for f in delto_requests(session, piece)]
    assert got == frames


@quick
@given(delto_frames(delto.GET_VERSION))
def test_delto_version_reply_any_bytes(data):
    info = decoded(delto.decode_version_reply, data)
    if info is not None:
        assert 0 <= info.model_id <= 0xFFFF and len(info.firmware) == 2


@quick
@given(st.integers(0, 0xFFFF), st.integers(0, 255), st.integers(0, 255),
       st.one_of(st.none(), st.tuples(st.integers(0, 255), st.integers(0, 255))))
def test_delto_version_reply_round_trip(model_id, major, minor, sensor):
    info = delto.VersionInfo(model_id, (major, minor), *(sensor or (None, None)))
    assert delto.decode_version_reply(delto.encode_version_reply(info)) == info


@quick
@given(delto_frames(delto.GET_DATA))
def test_delto_data_request_any_bytes(data):
    codes = decoded(delto.decode_data_request, data)
    if codes is not None:
        assert all(1 <= c <= 7 for c in codes)
        assert delto.decode_data_request(delto.encode_data_request(codes)) == codes


@quick
@given(st.one_of(delto_frames(delto.SET_DUTY), delto_frames(delto.SET_GPIO)))
def test_delto_commands_any_bytes(data):
    duties = decoded(delto.decode_duty, data)
    assert duties is None or all(-32768 <= d <= 32767 for d in duties.values())
    gpio = decoded(delto.decode_gpio, data)
    assert gpio is None or len(gpio) == 3


@quick
@given(st.lists(st.integers(-1000, 1000), min_size=1, max_size=20),
       st.tuples(st.booleans(), st.booleans(), st.booleans()))
def test_delto_commands_round_trip(duties, outputs):
    assert delto.decode_duty(delto.encode_duty(duties)) == dict(enumerate(duties, 1))
    assert delto.decode_gpio(delto.encode_gpio(outputs)) == outputs


def test_delto_reply_layout_and_fields_agree_for_every_model_and_sensor_type():
    """Every index the field map gives is inside the reply the layout unpacks: no IndexError
    whatever SensorType byte the gripper sends (an unknown one carries no sensor block)."""
    for model in MODEL_LIST:
        for codes in CODE_SETS:
            for sensor_type in range(256):
                size = delto.data_reply_length(model, codes, sensor_type) - 3
                raw = delto.unpack_data_reply(delto.frame(delto.GET_DATA, bytes(size)), model,
                                              codes, sensor_type)
                fields = delto.reply_fields(model, codes, sensor_type)
                used = [i for values in fields.values() for i, _ in values]
                assert len(used) == len(set(used))
                assert max(used) < len(raw)
                if sensor_type in delto.SENSOR_BLOCKS and delto.FINGERTIP_SENSOR in codes \
                        and not model.legacy:
                    assert ("ft" in fields) != ("tactile" in fields)
                else:
                    assert "ft" not in fields and "tactile" not in fields


@st.composite
def delto_data_replies(draw):  # type: ignore[no-untyped-def]
    """(model, codes, sensor type, reply bytes): a body of the size the layout expects or of
    any other size, or bytes without a frame at all."""
    model = draw(st.sampled_from(MODEL_LIST))
    codes = draw(st.sampled_from(CODE_SETS))
    sensor_type = draw(st.one_of(st.integers(0, 5), st.integers(0, 255)))
    size = delto.data_reply_length(model, codes, sensor_type) - 3
    body = draw(st.one_of(st.binary(min_size=size, max_size=size),
                          st.binary(max_size=size + 16)))
    data = draw(st.one_of(st.just(delto.frame(delto.GET_DATA, body)), st.binary(max_size=300)))
    return model, codes, sensor_type, data


@slow
@thorough
@given(delto_data_replies())
def test_delto_data_reply_any_bytes_every_model_and_sensor_type(case):
    model, codes, sensor_type, data = case
    raw = decoded(delto.unpack_data_reply, data, model, codes, sensor_type)
    record = decoded(delto.decode_data_reply, data, model, codes, sensor_type)
    assert (raw is None) == (record is None)
    if raw is None:
        return
    # what the driver does with each reply: every field picked and scaled
    for values in delto.reply_fields(model, codes, sensor_type).values():
        assert all(math.isfinite(raw[i] * scale) for i, scale in values)
    assert len(record.position) == len(record.current) == model.motors
    assert len(record.ft) in (0, model.fingers) and len(record.tactile) in (0, model.fingers)


@st.composite
def delto_valid_replies(draw):  # type: ignore[no-untyped-def]
    """A reply as a gripper sends it: motor ids 1..N in order, GPIO bytes 0 or 1."""
    model = draw(st.sampled_from(MODEL_LIST))
    codes = draw(st.sampled_from(CODE_SETS))
    sensor_type = draw(st.integers(0, 255))
    layout = delto._reply_layout(model, codes, sensor_type)
    fields = delto.reply_fields(model, codes, sensor_type)
    gpio = {i for i, _ in fields.get("gpio", ())}
    ranges = {"b": (-128, 127), "B": (0, 255), "h": (-32768, 32767), "H": (0, 65535)}
    values = [draw(st.integers(0, 1)) if k in gpio else draw(st.integers(*ranges[c]))
              for k, c in enumerate(delto._field_codes(layout))]
    stride = 3 if model.legacy else 5
    for m in range(model.motors):
        values[m * stride] = m + 1
    return model, codes, sensor_type, delto.frame(delto.GET_DATA, layout.pack(*values))


@slow
@thorough
@given(delto_valid_replies())
def test_delto_data_reply_round_trip(case):
    """bytes → record in SI units → bytes: the scales lose nothing."""
    model, codes, sensor_type, data = case
    record = delto.decode_data_reply(data, model, codes, sensor_type)
    assert delto.encode_data_reply(record, model, codes, sensor_type) == data


# -- Dynamixel ----------------------------------------------------------------------------------

ids = st.integers(0, dxl.MAX_ID)
params = st.one_of(st.binary(max_size=24),
                   st.lists(st.sampled_from([b"\xff", b"\xfd", b"\x00", b"\xff\xff\xfd"]),
                            max_size=8).map(b"".join))  # what stuffing is about


@st.composite
def dxl_streams(draw):  # type: ignore[no-untyped-def]
    """Valid packets, packets with a byte changed or cut short, and noise, run together."""
    parts = []
    for _ in range(draw(st.integers(0, 5))):
        kind = draw(st.sampled_from(["packet", "status", "corrupt", "short", "noise"]))
        pkt = dxl.packet(draw(ids), draw(st.integers(0, 255)), draw(params)) \
            if kind != "status" else dxl.status(draw(ids), draw(st.integers(0, 255)),
                                               draw(params))
        if kind == "corrupt":
            at = draw(st.integers(0, len(pkt) - 1))
            pkt = pkt[:at] + bytes([pkt[at] ^ draw(st.integers(1, 255))]) + pkt[at + 1:]
        elif kind == "short":
            pkt = pkt[:draw(st.integers(0, len(pkt) - 1))]
        elif kind == "noise":
            pkt = draw(st.binary(max_size=32))
        parts.append(pkt)
    return b"".join(parts)


@slow
@thorough
@given(dxl_streams(), st.lists(st.integers(0, 512), max_size=6))
def test_dynamixel_packet_reader_takes_any_stream(data, cuts):
    reader = dxl.PacketReader()
    for piece in chunks(data, cuts):
        for device_id, instruction, body in decoded(reader.feed, piece) or []:
            assert 0 <= device_id <= 255 and 0 <= instruction <= 255
            status = decoded(dxl.decode_status, device_id, instruction, body)
            if status is not None:
                status.error_text()


@quick
@given(ids, st.sampled_from([dxl.PING, dxl.READ, dxl.WRITE, dxl.SYNC_READ, dxl.STATUS]),
       params, st.lists(st.integers(0, 512), max_size=4))
def test_dynamixel_packets_round_trip_however_split(device_id, instruction, body, cuts):
    pkt = dxl.packet(device_id, instruction, body)
    reader = dxl.PacketReader()
    got = [p for piece in chunks(pkt, cuts) for p in reader.feed(piece)]
    assert got == [(device_id, instruction, body)]


@quick
@given(ids, st.integers(0, 255), params)
def test_dynamixel_status_round_trip(device_id, error, data):
    [found] = dxl.PacketReader().feed(dxl.status(device_id, error, data))
    assert dxl.decode_status(*found) == dxl.Status(device_id, error, data)


@quick
@given(ids, st.integers(0, 255), st.binary(max_size=8))
def test_dynamixel_decode_status_any_fields(device_id, instruction, body):
    decoded(dxl.decode_status, device_id, instruction, body)


def sync_reply_bytes(length: int, servo_ids: list[int]) -> st.SearchStrategy[bytes]:
    """The replies to a sync read, some corrupted, missing or out of order, or noise."""
    replies = [dxl.status(i, 0, bytes([i]) * length) for i in servo_ids]
    return st.one_of(
        st.binary(max_size=80),
        st.permutations(replies).flatmap(lambda r: st.lists(st.sampled_from(r), max_size=5))
        .map(b"".join),
        st.tuples(st.just(b"".join(replies)), st.integers(0, 200), st.integers(1, 255))
        .map(lambda t: bytes(b ^ t[2] if k == t[1] else b for k, b in enumerate(t[0]))),
    )


@slow
@thorough
@given(st.data(), st.integers(0, 12), st.lists(ids, min_size=1, max_size=4, unique=True))
def test_dynamixel_sync_replies_any_bytes(data, length, servo_ids):
    raw = data.draw(sync_reply_bytes(length, servo_ids))
    check = dxl.SyncReplies(length, servo_ids)
    for end in range(0, len(raw), 7):  # as the bytes arrive
        check.feed(raw[:end])
    for reply in check.result(raw) + dxl.split_statuses(raw):
        device_id, error, payload = reply
        assert 0 <= device_id <= 255 and 0 <= error <= 255 and isinstance(payload, bytes)
    for offset in range(0, len(raw) + 2, 5):
        at = dxl.status_at(raw, offset, length, servo_ids[0])
        assert at is None or at is False or (at[0] == servo_ids[0] and len(at[2]) == length)


@quick
@given(st.integers(1, 12), st.lists(ids, min_size=1, max_size=5, unique=True), st.data())
def test_dynamixel_sync_replies_round_trip(length, servo_ids, data):
    payloads = [data.draw(st.binary(min_size=length, max_size=length)) for _ in servo_ids]
    raw = b"".join(dxl.status(i, 0, p) for i, p in zip(servo_ids, payloads))
    expected = [(i, 0, p) for i, p in zip(servo_ids, payloads)]
    assert dxl.SyncReplies(length, servo_ids).result(raw) == expected
    assert dxl.split_statuses(raw) == expected


@quick
@given(st.integers(0, 12), st.lists(ids, min_size=1, max_size=5, unique=True),
       st.binary(max_size=120))
def test_dynamixel_fast_sync_any_bytes(length, servo_ids, raw):
    for device_id, error, payload in dxl.split_fast_sync(raw, length, servo_ids):
        assert device_id in servo_ids and 0 <= error <= 255 and len(payload) <= length


@quick
@given(st.integers(1, 12), st.lists(ids, min_size=1, max_size=5, unique=True), st.data())
def test_dynamixel_fast_sync_round_trip(length, servo_ids, data):
    blocks = [(data.draw(st.integers(0, 255)), i,
               data.draw(st.binary(min_size=length, max_size=length))) for i in servo_ids]
    raw = dxl.fast_sync_status(blocks)
    assume(b"\xff\xff\xfd\xfd" not in raw[7:])  # see the next test
    assert dxl.split_fast_sync(raw, length, servo_ids) == [(i, e, d) for e, i, d in blocks]


def test_dynamixel_fast_sync_status_with_ff_ff_fd_in_its_data_round_trips():
    blocks = [(0, 1, b"\xff\xff\xfd\xfd")]  # read as stuffed: one FD goes
    raw = dxl.fast_sync_status(blocks)
    assert dxl.split_fast_sync(raw, 4, [1]) == [(1, 0, b"\xff\xff\xfd\xfd")]


@quick
@given(st.binary(max_size=64))
def test_dynamixel_crc_matches_the_byte_at_a_time_algorithm(data):
    crc = 0
    for byte in data:
        crc = ((crc << 8) ^ dxl._TABLE[((crc >> 8) ^ byte) & 0xFF]) & 0xFFFF
    assert dxl.crc16(data) == crc


# -- Bioscara -----------------------------------------------------------------------------------

@quick
@given(st.binary(max_size=8))
def test_bioscara_replies_any_bytes(data):
    value = decoded(bioscara.decode_float, data)
    assert value is None or (isinstance(value[0], float) and 0 <= value[1] <= 255)
    flags = decoded(bioscara.decode_ping, data)
    assert flags is None or 0 <= flags <= 255
    for byte in data:
        assert isinstance(bioscara.describe_flags(byte), str)


@quick
@given(st.floats(width=32), st.integers(0, 255), st.integers(0, 255))
def test_bioscara_float_round_trip(value, register, flags):
    request = bioscara.write_float(register, value)
    assert request[0] == register
    got, got_flags = bioscara.decode_float(request[1:] + bytes([flags]))
    assert struct.pack("<f", got) == struct.pack("<f", value) and got_flags == flags


# -- LSM6DS3 ------------------------------------------------------------------------------------

SCALES = [(imu.accel_scale(g), imu.gyro_scale(d)) for g in imu.ACCEL_RANGE for d in imu.GYRO_RANGE]


@quick
@given(st.binary(max_size=20), st.sampled_from(SCALES), st.integers(0, 255))
def test_lsm6ds3_any_bytes(block, scales, who_am_i):
    reading = decoded(imu.decode, block, *scales)
    if reading is not None:
        temperature, gyro, accel = reading
        assert math.isfinite(temperature) and len(gyro) == len(accel) == 3
    name = decoded(imu.chip_name, who_am_i)
    assert (name is None) == (who_am_i not in imu.CHIPS)


@quick
@given(st.binary(min_size=imu.BLOCK, max_size=imu.BLOCK), st.sampled_from(SCALES))
def test_lsm6ds3_round_trip(block, scales):
    temperature, gyro, accel = imu.decode(block, *scales)
    assert imu.encode(temperature, gyro, accel, *scales) == block


@pytest.mark.parametrize("sensor_type", [6, 0x7F, 0xFF])
def test_a_gripper_reporting_an_unknown_sensor_type_streams_without_its_block(cli, sensor_type):
    """The driver sizes the reply and places its fields by the same rule: no sensor block,
    and the stream says which values the profile's sensors lack (exit 3)."""
    import json

    from deltoctl.families.delto.emulator import DeltoServer, firmware_for_profile
    from deltoctl.profile.catalog import load_profile

    firmware = firmware_for_profile(load_profile("dg-5f-right"), sensor_type=sensor_type)
    with DeltoServer(firmware) as server:
        result = cli("-p", "dg-5f-right", "-t", server.endpoint, "--json", "stream", "-d", "0.2",
                     "-i", "rj_dg_1_1/position,right_fingertip_finger_1/force.z")
    assert result.exit_code == 3, result.stderr
    assert "no values for right_fingertip_finger_1/*" in result.stderr
    last = json.loads(result.stdout.splitlines()[-1])["values"]
    assert last["rj_dg_1_1/position"] is not None
    assert last["right_fingertip_finger_1/force.z"] is None
