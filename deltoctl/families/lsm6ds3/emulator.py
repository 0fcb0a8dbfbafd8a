"""An LSM6DS3 (or LSM6DS3TR-C) as an I2C device model: a register file with auto-increment,
outputs computed at each read from gravity, a settable orientation and rotation rate, noise,
bias and scale errors, the self-test's response (CTRL5_C), and the full-scale settings the host
wrote. A test turns the chip (``set_orientation``, ``point_up``) as an operator would."""

from __future__ import annotations

import math
import random
from typing import TYPE_CHECKING

from deltoctl.core.serving import ServeContext
from deltoctl.families.lsm6ds3 import codec

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
        self.registers = bytearray(128)
        self.registers[codec.WHO_AM_I] = who_am_i
        self.pointer = 0
        self.temperature = temperature
        self.roll = self.pitch = self.yaw = 0.0  # rad: the ROS frame against the world
        self.rates = (0.0, 0.0, 0.0)  # rad/s in the ROS frame
        self.accel_noise, self.gyro_noise = ACCEL_NOISE, GYRO_NOISE  # one sigma
        # the sensor's errors, in the ROS frame: accel reads scale·true + bias; gyro true + bias
        self.accel_bias = (0.0, 0.0, 0.0)  # m/s²
        self.accel_scale = (1.0, 1.0, 1.0)
        self.gyro_bias = (0.0, 0.0, 0.0)  # rad/s
        # what the self-test force adds to each of the chip's axes: mg, dps (0: a broken part)
        self.self_test = (600.0, 300.0)

    def set_orientation(self, roll: float, pitch: float, yaw: float = 0.0) -> None:
        self.roll, self.pitch, self.yaw = roll, pitch, yaw

    def point_up(self, axis: str) -> None:
        """Lay the chip with this axis of the ROS frame (``"+x"`` … ``"-z"``) up."""
        self.set_orientation(*(math.radians(a) for a in UP[axis]))

    def specific_force(self) -> tuple[float, float, float]:
        """What an accelerometer at rest measures, in the ROS frame: gravity's reaction."""
        g, r, p = codec.G, self.roll, self.pitch
        return (-g * math.sin(p), g * math.sin(r) * math.cos(p), g * math.cos(r) * math.cos(p))

    def _sample(self) -> None:
        ctrl1, ctrl2 = self.registers[codec.CTRL1_XL], self.registers[codec.CTRL2_G]
        accel = codec.accel_scale(RANGE_G[ctrl1 & 0x0C])
        gyro = codec.gyro_scale(RANGE_DPS[ctrl2 & 0x0C])
        force = tuple(s * v + b + random.gauss(0, self.accel_noise) for v, s, b in
                      zip(self.specific_force(), self.accel_scale, self.accel_bias))
        rates = tuple(v + b + random.gauss(0, self.gyro_noise)
                      for v, b in zip(self.rates, self.gyro_bias))
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

    def write(self, data: bytes) -> None:
        if not data:
            return
        self.pointer = data[0]
        for value in data[1:]:
            if self.pointer != codec.WHO_AM_I:  # read-only
                self.registers[self.pointer] = value
            self.pointer = (self.pointer + 1) % len(self.registers)

    def read(self, length: int) -> bytes:
        if self.pointer <= codec.OUTX_L_XL + 5 and self.pointer + length > codec.OUT_TEMP_L:
            self._sample()
        if self.pointer == codec.STATUS_REG:  # a new sample at every read
            self.registers[codec.STATUS_REG] = codec.XLDA | codec.GDA
        start = self.pointer
        self.pointer = (start + length) % len(self.registers)
        return bytes(self.registers[start:start + length])


def serve(ctx: ServeContext, blocks: list[Hardware]) -> dict[str, str]:
    """Each IMU on its block's simulated I2C bus, with the WHO_AM_I and tilt asked for."""
    o = ctx.options
    buses = {}
    for hw in blocks:
        bus, url = ctx.i2c_bus(hw.bus or "i2c")
        for sensor in hw.sensors:
            if sensor.address is None:
                continue
            chip = Lsm6ds3Chip()
            chip.registers[codec.WHO_AM_I] = o.who_am_i
            chip.set_orientation(*(math.radians(a) for a in o.orientation[:3]))
            bus.devices[sensor.address] = chip
        buses[hw.bus or "i2c"] = url
    return buses
