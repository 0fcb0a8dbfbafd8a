"""The LSM6DS3 on an I2C bus: detect by WHO_AM_I, configure rate and range, read gyro,
accelerometer and temperature into a sensor's interfaces (``imu/angular_velocity.x`` …)."""

from __future__ import annotations

from typing import Any

from deltoctl.core.driver import Block, Driver
from deltoctl.errors import DeltoctlError, DeviceError, InvalidInput, ProtocolError
from deltoctl.families.lsm6ds3 import codec
from deltoctl.transport.i2c import I2CBus, shared_bus

AXES = ("x", "y", "z")
# no orientation estimate: the MH5 reports a fixed quaternion
ORIENTATION = {"orientation.x": 0.0, "orientation.y": 0.0, "orientation.z": 0.0,
               "orientation.w": 1.0}


class Lsm6ds3Driver(Driver):
    def __init__(self, block: Block) -> None:
        super().__init__(block)
        hw = block.hw
        if not hw.sensors or hw.sensors[0].address is None:
            raise InvalidInput(f"{hw.name}: an IMU block needs a sensor with an address")
        self.sensor = hw.sensors[0]
        self.address = self.sensor.address
        p = {**hw.params, **self.sensor.params}
        try:
            self.odr = float(p.get("odr", 416))
            self.range_g = int(p.get("accel_range", 2))
            self.range_dps = int(p.get("gyro_range", 245))
            self.lpf = codec.LowPass(float(p.get("lpf", 1.0)))
        except ValueError as exc:
            raise InvalidInput(f"{hw.name}: {exc}") from None
        self.settings = (codec.ctrl1_xl(self.odr, self.range_g),
                         codec.ctrl2_g(self.odr, self.range_dps))
        self.accel = codec.accel_scale(self.range_g)
        self.gyro = codec.gyro_scale(self.range_dps)
        self.bus: I2CBus | None = None
        self.chip = ""
        self._request = bytes([codec.OUT_TEMP_L])

    @property
    def stats(self) -> dict[str, int]:
        bus = self.bus.stats if self.bus else {"packets": 0, "errors": 0}
        return {"packets": bus["packets"], "errors": bus["errors"], "reconnects": 0}

    def _register(self, register: int) -> int:
        assert self.bus is not None
        return self.bus.transfer(self.address, bytes([register]), 1)[0]

    def configure(self) -> None:
        self.bus = shared_bus(self.block.links, self.url)
        who = self._register(codec.WHO_AM_I)
        try:
            self.chip = codec.chip_name(who)
        except ProtocolError as exc:
            raise DeviceError(f"{self.sensor.name} at {self.address:#04x} on {self.url}: "
                              f"{exc.message}", hint="check the address and the part") from None
        ctrl1, ctrl2 = self.settings
        self.bus.write(self.address, bytes([codec.CTRL1_XL, ctrl1]))
        self.bus.write(self.address, bytes([codec.CTRL2_G, ctrl2]))
        ctrl4 = self._register(codec.CTRL4_C)
        self.bus.write(self.address, bytes([codec.CTRL4_C, ctrl4 | codec.BW_SCAL_ODR]))
        self.bus.write(self.address, bytes([codec.ORIENT_CFG_G, 0]))  # remap in software
        self.connected = True

    def read(self) -> dict[str, float]:
        assert self.bus is not None
        name = self.sensor.name
        try:
            block = self.bus.transfer(self.address, self._request, codec.BLOCK)
            temperature, gyro, accel = codec.decode(block, self.accel, self.gyro)
        except DeltoctlError:
            self.connected = False
            return self.values
        self.connected = True
        filtered = self.lpf((*gyro, *accel))
        for i, axis in enumerate(AXES):
            self.values[f"{name}/angular_velocity.{axis}"] = filtered[i]
            self.values[f"{name}/linear_acceleration.{axis}"] = filtered[3 + i]
        for key, value in ORIENTATION.items():
            self.values[f"{name}/{key}"] = value
        self.values[f"{name}/temperature"] = temperature
        return self.values

    def detect(self) -> dict:
        check = {"what": f"{self.sensor.name} at {self.address:#04x}",
                 "profile": "LSM6DS3 or LSM6DS3TR-C", "device": self.chip or "no answer",
                 "match": bool(self.chip)}
        return {"bus": self.url, "chip": self.chip, "checks": [check],
                "summary": f"{self.sensor.name}: {self.chip} at {self.address:#04x}"}

    def identify(self) -> dict:
        return {"bus": self.url, "address": f"{self.address:#04x}", "chip": self.chip,
                "output_rate_hz": self.odr, "accel_range_g": self.range_g,
                "gyro_range_dps": self.range_dps}

    # -- configuration ---------------------------------------------------------------------------
    def _config_registers(self) -> dict[int, tuple[str, str]]:
        """Address → (name, access) of the identity and control registers; "profile": the
        driver writes it from the profile (odr, accel_range, gyro_range) at each start."""
        return {
            0x06: ("FIFO_CTRL1", "RW"), 0x07: ("FIFO_CTRL2", "RW"), 0x08: ("FIFO_CTRL3", "RW"),
            0x09: ("FIFO_CTRL4", "RW"), 0x0A: ("FIFO_CTRL5", "RW"),
            codec.ORIENT_CFG_G: ("DRDY_PULSE_CFG_G" if self.chip == "LSM6DS3TR-C"
                                 else "ORIENT_CFG_G", "profile"),
            0x0D: ("INT1_CTRL", "RW"), 0x0E: ("INT2_CTRL", "RW"),
            codec.WHO_AM_I: ("WHO_AM_I", "R"),
            codec.CTRL1_XL: ("CTRL1_XL", "profile"), codec.CTRL2_G: ("CTRL2_G", "profile"),
            0x12: ("CTRL3_C", "RW"), codec.CTRL4_C: ("CTRL4_C", "RW"), 0x14: ("CTRL5_C", "RW"),
            0x15: ("CTRL6_C", "RW"), 0x16: ("CTRL7_G", "RW"), 0x17: ("CTRL8_XL", "RW"),
            0x18: ("CTRL9_XL", "RW"), 0x19: ("CTRL10_C", "RW"),
        }

    def config_read(self) -> dict[str, dict[str, dict[str, Any]]]:
        """The chip's identity and control registers, one byte each (one read per register:
        auto-increment is itself a CTRL3_C setting), the rates and ranges spelled out."""
        odr = {bits: hz for hz, bits in codec.ODR.items()}
        accel = {bits: g for g, bits in codec.ACCEL_RANGE.items()}
        gyro = {bits: dps for dps, bits in codec.GYRO_RANGE.items()}
        band = {bits: hz for hz, bits in codec.ACCEL_BANDWIDTH.items()}

        def rate(value: int) -> str:
            return f"{odr[value & 0xF0]:g} Hz" if value & 0xF0 in odr else "power-down"

        entries = {}
        for register, (name, access) in self._config_registers().items():
            value = self._register(register)
            entry: dict[str, Any] = {"value": value, "access": access, "address": register,
                                     "min": 0, "max": 255}
            if register == codec.WHO_AM_I:
                entry["meaning"] = codec.CHIPS.get(value, "unknown")
            elif register == codec.CTRL1_XL:
                entry["meaning"] = (f"{rate(value)}, ±{accel[value & 0x0C]} g, "
                                    f"filter {band[value & 0x03]} Hz")
            elif register == codec.CTRL2_G:
                entry["meaning"] = f"{rate(value)}, ±{gyro[value & 0x0C]} dps"
            entries[name] = entry
        return {self.sensor.name: entries}

    def config_write(self, changes: dict[str, dict[str, Any]],
                     allow: frozenset[str] = frozenset()) -> dict[str, dict[str, Any]]:
        """The writable control registers in address order (FIFO, interrupts, CTRL3_C to
        CTRL10_C), then read back; CTRL3_C's BOOT and SW_RESET bits are commands, refused."""
        assert self.bus is not None
        by_name = {name: (register, access)
                   for register, (name, access) in self._config_registers().items()}
        writes = []
        for part, items in changes.items():
            if part != self.sensor.name:
                raise InvalidInput(f"{self.hw.name} has no sensor {part!r}")
            for name, value in items.items():
                register, access = by_name.get(name, (None, ""))
                if register is None or access != "RW":
                    raise InvalidInput(f"{part}: {name!r} is not a register a restore writes")
                if not isinstance(value, int) or isinstance(value, bool) or \
                        not 0 <= value <= 255:
                    raise InvalidInput(f"{part}: {name} takes a byte (0-255), not {value!r}")
                if name == "CTRL3_C" and value & 0x81:
                    raise InvalidInput(f"{part}: CTRL3_C {value:#04x} sets BOOT or SW_RESET, "
                                       "which are commands, not settings")
                writes.append((register, name, value))
        writes.sort()
        for register, _, value in writes:
            self.bus.write(self.address, bytes([register, value]))
        return {self.sensor.name: {name: self._register(register)
                                   for register, name, _ in writes}} if writes else {}

    def cleanup(self) -> None:
        self.bus = None  # the System closes the shared bus
        self.connected = False
