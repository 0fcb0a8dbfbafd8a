"""The Dynamixel X series by model number: each model's control table, units, limits and
operating modes, as data (ROBOTIS e-manual, emanual.robotis.com/docs/en/dxl/x/<model>/).

Models that share an address layout share one table; a model's entry adds what differs (its
current unit, the default and maximum of its limits, its voltage range, its modes, the defaults
of its control loops' gains: a row of ``GAINS``, one per distinct set). Every X
model keeps Present Current or Load, Velocity and Position at 126/128/132 and Present Input
Voltage and Temperature at 144/146, so one Sync Read serves a bus of mixed models; the meaning
of 126 (load or current, and the current's unit) is the servo's own.

Model numbers: the "Model Number" row of each e-manual page (reference:
dynamixel-x-series-and-cia402.md). Facts not checked against a page are listed in
``UNVERIFIED`` (one place to correct them).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import TYPE_CHECKING, Any

from deltoctl.families.dynamixel.control_table import XL430, Item

if TYPE_CHECKING:
    from deltoctl.families.dynamixel.models1 import Model1

# -- the layouts ----------------------------------------------------------------------------------

_CURRENT = (  # the items of a model with a current sensor
    Item(38, 2, "Current Limit", safety=True),
    Item(102, 2, "Goal Current", signed=True),
    Item(126, 2, "Present Current", "R", signed=True),
)
_EXTERNAL_PORTS = tuple(Item(56 + k, 1, f"External Port Mode {k + 1}", default=3, low=0,
                             high=3) for k in range(3)) + tuple(
    Item(152 + 2 * k, 2, f"External Port Data {k + 1}") for k in range(3))


def _layout(*, drop: tuple[str, ...] = (), add: tuple[Item, ...] = ()) -> tuple[Item, ...]:
    items = [i for i in XL430 if i.name not in drop] + list(add)
    return tuple(sorted(items, key=lambda i: i.address))


# XL430-W250, 2XL430-W250, XC430-W150/W240: no current sensor, Present Load at 126
# (docs/en/dxl/x/xl430-w250.md)
X430_LOAD = XL430
# XM430, XH430, XD430: Current Limit 38, Goal Current 102, Present Current 126
# (docs/en/dxl/x/xm430-w350.md, xh430-v350.md, xd430-t350.md)
X430_CURRENT = _layout(drop=("Present Load",), add=_CURRENT)
# XM540, XH540, XD540: the 430's, plus three external ports (56-58, 152-157)
# (docs/en/dxl/x/xm540-w270.md, xh540-w270.md, xd540-t270.md)
X540 = _layout(drop=("Present Load",), add=_CURRENT + _EXTERNAL_PORTS)
# XW430, XW540 (waterproof): the 430's without the LED (docs/en/dxl/x/xw540-t260.md,
# xw430-t200.md)
XW = _layout(drop=("Present Load", "LED"), add=_CURRENT)
# XL330, XC330: the 430's, plus PWM Slope 62 (docs/en/dxl/x/xl330-m288.md, xc330-t288.md)
_PWM_SLOPE = Item(62, 1, "PWM Slope", default=140, low=1, high=255)
X330 = _layout(drop=("Present Load",), add=(*_CURRENT, _PWM_SLOPE))

LAYOUTS = {"X430 without current": X430_LOAD, "X430": X430_CURRENT, "X540": X540, "XW": XW,
           "X330": X330}

# Operating Mode (11) values, and which a model runs
CURRENT, VELOCITY, POSITION, EXTENDED, CURRENT_POSITION, PWM = 0, 1, 3, 4, 5, 16
MODE_NAMES = {CURRENT: "current", VELOCITY: "velocity", POSITION: "position",
              EXTENDED: "extended position", CURRENT_POSITION: "current-based position",
              PWM: "PWM"}
NO_CURRENT_MODES = frozenset({VELOCITY, POSITION, EXTENDED, PWM})
ALL_MODES = frozenset(MODE_NAMES)


@dataclass(frozen=True)
class Model:
    """One model: its number, name, table and what differs from the table's defaults."""

    number: int
    name: str
    layout: str  # a key of LAYOUTS
    current_unit: float | None = None  # mA per step of Present/Goal Current; None: no sensor
    current_limit: int | None = None  # Current Limit (38): its default, also its maximum
    velocity_limit: int = 265  # Velocity Limit (44) default, 0.229 rpm
    velocity_max: int = 1023  # ... and its maximum
    voltage: tuple[int, int, int, int] = (140, 60, 60, 140)  # max, min default; range (0.1 V)
    temperature_limit: int = 80  # °C, default
    baud_codes: int = 7  # the highest Baud Rate (8) code: 7 = 4.5 Mbps, 6 = 4 Mbps
    gains: str = "XL430-W250"  # a key of GAINS: the control loops' defaults
    overrides: dict[str, int] = field(default_factory=dict)  # other defaults by item name

    @property
    def modes(self) -> frozenset[int]:
        return NO_CURRENT_MODES if self.current_unit is None else ALL_MODES

    @cached_property
    def table(self) -> tuple[Item, ...]:
        """The layout with this model's number, defaults and ranges."""
        vmax, vmin, vlow, vhigh = self.voltage
        changes: dict[str, dict[str, int | None]] = {
            "Model Number": {"default": self.number},
            "Baud Rate": {"high": self.baud_codes},
            "Operating Mode": {"high": max(self.modes)},
            "Temperature Limit": {"default": self.temperature_limit},
            "Max Voltage Limit": {"default": vmax, "low": vlow, "high": vhigh},
            "Min Voltage Limit": {"default": vmin, "low": vlow, "high": vhigh},
            "Velocity Limit": {"default": self.velocity_limit, "high": self.velocity_max},
            "Current Limit": {"default": self.current_limit, "low": 0,
                              "high": self.current_limit},
        }
        for name, value in zip(GAIN_ITEMS, GAINS[self.gains]):
            changes.setdefault(name, {})["default"] = value
        for name, value in self.overrides.items():
            changes.setdefault(name, {})["default"] = value
        return tuple(replace(i, **changes[i.name]) if i.name in changes else i
                     for i in LAYOUTS[self.layout])

    @cached_property
    def by_name(self) -> dict[str, Item]:
        return {i.name: i for i in self.table}

    @property
    def table_size(self) -> int:
        """Bytes from address 0 to the end of the last item (one READ gets the whole table)."""
        return max(i.address + i.size for i in self.table)

    def units(self) -> dict[str, str]:
        """The unit of one raw step of each item that has one."""
        from deltoctl.families.dynamixel.control_table import UNITS

        units = dict(UNITS)
        if self.current_unit is not None:
            unit = f"{self.current_unit:g} mA"
            units.update({"Current Limit": unit, "Goal Current": unit, "Present Current": unit})
        return units

    def current_amps(self, raw: int) -> float:
        """Present Current in A (raw steps × the model's unit)."""
        return raw * (self.current_unit or 0.0) / 1000.0


