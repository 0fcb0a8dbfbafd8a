"""Delto developer-mode protocol, sans-I/O: requests and replies to and from bytes.

Frames in both directions are ``[LEN_HI][LEN_LO][CMD] payload``, LEN counting the whole frame;
every field is big-endian; there is no checksum. Only GET_VERSION and GET_DATA are answered.
The same functions serve the driver and the emulator, and the conversation they hold is
session.py's. Bad bytes raise ProtocolError.
"""

from __future__ import annotations

import math
import re
import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache
from itertools import chain

from deltoctl.errors import ProtocolError
from deltoctl.families.delto.models import (
    FT_TYPES,
    MODELS,
    TACTILE_GRIDS,
    DeltoModel,
)

GET_DATA = 0x01
SET_DUTY = 0x05
SET_GPIO = 0x06
GET_VERSION = 0x08
SET_FT_SENSOR_OFFSET = 0x0B
COMMANDS = {GET_DATA: "GET_DATA", SET_DUTY: "SET_DUTY", SET_GPIO: "SET_GPIO",
            GET_VERSION: "GET_VERSION", SET_FT_SENSOR_OFFSET: "SET_FT_SENSOR_OFFSET"}

# GET_DATA selectors
JOINT, CURRENT, TEMPERATURE, VELOCITY, FINGERTIP_SENSOR, GPIO = 1, 2, 3, 4, 5, 6

DEFAULT_PORT = 502  # Modbus TCP's, which developer mode keeps
MAX_FRAME = 4096  # bytes, either way (the longest reply is 347)
RPM_TO_RAD_S = math.pi / 30


def frame_name(data: bytes) -> str | None:
    """The command a frame carries (requests and replies alike), for the -vv trace."""
    return COMMANDS.get(data[2], f"command {data[2]:#04x}") if len(data) >= 3 else None


def frame(cmd: int, payload: bytes = b"") -> bytes:
    return struct.pack(">HB", 3 + len(payload), cmd) + payload


def _check(data: bytes, cmd: int, what: str) -> None:
    if len(data) < 3:
        raise ProtocolError(f"{what}: {len(data)} bytes is shorter than a frame header")
    length = (data[0] << 8) | data[1]
    if length != len(data):
        raise ProtocolError(f"{what}: LEN says {length} bytes, frame has {len(data)}")
    if data[2] != cmd:
        raise ProtocolError(f"{what}: command byte {data[2]:#04x}, expected {cmd:#04x}")


# -- GET_VERSION ---------------------------------------------------------------------------------

@dataclass(frozen=True)
class VersionInfo:
    model_id: int
    firmware: tuple[int, int]
    sensor_type: int | None  # None: old firmware sent the short reply
    finger_mask: int | None

    @property
    def model(self) -> DeltoModel | None:
        return MODELS.get(self.model_id)


def encode_version_request() -> bytes:
    return frame(GET_VERSION)


def encode_version_reply(info: VersionInfo) -> bytes:
    payload = struct.pack(">HBB", info.model_id, *info.firmware)
    if info.sensor_type is not None:
        payload += bytes([info.sensor_type, info.finger_mask or 0])
    return frame(GET_VERSION, payload)


def decode_version_reply(data: bytes) -> VersionInfo:
    _check(data, GET_VERSION, "GET_VERSION reply")
    if len(data) < 7:
        raise ProtocolError(f"GET_VERSION reply: {len(data)} bytes, expected at least 7")
    model_id, major, minor = struct.unpack_from(">HBB", data, 3)
    if len(data) >= 9:
        return VersionInfo(model_id, (major, minor), data[7], data[8])
    return VersionInfo(model_id, (major, minor), None, None)


# -- GET_DATA ------------------------------------------------------------------------------------

def data_codes(model: DeltoModel, fingertip_sensor: bool, io: bool) -> tuple[int, ...]:
    if model.legacy:
        return (JOINT, CURRENT)
    codes = (JOINT, CURRENT, TEMPERATURE, VELOCITY)
    if fingertip_sensor:
        codes += (FINGERTIP_SENSOR,)
    if io:
        codes += (GPIO,)
    return codes


def encode_data_request(codes: tuple[int, ...]) -> bytes:
    return frame(GET_DATA, bytes(codes))


def decode_data_request(data: bytes) -> tuple[int, ...]:
    _check(data, GET_DATA, "GET_DATA request")
    codes = tuple(data[3:])
    bad = [c for c in codes if not 1 <= c <= 7]
    if bad:
        raise ProtocolError(f"GET_DATA request: unknown data code {bad[0]:#04x}")
    return codes


def data_reply_length(model: DeltoModel, codes: tuple[int, ...], sensor_type: int) -> int:
    return 3 + _reply_layout(model, codes, sensor_type).size


