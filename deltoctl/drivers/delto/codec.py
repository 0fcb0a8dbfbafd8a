"""Delto developer-mode protocol, sans-I/O: requests and replies to and from bytes.

Frames in both directions are ``[LEN_HI][LEN_LO][CMD] payload``, LEN counting the whole frame;
every field is big-endian; there is no checksum. Only GET_VERSION and GET_DATA are answered.
The same functions serve the driver and the emulator. Bad bytes raise ProtocolError.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field

from deltoctl.drivers.delto.models import (
    FT_TYPES,
    MODELS,
    SENSOR_BYTES,
    SENSOR_NONE,
    TACTILE_M,
    TACTILE_S,
    DeltoModel,
)
from deltoctl.errors import ProtocolError

GET_DATA = 0x01
SET_DUTY = 0x05
SET_GPIO = 0x06
GET_VERSION = 0x08
SET_FT_SENSOR_OFFSET = 0x0B

# GET_DATA selectors
JOINT, CURRENT, TEMPERATURE, VELOCITY, FINGERTIP_SENSOR, GPIO = 1, 2, 3, 4, 5, 6

MAX_FRAME = 4096
RPM_TO_RAD_S = math.pi / 30


def frame(cmd: int, payload: bytes = b"") -> bytes:
    return struct.pack(">HB", 3 + len(payload), cmd) + payload


class FrameReader:
    """Reassembles frames from a byte stream: ``feed(data)`` returns the complete ones."""

    def __init__(self) -> None:
        self._buffer = bytearray()

    def feed(self, data: bytes) -> list[bytes]:
        self._buffer += data
        frames = []
        while len(self._buffer) >= 2:
            length = (self._buffer[0] << 8) | self._buffer[1]
            if length < 3 or length > MAX_FRAME:
                self._buffer.clear()
                raise ProtocolError(f"frame length {length} is not possible "
                                    f"(3..{MAX_FRAME})")
            if len(self._buffer) < length:
                break
            frames.append(bytes(self._buffer[:length]))
            del self._buffer[:length]
        return frames

    def pending(self) -> int:
        return len(self._buffer)


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
    length = 3 + model.motors * model.bytes_per_motor
    if FINGERTIP_SENSOR in codes and not model.legacy:
        length += SENSOR_BYTES.get(sensor_type, 0) * model.fingers
    if GPIO in codes and not model.legacy:
        length += 4
    return length


@dataclass
class DataRecord:
    """One GET_DATA reply in SI units (current in mA, as the Delto driver reports it)."""

    position: list[float]  # rad
    current: list[float]  # mA
    temperature: list[float] = field(default_factory=list)  # °C
    velocity: list[float] = field(default_factory=list)  # rad/s
    ft: list[tuple[float, ...]] = field(default_factory=list)  # per finger: F N, T N·m
    tactile: list[tuple[int, ...]] = field(default_factory=list)
    gpio: tuple[bool, bool, bool, bool] | None = None  # output 1..3, input 1


def decode_data_reply(data: bytes, model: DeltoModel, codes: tuple[int, ...],
                      sensor_type: int) -> DataRecord:
    _check(data, GET_DATA, "GET_DATA reply")
    expected = data_reply_length(model, codes, sensor_type)
    if len(data) != expected:
        raise ProtocolError(f"GET_DATA reply: {len(data)} bytes, expected {expected} for "
                            f"{model.name} with codes {list(codes)}")
    scale = model.position_scale()
    n = model.motors
    record = DataRecord(position=[0.0] * n, current=[0.0] * n)
    offset = 3
    if model.legacy:
        for i in range(n):
            _, pos, cur = struct.unpack_from(">Bhh", data, offset)
            record.position[i] = pos * scale
            record.current[i] = float(cur)
            offset += 5
        return record
    record.temperature = [0.0] * n
    record.velocity = [0.0] * n
    for i in range(n):
        _, pos, cur, temp, vel = struct.unpack_from(">Bhhhb", data, offset)
        record.position[i] = pos * scale
        record.current[i] = float(cur)
        record.temperature[i] = temp * 0.1
        record.velocity[i] = vel * RPM_TO_RAD_S
        offset += 8
    if FINGERTIP_SENSOR in codes and sensor_type != SENSOR_NONE:
        for _ in range(model.fingers):
            if sensor_type in FT_TYPES:
                fx, fy, fz, tx, ty, tz = struct.unpack_from(">6h", data, offset)
                record.ft.append((fx * 0.1, fy * 0.1, fz * 0.1,
                                  tx * 0.001, ty * 0.001, tz * 0.001))
            elif sensor_type == TACTILE_M:
                record.tactile.append(tuple(data[offset:offset + 15]))
            elif sensor_type == TACTILE_S:
                record.tactile.append(struct.unpack_from(">18H", data, offset))
            offset += SENSOR_BYTES[sensor_type]
    if GPIO in codes:
        record.gpio = tuple(b != 0 for b in data[offset:offset + 4])  # type: ignore[assignment]
    return record


def _wire(value: float, limit: int = 32767) -> int:
    return max(-limit - 1, min(limit, round(value)))


def encode_data_reply(record: DataRecord, model: DeltoModel, codes: tuple[int, ...],
                      sensor_type: int) -> bytes:
    """The emulator's side: a DataRecord in SI units → the reply frame."""
    scale = model.position_scale()
    out = bytearray()
    for i in range(model.motors):
        pos = _wire(record.position[i] / scale)
        cur = _wire(record.current[i])
        if model.legacy:
            out += struct.pack(">Bhh", i + 1, pos, cur)
        else:
            out += struct.pack(">Bhhhb", i + 1, pos, cur, _wire(record.temperature[i] * 10),
                               _wire(record.velocity[i] / RPM_TO_RAD_S, 127))
    if FINGERTIP_SENSOR in codes and not model.legacy and sensor_type != SENSOR_NONE:
        for f in range(model.fingers):
            if sensor_type in FT_TYPES:
                fx, fy, fz, tx, ty, tz = record.ft[f]
                out += struct.pack(">6h", *(_wire(v * 10) for v in (fx, fy, fz)),
                                   *(_wire(v * 1000) for v in (tx, ty, tz)))
            elif sensor_type == TACTILE_M:
                out += bytes(record.tactile[f][:15])
            elif sensor_type == TACTILE_S:
                out += struct.pack(">18H", *record.tactile[f][:18])
    if GPIO in codes and not model.legacy:
        out += bytes(1 if b else 0 for b in (record.gpio or (False,) * 4))
    return frame(GET_DATA, bytes(out))


# -- commands without a reply -------------------------------------------------------------------

def encode_duty(duties: list[int]) -> bytes:
    """Duty per motor in 0.1 % (±1000 = ±100 %), motor ids 1..N."""
    payload = bytearray()
    for i, duty in enumerate(duties):
        payload += struct.pack(">Bh", i + 1, max(-1000, min(1000, int(duty))))
    return frame(SET_DUTY, bytes(payload))


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