# The control loops' defaults (RAM, restored at each reboot): Velocity I and P, Position D, I
# and P Gain, one row per distinct set of the pages, named after the first; both Feedforward
# Gains are 0 on every page.
GAIN_ITEMS = ("Velocity I Gain", "Velocity P Gain", "Position D Gain", "Position I Gain",
              "Position P Gain")
GAINS: dict[str, tuple[int, int, int, int, int]] = {
    "XL430-W250": (1000, 100, 4000, 0, 640),  # xl430-w250.md (the layout's own)
    "2XL430-W250": (1800, 100, 2000, 0, 640),  # 2xl430-w250.md
    "XC430-W150": (1920, 100, 0, 0, 460),  # xc430-w150.md
    "XC430-W240": (1920, 100, 0, 0, 700),  # xc430-w240.md
    # xm430-w350/-w210, xh430-v350/-v210, xm540-w270/-w150, xh540-w270/-w150/-v270/-v150,
    # xd540-t270/-t150, xw540-t260/-t140/-h260.md
    "XM430-W350": (1920, 100, 0, 0, 800),
    # xh430-w350/-w210, xd430-t350/-t210, xw430-t200/-t333.md
    "XH430-W350": (1920, 100, 0, 0, 900),
    "XL330-M288": (1600, 180, 0, 0, 400),  # xl330-m288.md
    "XL330-M077": (400, 40, 0, 400, 400),  # xl330-m077.md
    "XC330-T288": (1200, 40, 0, 0, 900),  # xc330-t288.md, xc330-t181.md
    "XC330-M288": (1600, 50, 500, 0, 1100),  # xc330-m288.md
    "XC330-M181": (1400, 100, 500, 0, 1200),  # xc330-m181.md
}

