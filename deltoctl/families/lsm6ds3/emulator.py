"""An LSM6DS3 (or LSM6DS3TR-C) as an I2C device model: a register file with auto-increment,
outputs computed at each read from gravity, a settable orientation and rotation rate, noise,
bias and scale errors, the self-test's response (CTRL5_C), and the full-scale settings the host
wrote. A test turns the chip (``set_orientation``, ``point_up``) as an operator would; ``sim
serve`` turns it through a timed sequence of faces (``--faces``) or by a control line on its
standard input (``face -x``, ``tilt 10 0 0``, ``rate 0 0 90``, ``faces +z:2,-z:2``)."""

from __future__ import annotations

import errno
import math
import os
import random
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING

from deltoctl.core.emulator_contract import ServeContext
from deltoctl.errors import InvalidInput, ProtocolError
from deltoctl.families.lsm6ds3 import FAMILY, codec

if TYPE_CHECKING:
    from deltoctl.profile.model import Hardware

ACCEL_NOISE = 0.02  # m/s², one sigma
GYRO_NOISE = 0.002  # rad/s
RANGE_G = {bits: g for g, bits in codec.ACCEL_RANGE.items()}
RANGE_DPS = {bits: dps for dps, bits in codec.GYRO_RANGE.items()}
# the (roll, pitch) that points each axis of the ROS frame up, degrees
UP = {"+z": (0.0, 0.0), "-z": (180.0, 0.0), "+y": (90.0, 0.0), "-y": (-90.0, 0.0),
      "+x": (0.0, -90.0), "-x": (0.0, 90.0)}


class Lsm6ds3Chip:
    def __init__(self, who_am_i: int = 0x6A, temperature: float = 31.0) -> None:
        self.registers = bytearray(codec.REGISTER_COUNT)
        self.registers[codec.WHO_AM_I] = who_am_i
        self.device = codec.Device()  # the register address a read starts from
        self.temperature = temperature
        self.roll = self.pitch = self.yaw = 0.0  # rad: the ROS frame against the world
        self.rates = (0.0, 0.0, 0.0)  # rad/s in the ROS frame
        self.accel_noise, self.gyro_noise = ACCEL_NOISE, GYRO_NOISE  # one sigma
        # the sensor's errors, in the ROS frame: each reads scale·true + bias
        self.accel_bias = (0.0, 0.0, 0.0)  # m/s²
        self.accel_scale = (1.0, 1.0, 1.0)
        self.gyro_bias = (0.0, 0.0, 0.0)  # rad/s
        self.gyro_scale = (1.0, 1.0, 1.0)
        self.faces: tuple[tuple[str, float], ...] = ()  # (axis up, seconds), over and over
        self.faces_since = 0.0  # time.monotonic() when the sequence began
        # what the self-test force adds to each of the chip's axes: mg, dps (0: a broken part)
        self.self_test = (600.0, 300.0)

    def set_orientation(self, roll: float, pitch: float, yaw: float = 0.0) -> None:
        self.roll, self.pitch, self.yaw = roll, pitch, yaw

    def point_up(self, axis: str) -> None:
        """Lay the chip with this axis of the ROS frame (``"+x"`` … ``"-z"``) up."""
        self.set_orientation(*(math.radians(a) for a in UP[axis]))

    def turn_through(self, faces: Sequence[tuple[str, float]]) -> None:
        """From now on, each ``(axis, seconds)`` in turn has its axis up, over and over."""
        self.faces, self.faces_since = tuple(faces), time.monotonic()
        self._follow_faces()

    def face_now(self) -> str | None:
        """The axis the face sequence has up now (None without one)."""
        total = sum(seconds for _, seconds in self.faces)
        if not total:
            return None
        elapsed = (time.monotonic() - self.faces_since) % total
        for axis, seconds in self.faces:
            if elapsed < seconds:
                return axis
            elapsed -= seconds
        return self.faces[-1][0]

    def _follow_faces(self) -> None:
        axis = self.face_now()
        if axis is not None:
            self.point_up(axis)

    def specific_force(self) -> tuple[float, float, float]:
        """What an accelerometer at rest measures, in the ROS frame: gravity's reaction."""
        g, r, p = codec.G, self.roll, self.pitch
        return (-g * math.sin(p), g * math.sin(r) * math.cos(p), g * math.cos(r) * math.cos(p))

    def _sample(self) -> None:
        ctrl1, ctrl2 = self.registers[codec.CTRL1_XL], self.registers[codec.CTRL2_G]
        accel = codec.accel_scale(RANGE_G[ctrl1 & 0x0C])
        gyro = codec.gyro_scale(RANGE_DPS[ctrl2 & 0x0C])
        self._follow_faces()
        force = tuple(s * v + b + random.gauss(0, self.accel_noise) for v, s, b in
                      zip(self.specific_force(), self.accel_scale, self.accel_bias))
        rates = tuple(s * v + b + random.gauss(0, self.gyro_noise)
                      for v, s, b in zip(self.rates, self.gyro_scale, self.gyro_bias))
        force, rates = self._self_test_force(force, rates)
        block = codec.encode(self.temperature, rates, force, accel, gyro)
        self.registers[codec.OUT_TEMP_L:codec.OUT_TEMP_L + codec.BLOCK] = block

    def _self_test_force(self, force: tuple, rates: tuple) -> tuple[tuple, tuple]:
        """The self-test adds its force to each chip axis (+ or −, as CTRL5_C asks); the ROS
        frame is (−z, y, −x) of the chip's."""
        ctrl5 = self.registers[codec.CTRL5_C]
        accel = {codec.ST_XL_POSITIVE: 1, codec.ST_XL_NEGATIVE: -1}.get(ctrl5 & 0x03, 0)
        gyro = {codec.ST_G_POSITIVE: 1, codec.ST_G_NEGATIVE: -1}.get(ctrl5 & 0x0C, 0)
        da = accel * self.self_test[0] / 1000.0 * codec.G
        dg = gyro * math.radians(self.self_test[1])
        return ((force[0] - da, force[1] + da, force[2] - da),
                (rates[0] - dg, rates[1] + dg, rates[2] - dg))

    # -- the I2C side: writes and reads through the device role of the codec ------------------
    def write(self, data: bytes) -> None:
        """A register selected, and the values after it stored (a NACK for no register)."""
        if not data:
            return
        try:
            request = self.device.written(data)
        except ProtocolError:
            raise OSError(errno.EREMOTEIO, os.strerror(errno.EREMOTEIO)) from None
        for register, value in request.cells():
            self.registers[register] = value

    def read(self, length: int) -> bytes:
        request = self.device.read(length)
        start = request.register
        if start <= codec.OUTX_L_XL + 5 and start + length > codec.OUT_TEMP_L:
            self._sample()
        if start == codec.STATUS_REG:  # a new sample at every read
            self.registers[codec.STATUS_REG] = codec.XLDA | codec.GDA
        return self.device.reply(self.registers, request)