@dataclass
class DataRecord:
    """One GET_DATA reply in SI units (current in mA, as the Delto driver reports it)."""

    position: list[float]  # rad
    current: list[float]  # mA
    temperature: list[float] = field(default_factory=list)  # °C
    velocity: list[float] = field(default_factory=list)  # rad/s
    ft: list[tuple[float, ...]] = field(default_factory=list)  # per finger: F N, T N·m
    tactile: list[tuple[int, ...]] = field(default_factory=list)  # per finger, wire order
    gpio: tuple[bool, bool, bool, bool] | None = None  # output 1..3, input 1


# Each fingertip's block per sensor type: its struct format and how many values it holds.
# A type the gripper reports beyond these has no block (the vendor's parser reads none).
SENSOR_BLOCKS = {**dict.fromkeys(FT_TYPES, ("6h", 6)),
                 **{t: (f"{g.cells}{g.code}", g.cells) for t, g in TACTILE_GRIDS.items()}}


def tactile_rows(cells: tuple[int, ...] | list[int], sensor_type: int) -> list[list[int]]:
    """One finger's cells (wire order) as its grid's rows (models.TactileGrid)."""
    cols = TACTILE_GRIDS[sensor_type].cols
    return [list(cells[r:r + cols]) for r in range(0, len(cells), cols)]


def sensor_block(model: DeltoModel, codes: tuple[int, ...],
                 sensor_type: int) -> tuple[str, int] | None:
    """The fingertip block a GET_DATA reply carries per finger, or None: one rule for the
    reply's size and its fields' positions, whatever the SensorType byte says."""
    if FINGERTIP_SENSOR not in codes or model.legacy:
        return None
    return SENSOR_BLOCKS.get(sensor_type)


@lru_cache(maxsize=64)
def _reply_layout(model: DeltoModel, codes: tuple[int, ...], sensor_type: int) -> struct.Struct:
    """One precompiled struct for a whole GET_DATA reply body: the hot path of every cycle."""
    fmt = ">" + ("Bhh" if model.legacy else "Bhhhb") * model.motors
    block = sensor_block(model, codes, sensor_type)
    if block is not None:
        fmt += block[0] * model.fingers
    if GPIO in codes and not model.legacy:
        fmt += "4B"
    return struct.Struct(fmt)


@lru_cache(maxsize=64)
def reply_fields(model: DeltoModel, codes: tuple[int, ...],
                 sensor_type: int) -> dict[str, tuple[tuple[int, float], ...]]:
    """Where each value of a GET_DATA reply sits in the unpacked body, and its scale to SI:
    ``{"position": ((index, scale), ...), "current": ..., "ft": six per finger, ...}``."""
    stride = 3 if model.legacy else 5
    motors = range(model.motors)
    fields: dict[str, tuple[tuple[int, float], ...]] = {
        "position": tuple((m * stride + 1, model.position_scale()) for m in motors),
        "current": tuple((m * stride + 2, 1.0) for m in motors),  # mA
    }
    if model.legacy:
        return fields
    fields["temperature"] = tuple((m * 5 + 3, 0.1) for m in motors)
    fields["velocity"] = tuple((m * 5 + 4, RPM_TO_RAD_S) for m in motors)
    at = model.motors * 5
    block = sensor_block(model, codes, sensor_type)
    if block is not None:
        width = block[1] * model.fingers
        if sensor_type in FT_TYPES:  # F in 0.1 N, T in 0.001 N·m
            scales = (0.1, 0.1, 0.1, 0.001, 0.001, 0.001)
            fields["ft"] = tuple((at + k, scales[k % 6]) for k in range(width))
        else:  # tactile cells, as read
            fields["tactile"] = tuple((at + k, 1) for k in range(width))
        at += width
    if GPIO in codes:
        fields["gpio"] = tuple((at + k, 1) for k in range(4))
    return fields


def unpack_data_reply(data: bytes, model: DeltoModel, codes: tuple[int, ...],
                      sensor_type: int) -> tuple[int, ...]:
    """The reply's body as raw integers, in wire order (``reply_fields`` says which is which)."""
    _check(data, GET_DATA, "GET_DATA reply")
    layout = _reply_layout(model, codes, sensor_type)
    if len(data) != 3 + layout.size:
        raise ProtocolError(f"GET_DATA reply: {len(data)} bytes, expected {3 + layout.size} for "
                            f"{model.name} with codes {list(codes)}")
    return layout.unpack_from(data, 3)


def data_reply_unpacker(model: DeltoModel, codes: tuple[int, ...],
                        sensor_type: int) -> Callable[[bytes], tuple[int, ...]]:
    """``unpack_data_reply`` for one shape of reply, its layout worked out once: a cycle's
    reply is a length, a command byte and one unpack; a bad one gets the same errors."""
    layout = _reply_layout(model, codes, sensor_type)
    size = 3 + layout.size
    head = bytes([size >> 8 & 0xFF, size & 0xFF, GET_DATA])
    unpack_from = layout.unpack_from

    def unpack(data: bytes) -> tuple[int, ...]:
        if len(data) != size or data[:3] != head:
            return unpack_data_reply(data, model, codes, sensor_type)  # raises: says why
        return unpack_from(data, 3)

    return unpack


