"""The Protocol 1.0 servos by model number: AX-12A, AX-18A, RX-28, RX-64 (position 0-1023 over
300°) and MX-28, MX-64, MX-106 in their Protocol 1.0 firmware (0-4095 over 360°), their control
tables as data (ROBOTIS e-manual, emanual.robotis.com/docs/en/dxl/ax/ax-12a/ and siblings; each
model's page in ``MODELS_1``).

EEPROM items lie below address 24 and, unlike Protocol 2.0's, take writes with torque on.
Present Speed, Present Load and Moving Speed are sign-magnitude with the sign in bit 10 (a set
bit: clockwise).
What a page leaves open is in ``UNVERIFIED_1``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

from deltoctl.servo import items


@dataclass(frozen=True)
class Item1(items.Item):
    """A Protocol 1.0 item: little-endian; EEPROM below 24."""

    @property
    def eeprom(self) -> bool:
        return self.address < 24


TORQUE_ENABLE, GOAL_POSITION, MOVING_SPEED, PRESENT_POSITION = 24, 30, 32, 36
PRESENT = (36, 8)  # Present Position, Speed, Load, Voltage, Temperature in one read

_COMMON = (
    Item1(0, 2, "Model Number", "R"),
    Item1(2, 1, "Firmware Version", "R"),
    Item1(3, 1, "ID", default=1, low=0, high=253),
    Item1(4, 1, "Baud Rate", default=1, low=0, high=254),
    Item1(5, 1, "Return Delay Time", default=250, low=0, high=254),
    Item1(6, 2, "CW Angle Limit", low=0, high=1023, safety=True),
    Item1(8, 2, "CCW Angle Limit", default=1023, low=0, high=1023, safety=True),
    Item1(11, 1, "Temperature Limit", default=70, low=0, high=99, safety=True),
    Item1(12, 1, "Min Voltage Limit", default=60, low=50, high=250, safety=True),
    Item1(13, 1, "Max Voltage Limit", default=140, low=50, high=250, safety=True),
    Item1(14, 2, "Max Torque", default=1023, low=0, high=1023, safety=True),
    Item1(16, 1, "Status Return Level", default=2, low=0, high=2),
    Item1(17, 1, "Alarm LED", default=36, low=0, high=127),
    Item1(18, 1, "Shutdown", default=36, low=0, high=127, safety=True),
    Item1(24, 1, "Torque Enable", low=0, high=1),
    Item1(25, 1, "LED", low=0, high=1),
    Item1(30, 2, "Goal Position", default=512, low=0, high=1023),
    Item1(32, 2, "Moving Speed", low=-1023, high=1023, sign_bit=10),
    Item1(34, 2, "Torque Limit", default=1023, low=0, high=1023),
    Item1(36, 2, "Present Position", "R"),
    Item1(38, 2, "Present Speed", "R", sign_bit=10),
    Item1(40, 2, "Present Load", "R", sign_bit=10),
    Item1(42, 1, "Present Voltage", "R"),
    Item1(43, 1, "Present Temperature", "R"),
    Item1(44, 1, "Registered", "R"),
    Item1(46, 1, "Moving", "R"),
    Item1(47, 1, "Lock", low=0, high=1),
    Item1(48, 2, "Punch", default=32, low=0, high=1023),
)
_COMPLIANCE = (  # AX and RX: compliance instead of a PID
    Item1(26, 1, "CW Compliance Margin", default=1, low=0, high=255),
    Item1(27, 1, "CCW Compliance Margin", default=1, low=0, high=255),
    Item1(28, 1, "CW Compliance Slope", default=32, low=0, high=254),
    Item1(29, 1, "CCW Compliance Slope", default=32, low=0, high=254),
)
_MX = (  # MX: multi-turn, resolution, a PID, a clock, acceleration
    Item1(20, 2, "Multi Turn Offset", signed=True, low=-24576, high=24576, safety=True),
    Item1(22, 1, "Resolution Divider", default=1, low=1, high=4),
    Item1(26, 1, "D Gain", low=0, high=254),
    Item1(27, 1, "I Gain", low=0, high=254),
    Item1(28, 1, "P Gain", default=32, low=0, high=254),
    Item1(50, 2, "Realtime Tick", "R"),
    Item1(73, 1, "Goal Acceleration", low=0, high=254),
)
_MX_TORQUE = (  # MX-64 and MX-106: current sensing (4.5 mA a step from 2048) and torque control
    Item1(68, 2, "Current", "RW", low=0, high=4095),
    Item1(70, 1, "Torque Control Mode Enable", low=0, high=1),
    Item1(71, 2, "Goal Torque", low=-1023, high=1023, sign_bit=10),
)
_MX_RANGES = {"CW Angle Limit": 4095, "CCW Angle Limit": 4095, "Goal Position": 4095}


def _layout(*parts: tuple[Item1, ...], wide: bool = False,
            **defaults: int) -> tuple[Item1, ...]:
    """The items of ``parts``; ``wide``: positions of 0-4095; ``defaults`` by item key
    (max_voltage_limit=160)."""
    table = [i for part in parts for i in part]
    if wide:
        table = [replace(i, high=_MX_RANGES[i.name],
                         default=4095 if i.name == "CCW Angle Limit" else
                         2048 if i.name == "Goal Position" else i.default)
                 if i.name in _MX_RANGES else i for i in table]
    table = [replace(i, default=defaults[i.key.replace("-", "_")])
             if i.key.replace("-", "_") in defaults else i for i in table]
    return tuple(sorted(table, key=lambda i: i.address))


@dataclass(frozen=True)
class Model1:
    """One Protocol 1.0 model: its number, name, page, table and scales."""

    number: int
    name: str
    page: str  # its e-manual page
    layout: tuple[Item1, ...] = field(repr=False)
    resolution: int  # position steps over ``degrees``
    degrees: float
    rpm_per_unit: float  # Moving / Present Speed
    bulk_read: bool = False  # MX: BULK_READ
    protocol = 1.0
    current_unit = None  # no Present Current at 126: the effort is Present Load
    modes: frozenset[int] = frozenset()

    @property
    def table(self) -> tuple[Item1, ...]:
        return self.layout

    @cached_property
    def by_name(self) -> dict[str, Item1]:
        return {i.name: i for i in self.table}

    @property
    def table_size(self) -> int:
        return max(i.address + i.size for i in self.table)

    @property
    def center(self) -> int:
        """The step at the middle of the range (150° or 180°): a joint's zero."""
        return self.resolution // 2

    @property
    def rad_per_step(self) -> float:
        import math

        return math.radians(self.degrees) / self.resolution

    @property
    def rad_s_per_unit(self) -> float:
        import math

        return self.rpm_per_unit * 2 * math.pi / 60

    def units(self) -> dict[str, str]:
        step = f"{self.degrees / self.resolution:.3g}°"
        speed = f"{self.rpm_per_unit:g} rpm"
        return {"Return Delay Time": "2 µs", "CW Angle Limit": step, "CCW Angle Limit": step,
                "Temperature Limit": "°C", "Min Voltage Limit": "0.1 V",
                "Max Voltage Limit": "0.1 V", "Max Torque": "0.1 %", "Goal Position": step,
                "Moving Speed": speed, "Torque Limit": "0.1 %", "Present Position": step,
                "Present Speed": speed, "Present Load": "0.1 %", "Present Voltage": "0.1 V",
                "Present Temperature": "°C", "Goal Acceleration": "8.583°/s²",
                "Multi Turn Offset": step}

    def current_amps(self, raw: int) -> float:
        return 0.0