def serve(ctx: ServeContext, blocks: list[Hardware]) -> dict[str, str]:
    """Each IMU on its block's simulated I2C bus, with the WHO_AM_I, tilt, face sequence and
    errors asked for; the control lines turn them all (they sit on one robot)."""
    o = ctx.options
    buses, chips = {}, []
    for hw in blocks:
        bus, url = ctx.i2c_bus(hw.bus or "i2c")
        for sensor in hw.sensors:
            if sensor.address is None:
                continue
            chip = Lsm6ds3Chip(o.who_am_i)
            chip.set_orientation(*(math.radians(a) for a in o.orientation[:3]))
            chip.accel_bias, chip.accel_scale = tuple(o.accel_bias), tuple(o.accel_scale)
            chip.gyro_bias, chip.gyro_scale = tuple(o.gyro_bias), tuple(o.gyro_scale)
            if o.faces:
                chip.turn_through(o.faces)
            bus.devices[sensor.address] = chip
            chips.append(chip)
        buses[hw.bus or "i2c"] = url
    if chips:
        _controls(ctx, chips)
    return buses


# what a control line may ask
TILT_LIMIT = 360.0  # degrees
RATE_LIMIT = 2000.0  # dps: the chip's widest full scale


def _numbers(words: list[str], counts: tuple[int, ...], limit: float, usage: str) -> list[float]:
    try:
        values = [float(w) for w in words]
    except ValueError:
        values = []
    if len(values) not in counts or not all(math.isfinite(v) and abs(v) <= limit
                                            for v in values):
        raise InvalidInput(f"takes {usage}, each within ±{limit:g}, got {' '.join(words)!r}")
    return values


def _controls(ctx: ServeContext, chips: list[Lsm6ds3Chip]) -> None:
    faces_option = next(o for o in FAMILY.serve_options if o.name == "faces")

    def face(words: list[str]) -> str:
        if len(words) != 1 or words[0] not in UP:
            raise InvalidInput(f"takes one axis to put up ({', '.join(UP)}), "
                               f"got {' '.join(words)!r}")
        for chip in chips:
            chip.faces = ()
            chip.point_up(words[0])
        return f"imu: {words[0]} up"

    def tilt(words: list[str]) -> str:
        angles = _numbers(words, (2, 3), TILT_LIMIT, "ROLL PITCH [YAW] in degrees")
        for chip in chips:
            chip.faces = ()
            chip.set_orientation(*(math.radians(a) for a in angles))
        return f"imu: tilted {' '.join(format(a, 'g') for a in angles)} degrees"

    def rate(words: list[str]) -> str:
        dps = _numbers(words, (3,), RATE_LIMIT, "WX WY WZ in degrees per second")
        for chip in chips:
            chip.rates = tuple(math.radians(w) for w in dps)
        return f"imu: turning at {' '.join(format(w, 'g') for w in dps)} dps"

    def faces(words: list[str]) -> str:
        if len(words) != 1:
            raise InvalidInput(f"takes AXIS:SECONDS,…, got {' '.join(words)!r}")
        steps = faces_option.value(words[0])
        for chip in chips:
            chip.turn_through(steps)
        return f"imu: through {words[0]}"

    ctx.control("face", "face AXIS: the IMU with this axis up (+x -x +y -y +z -z)", face)
    ctx.control("tilt", "tilt ROLL PITCH [YAW]: the IMU tilted so, in degrees", tilt)
    ctx.control("rate", "rate WX WY WZ: the IMU turning at these degrees per second", rate)
    ctx.control("faces", "faces AXIS:SECONDS,...: the IMU through these faces, over and "
                "over", faces)
