"""The LSM6DS3 on an I2C bus: detect by WHO_AM_I, configure rate and range, read gyro,
accelerometer and temperature into a sensor's interfaces (``imu/angular_velocity.x`` …),
corrected by the calibration file the sensor's ``calibration`` param names; the built-in
self-test."""

from __future__ import annotations

import hashlib
import json
import math
import time
from pathlib import Path
from typing import Any

from deltoctl import registry
from deltoctl.core.driver import Block, Driver
from deltoctl.core.exchange import ExchangePolicy
from deltoctl.errors import DeltoctlError, DeviceError, InvalidInput, ProtocolError
from deltoctl.families.lsm6ds3 import codec
from deltoctl.transport import i2c
from deltoctl.transport.i2c import I2CBus  # what every I2C link gives

AXES = ("x", "y", "z")
ZERO_RATE = math.radians(codec.ZERO_RATE_DPS)  # rad/s: the gyroscope at rest, per axis
# no orientation estimate: the MH5 reports a fixed quaternion
ORIENTATION = {"orientation.x": 0.0, "orientation.y": 0.0, "orientation.z": 0.0,
               "orientation.w": 1.0}
POLICY = ExchangePolicy(tries=3, pause=50e-6)  # as every I2C device of the MH5


def exchange(bus: I2CBus, address: int, request: codec.Read | codec.Write) -> bytes:
    """One transaction through the host role, under the exchange policy (i2c.exchange);
    what a read brought back."""
    data, length = codec.Host.encode(request)

    def attempt() -> bytes:
        if length:
            return bus.transfer(address, data, length)
        bus.write(address, data)
        return b""

    return codec.Host.decode(request, i2c.exchange(bus, address, attempt, POLICY.run,
                                                    POLICY.tries))