# the defaults that differ, as each page's table gives them (the Baud Rate's: 1 Mbps on the
# AX, 57600 bps on the RX and MX; the MX's Punch: 0)
_MX_DEFAULTS = dict(baud_rate=34, temperature_limit=80, punch=0)
AX_12 = _layout(_COMMON, _COMPLIANCE)
AX_18 = _layout(_COMMON, _COMPLIANCE, temperature_limit=75, max_torque=983, torque_limit=983)
RX = _layout(_COMMON, _COMPLIANCE, baud_rate=34, temperature_limit=80, max_voltage_limit=190)
MX_28 = _layout(_COMMON, _MX, wide=True, max_voltage_limit=160, **_MX_DEFAULTS)
MX_64 = _layout(_COMMON, _MX, _MX_TORQUE, wide=True, max_voltage_limit=240, **_MX_DEFAULTS)
MX_106 = _layout(_COMMON, _MX, _MX_TORQUE, (
    Item1(10, 1, "Drive Mode", low=0, high=3, safety=True),), wide=True,  # dual joint
    max_voltage_limit=160, **_MX_DEFAULTS)

# Each row's page is emanual.robotis.com/docs/en/dxl/<series>/<model>/ (its source in
# ROBOTIS-GIT/emanual: docs/en/dxl/<series>/<model>.md), whose control table the row follows.
_E = "emanual.robotis.com/docs/en/dxl"
MODELS_1: tuple[Model1, ...] = (
    Model1(12, "AX-12A", f"{_E}/ax/ax-12a/", AX_12, 1024, 300.0, 0.111),
    Model1(18, "AX-18A", f"{_E}/ax/ax-18a/", AX_18, 1024, 300.0, 0.111),
    Model1(28, "RX-28", f"{_E}/rx/rx-28/", RX, 1024, 300.0, 0.111),
    Model1(64, "RX-64", f"{_E}/rx/rx-64/", RX, 1024, 300.0, 0.111),
    Model1(29, "MX-28", f"{_E}/mx/mx-28/", MX_28, 4096, 360.0, 0.114, bulk_read=True),
    Model1(310, "MX-64", f"{_E}/mx/mx-64/", MX_64, 4096, 360.0, 0.114, bulk_read=True),
    Model1(320, "MX-106", f"{_E}/mx/mx-106/", MX_106, 4096, 360.0, 0.114, bulk_read=True),
)