def decode_data_reply(data: bytes, model: DeltoModel, codes: tuple[int, ...],
                      sensor_type: int) -> DataRecord:
    raw = unpack_data_reply(data, model, codes, sensor_type)
    fields = reply_fields(model, codes, sensor_type)

    def values(kind: str) -> list:
        return [raw[i] * scale for i, scale in fields.get(kind, ())]

    ft, tactile = values("ft"), values("tactile")
    width = len(tactile) // model.fingers
    gpio = values("gpio")
    return DataRecord(
        position=values("position"), current=values("current"),
        temperature=values("temperature"), velocity=values("velocity"),
        ft=[tuple(ft[k:k + 6]) for k in range(0, len(ft), 6)],
        tactile=[tuple(tactile[k:k + width]) for k in range(0, len(tactile), width or 1)],
        gpio=(gpio[0] != 0, gpio[1] != 0, gpio[2] != 0, gpio[3] != 0) if gpio else None)


def encode_data_reply(record: DataRecord, model: DeltoModel, codes: tuple[int, ...],
                      sensor_type: int) -> bytes:
    """The emulator's side: a DataRecord in SI units → the reply frame."""
    scale = 1.0 / model.position_scale()
    n = model.motors
    ids = range(1, n + 1)
    position = [round(p * scale) for p in record.position[:n]]
    current = map(round, record.current[:n])
    if model.legacy:
        values = list(chain.from_iterable(zip(ids, position, current)))
    else:
        temperature = [round(t * 10) for t in record.temperature[:n]]
        velocity = [round(v * (1.0 / RPM_TO_RAD_S)) for v in record.velocity[:n]]
        values = list(chain.from_iterable(zip(ids, position, current, temperature, velocity)))
    block = sensor_block(model, codes, sensor_type)
    if block is not None:
        for f in range(model.fingers):
            if sensor_type in FT_TYPES:
                fx, fy, fz, tx, ty, tz = record.ft[f]
                values += (round(fx * 10), round(fy * 10), round(fz * 10),
                           round(tx * 1000), round(ty * 1000), round(tz * 1000))
            else:
                values += record.tactile[f][: block[1]]
    if GPIO in codes and not model.legacy:
        values += (1 if b else 0 for b in (record.gpio or (False,) * 4))
    layout = _reply_layout(model, codes, sensor_type)
    try:
        body = layout.pack(*values)
    except struct.error:  # a value beyond its field: saturate, as the firmware's int16 does
        limits = [(-128, 127) if c == "b" else (0, 255) if c == "B" else (-32768, 32767)
                  if c == "h" else (0, 65535) for c in _field_codes(layout)]
        body = layout.pack(*(max(lo, min(hi, v)) for v, (lo, hi) in zip(values, limits)))
    return frame(GET_DATA, body)


def _field_codes(layout: struct.Struct) -> str:
    out = ""
    for count, code in re.findall(r"(\d*)([a-zA-Z])", layout.format.lstrip("<>")):
        out += code * int(count or 1)
    return out


# -- commands without a reply -------------------------------------------------------------------

@lru_cache(maxsize=8)
def _duty_layout(motors: int) -> struct.Struct:
    return struct.Struct(">HB" + "Bh" * motors)


def encode_duty(duties: list[int]) -> bytes:
    """Duty per motor in 0.1 % (±1000 = ±100 %), motor ids 1..N."""
    n = len(duties)
    clamped = [-1000 if d < -1000 else 1000 if d > 1000 else int(d) for d in duties]
    return _duty_layout(n).pack(3 + 3 * n, SET_DUTY, *chain.from_iterable(zip(range(1, n + 1),
                                                                              clamped)))


def decode_duty(data: bytes) -> dict[int, int]:
    _check(data, SET_DUTY, "SET_DUTY")
    body = data[3:]
    if len(body) % 3:
        raise ProtocolError(f"SET_DUTY: {len(body)} payload bytes is not a multiple of 3")
    return {body[i]: struct.unpack_from(">h", body, i + 1)[0] for i in range(0, len(body), 3)}


def encode_gpio(outputs: tuple[bool, bool, bool]) -> bytes:
    return frame(SET_GPIO, bytes(1 if o else 0 for o in outputs))


def decode_gpio(data: bytes) -> tuple[bool, bool, bool]:
    _check(data, SET_GPIO, "SET_GPIO")
    if len(data) != 6:
        raise ProtocolError(f"SET_GPIO: {len(data)} bytes, expected 6")
    return (data[3] != 0, data[4] != 0, data[5] != 0)


def encode_ft_offset() -> bytes:
    return frame(SET_FT_SENSOR_OFFSET)