class Lsm6ds3Driver(Driver):
    zero_rate = ZERO_RATE

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
        self.calibration = codec.Calibration()
        self.calibration_source: dict[str, str] | None = None  # the file applied, and its hash
        self._outputs = codec.Read(codec.OUT_TEMP_L, codec.BLOCK)

    @property
    def stats(self) -> dict[str, int]:
        bus = self.bus.stats if self.bus else {"packets": 0, "errors": 0}
        return {"packets": bus["packets"], "errors": bus["errors"], "reconnects": 0}

    def _read(self, register: int, count: int = 1) -> bytes:
        assert self.bus is not None
        return exchange(self.bus, self.address, codec.Read(register, count))

    def _register(self, register: int) -> int:
        return self._read(register)[0]

    def _write(self, register: int, value: int) -> None:
        assert self.bus is not None
        exchange(self.bus, self.address, codec.Write(register, bytes([value])))

    def configure(self) -> None:
        self.bus = registry.open_link(self.url, self.block.links)  # by its scheme
        who = self._register(codec.WHO_AM_I)
        try:
            self.chip = codec.chip_name(who)
        except ProtocolError as exc:
            raise DeviceError(f"{self.sensor.name} at {self.address:#04x} on {self.url}: "
                              f"{exc.message}", hint="check the address and the part") from None
        ctrl1, ctrl2 = self.settings
        self._write(codec.CTRL1_XL, ctrl1)
        self._write(codec.CTRL2_G, ctrl2)
        self._write(codec.CTRL4_C, self._register(codec.CTRL4_C) | codec.BW_SCAL_ODR)
        self._write(codec.ORIENT_CFG_G, 0)  # remap in software
        self._load_calibration()
        self.connected = True

    def _load_calibration(self) -> None:
        """The calibration file the sensor's ``calibration`` param names (beside the profile's
        file when relative): bounded, checked, refused with one message when wrong."""
        name = self.sensor.params.get("calibration")
        if not name:
            return
        from deltoctl.profile.yaml_loader import read_text

        path = Path(str(name))
        source = self.profile.source
        if not path.is_absolute() and source and Path(source).is_file():
            path = Path(source).parent / path
        text = read_text(path, "JSON", limit=64 * 1024, kind="calibration file")
        try:
            self.calibration = codec.Calibration.from_data(json.loads(text))
        except (ValueError, InvalidInput) as exc:
            why = exc.message if isinstance(exc, InvalidInput) else f"not JSON ({exc})"
            raise InvalidInput(f"{self.sensor.name}: calibration {path}: {why}") from None
        self.calibration_source = {"file": str(path),
                                   "sha256": hashlib.sha256(text.encode()).hexdigest()}

    def _sample(self) -> tuple[float, tuple, tuple]:
        """Temperature, angular velocity and acceleration, neither calibrated nor filtered."""
        assert self.bus is not None
        block = exchange(self.bus, self.address, self._outputs)
        return codec.decode(block, self.accel, self.gyro)

    def sample(self, calibrated: bool = True) -> tuple[tuple, tuple]:
        """One unfiltered reading (angular velocity, acceleration), calibrated or raw: what
        the IMU checks average."""
        _, gyro, accel = self._sample()
        return self.calibration.apply(gyro, accel) if calibrated else (gyro, accel)

    def read(self) -> dict[str, float]:
        assert self.bus is not None
        name = self.sensor.name
        try:
            temperature, gyro, accel = self._sample()
        except DeltoctlError:
            self.connected = False
            return self.values
        self.connected = True
        gyro, accel = self.calibration.apply(gyro, accel)
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
                 "match": bool(self.chip), "part": self.sensor.name,
                 "missing": not self.chip}
        return {"bus": self.url, "chip": self.chip, "checks": [check],
                "summary": f"{self.sensor.name}: {self.chip} at {self.address:#04x}"}

    def identify(self) -> dict:
        return {"bus": self.url, "address": f"{self.address:#04x}", "chip": self.chip,
                "output_rate_hz": self.odr, "accel_range_g": self.range_g,
                "gyro_range_dps": self.range_dps,
                "calibration": ({**self.calibration_source, "applied": True}
                                if self.calibration_source else {"applied": False})}

    @staticmethod
    def calibration_data(accel_bias: list[float], accel_scale: list[float],
                         gyro_bias: list[float]) -> dict[str, Any]:
        """What a calibration file holds (``calibrate imu --tumble`` adds its provenance)."""
        return {"kind": codec.CALIBRATION_KIND, **codec.Calibration(
            tuple(accel_bias), tuple(accel_scale), tuple(gyro_bias)).to_data()}

    # -- the built-in self-test ------------------------------------------------------------------
    def _average(self, register: int, ready: int) -> tuple[float, ...]:
        """The mean raw X/Y/Z of SELF_TEST_SAMPLES new samples, one discarded first."""
        total = [0.0, 0.0, 0.0]
        for i in range(codec.SELF_TEST_SAMPLES + 1):
            for _ in range(100):  # at 52 Hz a sample is ready within 20 ms
                if self._register(codec.STATUS_REG) & ready:
                    break
                time.sleep(0.002)
            else:
                raise DeviceError(f"{self.sensor.name}: no new sample during the self-test")
            xyz = codec.raw_axes(self._read(register, codec.RAW_AXES.size))
            if i:
                total = [t + v for t, v in zip(total, xyz)]
        return tuple(t / codec.SELF_TEST_SAMPLES for t in total)

    def _self_test_one(self, ctrl: int, setting: int, output: int, ready: int, on: int,
                       waits: tuple[float, float]) -> tuple[float, ...]:
        """|output change| per chip axis in LSB when the self-test bits ``on`` are set."""
        self._write(ctrl, setting)
        time.sleep(waits[0])
        off = self._average(output, ready)
        self._write(codec.CTRL5_C, on)
        time.sleep(waits[1])
        on_values = self._average(output, ready)
        self._write(codec.CTRL5_C, 0)
        return tuple(abs(a - b) for a, b in zip(on_values, off))

    def self_test(self) -> dict[str, Any]:
        """The datasheet's self-test of both sensors: each chip axis's output change against
        its range; the rates, ranges and CTRL5_C are restored whatever happens."""
        assert self.bus is not None
        saved = {r: self._register(r) for r in (codec.CTRL1_XL, codec.CTRL2_G, codec.CTRL5_C)}
        wait = codec.SELF_TEST_WAIT
        try:
            accel = self._self_test_one(
                codec.CTRL1_XL, codec.ctrl1_xl(*codec.SELF_TEST_ACCEL, bandwidth=400),
                codec.OUTX_L_XL, codec.XLDA, codec.ST_XL_POSITIVE, (wait["accel"],) * 2)
            gyro = self._self_test_one(
                codec.CTRL2_G, codec.ctrl2_g(*codec.SELF_TEST_GYRO), codec.OUTX_L_G,
                codec.GDA, codec.ST_G_POSITIVE, (wait["gyro"], wait["gyro_on"]))
        finally:
            for register, value in saved.items():
                self._write(register, value)
        mg = codec.accel_scale(codec.SELF_TEST_ACCEL[1]) / codec.G * 1000.0
        dps = codec.MDPS_PER_LSB_125 * codec.SELF_TEST_GYRO[1] / 125 / 1000.0
        return {"sensor": self.sensor.name, "chip": self.chip,
                "accel_mg": {a: round(v * mg, 2) for a, v in zip(AXES, accel)},
                "gyro_dps": {a: round(v * dps, 2) for a, v in zip(AXES, gyro)},
                "limits": {"accel_mg": codec.SELF_TEST_ACCEL_MG,
                           "gyro_dps": codec.SELF_TEST_GYRO_DPS},
                "unverified": [codec.UNVERIFIED[0]] if self.chip == "LSM6DS3" else []}

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
            self._write(register, value)
        return {self.sensor.name: {name: self._register(register)
                                   for register, name, _ in writes}} if writes else {}

    def cleanup(self) -> None:
        self.bus = None  # the System closes the shared bus
        self.connected = False
