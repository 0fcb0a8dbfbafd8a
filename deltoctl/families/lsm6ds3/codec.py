"""LSM6DS3 registers, settings and scaling, sans-I/O (reference §2.5).

The MH5 configures 416 Hz, ±2 g and 245 dps, reads gyro, accelerometer and temperature, maps
the axes into its ROS frame in software and low-pass filters each value.

The conversation is the chip's register file, kept here for both sides: a write starts with a
register address, the bytes after it fill that register and the next ones (auto-increment),
and a read returns bytes from where the last write left the address. The host (the driver)
encodes a :class:`Read` or a :class:`Write` and checks what it reads back; the device (the
emulator) keeps the register address and turns each write and read into one of them.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

from deltoctl.errors import InvalidInput, ProtocolError

WHO_AM_I = 0x0F
CTRL1_XL = 0x10
CTRL2_G = 0x11
CTRL4_C = 0x13
CTRL5_C = 0x14  # self-test: ST_XL bits 1:0, ST_G bits 3:2
STATUS_REG = 0x1E  # XLDA bit 0, GDA bit 1: a new sample is ready
ORIENT_CFG_G = 0x0B
OUT_TEMP_L = 0x20  # temperature, then gyro X/Y/Z (0x22) and accelerometer X/Y/Z (0x28)
OUTX_L_G = 0x22
OUTX_L_XL = 0x28
REGISTERS = {WHO_AM_I: "WHO_AM_I", CTRL1_XL: "CTRL1_XL", CTRL2_G: "CTRL2_G",
             CTRL4_C: "CTRL4_C", CTRL5_C: "CTRL5_C", STATUS_REG: "STATUS_REG",
             ORIENT_CFG_G: "ORIENT_CFG_G", OUT_TEMP_L: "OUT_TEMP_L",
             OUTX_L_G: "OUTX_L_G", OUTX_L_XL: "OUTX_L_XL"}
REGISTER_COUNT = 0x80  # the register file: addresses 0x00-0x7F
READ_ONLY = frozenset({WHO_AM_I})  # what a write leaves as it is
BLOCK = 14  # bytes from OUT_TEMP_L to OUTZ_H_XL
BW_SCAL_ODR = 0x80  # CTRL4_C: the accelerometer bandwidth comes from CTRL1_XL's BW bits

CHIPS = {0x69: "LSM6DS3", 0x6A: "LSM6DS3TR-C"}

ODR = {12.5: 0x10, 26: 0x20, 52: 0x30, 104: 0x40, 208: 0x50, 416: 0x60, 833: 0x70,
       1660: 0x80, 3330: 0x90, 6660: 0xA0}
ACCEL_RANGE = {2: 0x00, 4: 0x08, 8: 0x0C, 16: 0x04}  # g → FS_XL bits
ACCEL_BANDWIDTH = {400: 0x00, 200: 0x01, 100: 0x02, 50: 0x03}  # Hz → BW_XL bits
GYRO_RANGE = {245: 0x00, 500: 0x04, 1000: 0x08, 2000: 0x0C}  # dps → FS_G bits

G = 9.80665
MG_PER_LSB_2G = 0.061
MDPS_PER_LSB_125 = 4.375
RAW = struct.Struct("<7h")


# The built-in self-test (ST's LSM6DS3TR-C procedure): the accelerometer at 52 Hz ±4 g, the
# gyroscope at 208 Hz 2000 dps; each axis's output must move by the datasheet's range when the
# self-test force is on.
ST_XL_POSITIVE, ST_XL_NEGATIVE = 0x01, 0x02
ST_G_POSITIVE, ST_G_NEGATIVE = 0x04, 0x0C
ST_MASK = 0x0F
XLDA, GDA = 0x01, 0x02
SELF_TEST_ACCEL = (52, 4)  # Hz, ±g
SELF_TEST_GYRO = (208, 2000)  # Hz, dps
SELF_TEST_ACCEL_MG = (90.0, 1700.0)  # |output change| per axis, mg
SELF_TEST_GYRO_DPS = (150.0, 700.0)  # |output change| per axis at 2000 dps, dps
SELF_TEST_WAIT = {"accel": 0.1, "gyro": 0.15, "gyro_on": 0.05}  # s for the output to settle
SELF_TEST_SAMPLES = 5  # averaged, after one discarded
ZERO_RATE_DPS = 10.0  # the gyroscope's zero-rate level at rest, |dps| per axis
# What the datasheets consulted do not confirm: these values are taken as the LSM6DS3TR-C's.
UNVERIFIED = ("the self-test limits of the original LSM6DS3 (WHO_AM_I 0x69)",
              "the zero-rate level (10 dps)")
RAW_AXES = struct.Struct("<3h")


def frame_name(data: bytes) -> str | None:
    """The register an I2C write selects (one byte: a read follows) or writes, for -vv."""
    if not data:
        return None
    name = register_name(data[0])
    return name if len(data) == 1 else f"write {name}"


# -- the conversation, both roles -----------------------------------------------------------------
@dataclass(frozen=True)
class Read:
    """``count`` bytes from ``register`` on (auto-increment)."""

    register: int
    count: int = 1


@dataclass(frozen=True)
class Write:
    """``values`` into ``register`` and the ones after it (none: the register a read takes)."""

    register: int
    values: bytes = b""

    def cells(self) -> list[tuple[int, int]]:
        """``(register, value)`` each value lands in, the read-only registers left out."""
        cells = [((self.register + i) % REGISTER_COUNT, v) for i, v in enumerate(self.values)]
        return [(r, v) for r, v in cells if r not in READ_ONLY]


def register_name(register: int) -> str:
    return REGISTERS.get(register, f"register {register:#04x}")


def _check_register(register: int, error: type[Exception]) -> None:
    if not 0 <= register < REGISTER_COUNT:
        raise error(f"{register:#x} is no LSM6DS3 register (0x00-0x7f)")


class Host:
    """The driver's side: the bytes of each request, and what a read brought back checked."""

    @staticmethod
    def encode(request: Read | Write) -> tuple[bytes, int]:
        """What to write, and how many bytes to read after the repeated start (0: none)."""
        _check_register(request.register, InvalidInput)
        if isinstance(request, Write):
            return bytes([request.register]) + request.values, 0
        if not 1 <= request.count <= REGISTER_COUNT:
            raise InvalidInput(f"a read of {request.count} bytes from "
                               f"{register_name(request.register)}: 1 to {REGISTER_COUNT}")
        return bytes([request.register]), request.count

    @staticmethod
    def decode(request: Read | Write, reply: bytes) -> bytes:
        expected = request.count if isinstance(request, Read) else 0
        if len(reply) != expected:
            raise ProtocolError(f"{register_name(request.register)}: expected {expected} "
                                f"bytes, got {len(reply)}")
        return reply


