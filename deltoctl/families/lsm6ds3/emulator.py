"""An LSM6DS3 (or LSM6DS3TR-C) as an I2C device model: a register file with auto-increment,
outputs computed at each read from gravity, a settable orientation and rotation rate, noise,
and the full-scale settings the host wrote."""

from __future__ import annotations

import math
import random
from typing import TYPE_CHECKING

from deltoctl.families.lsm6ds3 import codec

if TYPE_CHECKING:
    from deltoctl.profile.model import Hardware
    from deltoctl.sim.serve import ServeContext

ACCEL_NOISE = 0.02  # m/s², one sigma
GYRO_NOISE = 0.002  # rad/s
RANGE_G = {bits: g for g, bits in codec.ACCEL_RANGE.items()}
RANGE_DPS = {bits: dps for dps, bits in codec.GYRO_RANGE.items()}


class Lsm6ds3Chip:
    def __init__(self, who_am_i: int = 0x6A, temperature: float = 31.0) -> None:
        self.registers = bytearray(128)
        self.registers[codec.WHO_AM_I] = who_am_i
        self.pointer = 0
        self.temperature = temperature
        self.roll = self.pitch = self.yaw = 0.0  # rad: the ROS frame against the world
        self.rates = (0.0, 0.0, 0.0)  # rad/s in the ROS frame

    def set_orientation(self, roll: float, pitch: float, yaw: float = 0.0) -> None:
        self.roll, self.pitch, self.yaw = roll, pitch, yaw

    def specific_force(self) -> tuple[float, float, float]:
        """What an accelerometer at rest measures, in the ROS frame: gravity's reaction."""
        g, r, p = codec.G, self.roll, self.pitch
        return (-g * math.sin(p), g * math.sin(r) * math.cos(p), g * math.cos(r) * math.cos(p))

    def _sample(self) -> None:
        ctrl1, ctrl2 = self.registers[codec.CTRL1_XL], self.registers[codec.CTRL2_G]
        accel = codec.accel_scale(RANGE_G[ctrl1 & 0x0C])
        gyro = codec.gyro_scale(RANGE_DPS[ctrl2 & 0x0C])
        force = tuple(v + random.gauss(0, ACCEL_NOISE) for v in self.specific_force())
        rates = tuple(v + random.gauss(0, GYRO_NOISE) for v in self.rates)
        block = codec.encode(self.temperature, rates, force, accel, gyro)
        self.registers[codec.OUT_TEMP_L:codec.OUT_TEMP_L + codec.BLOCK] = block

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