_X430 = dict(voltage=(160, 95, 95, 160), gains="XM430-W350")
_XH_W = dict(voltage=(160, 95, 95, 160), gains="XH430-W350")
_XH_V = dict(voltage=(300, 110, 110, 300), gains="XM430-W350")
_XC430 = dict(voltage=(160, 60, 60, 160), temperature_limit=80)
_XL330 = dict(layout="X330", current_unit=1.0, current_limit=1750, velocity_max=2047,
              voltage=(70, 35, 31, 70), temperature_limit=70, baud_codes=6,
              overrides={"Shutdown": 53})
_XC330_T = dict(layout="X330", current_unit=1.0, current_limit=910, velocity_max=2047,
                voltage=(140, 55, 55, 140), temperature_limit=70, baud_codes=6,
                gains="XC330-T288", overrides={"PWM Slope": 255})
_XC330_M = dict(layout="X330", current_unit=1.0, current_limit=2352, velocity_max=2047,
                voltage=(70, 35, 31, 70), temperature_limit=70, baud_codes=6)

# Each row's page is docs/en/dxl/x/<model>.md (lower case), e.g. docs/en/dxl/x/xm430-w350.md.
MODELS: tuple[Model, ...] = (
    Model(1060, "XL430-W250", "X430 without current", temperature_limit=72),
    Model(1090, "2XL430-W250", "X430 without current", velocity_limit=250,
          temperature_limit=72, gains="2XL430-W250"),
    Model(1070, "XC430-W150", "X430 without current", velocity_limit=460, gains="XC430-W150",
          overrides={"Moving Threshold": 20}, **_XC430),
    Model(1080, "XC430-W240", "X430 without current", velocity_limit=306, gains="XC430-W240",
          **_XC430),
    Model(1020, "XM430-W350", "X430", 2.69, 1193, velocity_limit=200, **_X430),
    Model(1030, "XM430-W210", "X430", 2.69, 1193, velocity_limit=330, **_X430),
    Model(1000, "XH430-W350", "X430", 2.69, 648, velocity_limit=130, **_XH_W),
    Model(1010, "XH430-W210", "X430", 2.69, 648, velocity_limit=210, **_XH_W),
    Model(1040, "XH430-V350", "X430", 1.34, 689, velocity_limit=135, **_XH_V),
    Model(1050, "XH430-V210", "X430", 1.34, 689, velocity_limit=230, **_XH_V),
    # the XD's tables are the XH's (its pages say so)
    Model(1001, "XD430-T350", "X430", 2.69, 648, velocity_limit=130, **_XH_W),
    Model(1011, "XD430-T210", "X430", 2.69, 648, velocity_limit=210, **_XH_W),
    Model(1280, "XW430-T200", "XW", 2.69, 2047, velocity_limit=235, **_XH_W),
    Model(1270, "XW430-T333", "XW", 2.69, 2047, velocity_limit=139, **_XH_W),
    Model(1120, "XM540-W270", "X540", 2.69, 2047, velocity_limit=128, **_X430),
    Model(1130, "XM540-W150", "X540", 2.69, 2047, velocity_limit=230, **_X430),
    Model(1100, "XH540-W270", "X540", 2.69, 2047, velocity_limit=167, **_X430),
    Model(1110, "XH540-W150", "X540", 2.69, 2047, velocity_limit=300, **_X430),
    Model(1140, "XH540-V270", "X540", 2.69, 2047, velocity_limit=128, **_XH_V),
    Model(1150, "XH540-V150", "X540", 2.69, 1188, velocity_limit=230, **_XH_V),
    Model(1101, "XD540-T270", "X540", 2.69, 2047, velocity_limit=167, **_X430),
    Model(1111, "XD540-T150", "X540", 2.69, 2047, velocity_limit=300, **_X430),
    Model(1170, "XW540-T260", "XW", 2.69, 2047, velocity_limit=167, **_X430),
    Model(1180, "XW540-T140", "XW", 2.69, 2047, velocity_limit=304, **_X430),
    Model(1310, "XW540-H260", "XW", 2.69, 1188, velocity_limit=145, **_XH_V),
    Model(1200, "XL330-M288", velocity_limit=445, gains="XL330-M288", **_XL330),
    Model(1190, "XL330-M077", velocity_limit=1620, gains="XL330-M077", **_XL330),
    Model(1220, "XC330-T288", velocity_limit=320, **_XC330_T),
    Model(1210, "XC330-T181", velocity_limit=510, **_XC330_T),
    Model(1240, "XC330-M288", velocity_limit=350, gains="XC330-M288", **_XC330_M),
    Model(1230, "XC330-M181", velocity_limit=545, gains="XC330-M181", **_XC330_M),
)