class Device:
    """The chip's side: the register address, set by a write and moved by every byte."""

    def __init__(self) -> None:
        self.pointer = 0

    def written(self, data: bytes) -> Write:
        """The write the host made; ProtocolError when it names no register."""
        if not data:
            raise ProtocolError("an empty write names no register")
        _check_register(data[0], ProtocolError)
        self.pointer = (data[0] + len(data) - 1) % REGISTER_COUNT
        return Write(data[0], bytes(data[1:]))

    def read(self, count: int) -> Read:
        """The read the host makes of ``count`` bytes; the address moves past them."""
        request = Read(self.pointer, count)
        self.pointer = (self.pointer + count) % REGISTER_COUNT
        return request

    @staticmethod
    def reply(registers: bytes | bytearray, request: Read) -> bytes:
        return bytes(registers[request.register:request.register + request.count])


def _lookup(table: dict, value: float, what: str) -> int:
    if value not in table:
        raise InvalidInput(f"LSM6DS3 {what} {value:g} is not one of "
                           f"{', '.join(f'{k:g}' for k in table)}")
    return table[value]


def ctrl1_xl(odr: float = 416, range_g: int = 2, bandwidth: int = 100) -> int:
    return (_lookup(ODR, odr, "output rate (Hz)") | _lookup(ACCEL_RANGE, range_g, "range (g)")
            | _lookup(ACCEL_BANDWIDTH, bandwidth, "bandwidth (Hz)"))


def ctrl2_g(odr: float = 416, range_dps: int = 245) -> int:
    return _lookup(ODR, odr, "output rate (Hz)") | _lookup(GYRO_RANGE, range_dps, "range (dps)")


def accel_scale(range_g: int) -> float:
    """m/s² per LSB: 0.061 mg at ±2 g, doubling with each range."""
    return MG_PER_LSB_2G * (range_g >> 1) / 1000.0 * G


def gyro_scale(range_dps: int) -> float:
    """rad/s per LSB: 4.375 mdps × range/125, 245 dps counted as 2 (8.75 mdps)."""
    div = 2 if range_dps == 245 else range_dps // 125
    return MDPS_PER_LSB_125 * div / 1000.0 * math.pi / 180.0


def chip_name(who_am_i: int) -> str:
    if who_am_i not in CHIPS:
        raise ProtocolError(f"WHO_AM_I reads {who_am_i:#04x}: not an LSM6DS3 (0x69) or an "
                            "LSM6DS3TR-C (0x6A)")
    return CHIPS[who_am_i]