# What the pages do not say, or say otherwise than the table keeps. Every page's table was
# read (addresses, sizes, access, initial values, the Baud Rate codes, the error bits, "no
# status to a broadcast ID whatever the Status Return Level", Goal Acceleration's 8.583°/s²).
# Correct a value, then remove it from here.
UNVERIFIED_1: dict[str, tuple[str, ...]] = {
    # the pages give no initial Goal Position or Moving Speed ("-"): the emulator starts at
    # the middle step at speed 0 (as fast as it can)
    "AX-12A": ("Goal Position default 512",),
    "AX-18A": ("Goal Position default 512",),
    "RX-28": ("Goal Position default 512", "Moving Speed unit 0.111 rpm (an include)"),
    "RX-64": ("Goal Position default 512", "Moving Speed unit 0.111 rpm (an include)"),
    # the MX pages' Current row says 0 initially and its text 2048 at idle: the table keeps 0
    "MX-28": ("Goal Position default 2048", "Multi Turn Offset range ±24576 (an include)"),
    "MX-64": ("Goal Position default 2048", "Current initial value (0 or 2048)"),
    "MX-106": ("Goal Position default 2048", "Current initial value (0 or 2048)",
               "Drive Mode range 0-3 (an include)"),
}

BY_NUMBER_1 = {m.number: m for m in MODELS_1}
AX_12A = BY_NUMBER_1[12]


def baud_of(code: int) -> int:
    """A Baud Rate (4) code's rate: 2 Mbps / (code + 1), MX's 250-252 2.25, 2.5, 3 Mbps."""
    return {250: 2_250_000, 251: 2_500_000, 252: 3_000_000}.get(code, round(2e6 / (code + 1)))


# the codes of the rates a host sets (a serial port's rate), as the e-manual's table pairs them
BAUD_CODES = {1_000_000: 1, 500_000: 3, 400_000: 4, 250_000: 7, 200_000: 9, 115_200: 16,
              57_600: 34, 19_200: 103, 9_600: 207, 2_250_000: 250, 2_500_000: 251,
              3_000_000: 252}