# What was not checked against the model's own e-manual page (the layouts of all of them were
# checked against ROBOTIS' dynamixel_hardware_interface model files). Correct a value, then
# remove it from here. Every page gives the same Return Delay Time (250), Drive Mode (0),
# Operating Mode (3), Moving Threshold (10, but 20 on the XC430-W150), PWM Limit (885),
# position limits (0-4095), Shutdown (52, but 53 on the XL330s), Bus Watchdog and profile
# (0). The pages disagree with themselves in three places, where the table keeps its value:
# the XD430-T350 and XD540-T270 pages' Model Number rows repeat the XH's (1000, 1100), and the
# XW430 pages give Protocol Type 1 (the emulator speaks Protocol 2.0 only).
UNVERIFIED: dict[str, tuple[str, ...]] = {
    # the pages read were an older edition, whose Velocity Limits (350, 360, 285, 380) the
    # newer editions of their siblings lowered (the XD430-T210's, the XH430-W210's table,
    # gives 210)
    "XM430-W350": ("velocity_limit",),
    "XH430-W210": ("velocity_limit",),
    "XH430-V350": ("velocity_limit",),
    "XH430-V210": ("velocity_limit",),
}

def _protocol_1() -> tuple[Model1, ...]:
    from deltoctl.families.dynamixel.models1 import MODELS_1

    return MODELS_1


ALL_MODELS: tuple[Model | Model1, ...] = MODELS + _protocol_1()  # both protocols'
BY_NUMBER: dict[int, Model | Model1] = {m.number: m for m in ALL_MODELS}
BY_KEY = {m.name.lower(): m for m in ALL_MODELS}
XL430_W250 = next(m for m in MODELS if m.number == 1060)


def by_number(number: int) -> Model | Model1 | None:
    return BY_NUMBER.get(number)


def by_name(text: str) -> Model | Model1 | None:
    """A model by name as profiles write it: XM430-W350, xm430_w350, XM430-W350-R (the
    interface suffix -T/-R is ignored), or its number."""
    key = text.strip().lower().replace("_", "-")
    if key.isdigit():
        return BY_NUMBER.get(int(key))
    model = BY_KEY.get(key)
    if model is None and key[-2:] in ("-t", "-r"):
        model = BY_KEY.get(key[:-2])
    return model


def label(number: int) -> str:
    """A model number for people: "XM430-W350 (1020)", or "unknown model 30"."""
    model = BY_NUMBER.get(number)
    return f"{model.name} ({number})" if model else f"unknown model {number}"


def expected_model(block: Mapping[str, str], joint: Mapping[str, str], name: str) -> int | None:
    """The model number a profile expects of a joint's servo: its ``model_number`` or
    ``motor_type`` param (1020, XM430-W350), else its block's; None when it names none."""
    from deltoctl.errors import InvalidInput

    for params in (joint, block):
        for key in ("model_number", "motor_type"):
            text = str(params.get(key, "")).strip()
            if not text:
                continue
            model = by_name(text)
            if model is not None:
                return model.number
            if text.isdigit() and int(text) < 1 << 16:
                return int(text)  # a model deltoctl has no table for: compared as it is
            raise InvalidInput(f"{name}: {key} {text!r} is not a Dynamixel model deltoctl "
                               "knows (e.g. XM430-W350, AX-12A or 1020)")
    return None


def config_rules() -> dict[str, tuple[int | None, int | None, str | None]]:
    """For `config restore`: each item's documented range over every model (the driver
    checks each servo's own model's before writing), and the --allow that a safety setting
    needs to be written (None for the others)."""
    rules: dict[str, tuple[int | None, int | None, str | None]] = {}
    for model in ALL_MODELS:
        for i in model.table:
            low, high, _ = rules.get(i.name, (i.low, i.high, None))
            rules[i.name] = (_widest(low, i.low, min), _widest(high, i.high, max),
                             i.key if i.safety else None)
    return rules


def _widest(a: int | None, b: int | None, pick: Any) -> int | None:
    return None if a is None or b is None else pick(a, b)


def item_names() -> list[str]:
    """Item names as the register verbs take them (return_delay_time), of every model."""
    names = dict.fromkeys(i.name.lower().replace(" ", "_") for m in ALL_MODELS for i in m.table)
    return list(names)