def raw_axes(data: bytes) -> tuple[int, int, int]:
    """X, Y, Z of one sensor's output registers, in the chip's own axes (the self-test's)."""
    if len(data) != RAW_AXES.size:
        raise ProtocolError(f"expected {RAW_AXES.size} bytes of X/Y/Z, got {len(data)}")
    return RAW_AXES.unpack(data)


def decode(block: bytes, accel: float, gyro: float) -> tuple[float, tuple, tuple]:
    """Temperature (°C), angular velocity and linear acceleration in the MH5's ROS frame:
    ang_vel = (−gz, gy, −gx), lin_acc = (−az, ay, −ax)."""
    if len(block) != BLOCK:
        raise ProtocolError(f"expected {BLOCK} bytes from OUT_TEMP_L, got {len(block)}")
    t, gx, gy, gz, ax, ay, az = RAW.unpack(block)
    return (t / 16.0 + 25.0, (-gz * gyro, gy * gyro, -gx * gyro),
            (-az * accel, ay * accel, -ax * accel))


def encode(temperature: float, angular_velocity: tuple, linear_acceleration: tuple,
           accel: float, gyro: float) -> bytes:
    """The inverse of ``decode``: what the chip holds for these readings (for the emulator)."""
    wx, wy, wz = angular_velocity
    fx, fy, fz = linear_acceleration

    def raw(value: float, scale: float) -> int:
        return max(-32768, min(32767, round(value / scale)))

    return RAW.pack(raw(temperature - 25.0, 1 / 16.0), raw(-wz, gyro), raw(wy, gyro),
                    raw(-wx, gyro), raw(-fz, accel), raw(fy, accel), raw(-fx, accel))


class LowPass:
    """y = old·(1 − f) + new·f, per value; the first sample passes through (old is 0.0)."""

    def __init__(self, factor: float) -> None:
        self.factor = factor
        self.state: list[float] = []

    def __call__(self, values: tuple) -> tuple:
        if not self.state:
            self.state = [0.0] * len(values)
        f = self.factor
        self.state = [new if old == 0.0 else old * (1 - f) + new * f
                      for old, new in zip(self.state, values)]
        return tuple(self.state)


CALIBRATION_KIND = "imu_calibration"
# what a calibration file may hold at all (its own checks are tighter): beyond, it is refused
CALIBRATION_BOUNDS = {"accel_bias": (-0.5 * G, 0.5 * G), "accel_scale": (0.5, 1.5),
                      "gyro_bias": (-0.5, 0.5)}


@dataclass(frozen=True)
class Calibration:
    """Per-axis corrections in the ROS frame: accel = (raw − bias) / scale (m/s²), gyro =
    raw − bias (rad/s). Written by ``calibrate imu --tumble``, named by a sensor's
    ``calibration`` param."""

    accel_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)
    accel_scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    gyro_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def apply(self, gyro: tuple, accel: tuple) -> tuple[tuple, tuple]:
        return (tuple(w - b for w, b in zip(gyro, self.gyro_bias)),
                tuple((a - b) / s for a, b, s in zip(accel, self.accel_bias, self.accel_scale)))

    def to_data(self) -> dict[str, list[float]]:
        return {"accel_bias": [round(v, 6) for v in self.accel_bias],
                "accel_scale": [round(v, 6) for v in self.accel_scale],
                "gyro_bias": [round(v, 6) for v in self.gyro_bias]}

    @classmethod
    def from_data(cls, data: object) -> Calibration:
        """A calibration file's contents, checked: three finite numbers per correction within
        CALIBRATION_BOUNDS, from a calibration that passed its checks. Raises InvalidInput."""
        if not isinstance(data, dict) or data.get("kind") != CALIBRATION_KIND:
            raise InvalidInput(f"not an IMU calibration (expected kind: {CALIBRATION_KIND})")
        if data.get("pass") is not True:
            raise InvalidInput("this calibration failed its checks; run calibrate imu --tumble "
                               "again")
        values = {}
        for key, (low, high) in CALIBRATION_BOUNDS.items():
            axes = data.get(key)
            if not (isinstance(axes, list) and len(axes) == 3 and all(
                    isinstance(v, (int, float)) and not isinstance(v, bool)
                    and math.isfinite(v) and low <= v <= high for v in axes)):
                raise InvalidInput(f"{key} must be three numbers from {low:g} to {high:g}, "
                                   f"got {axes!r}"[:200])
            values[key] = tuple(float(v) for v in axes)
        return cls(**values)
