"""The Feetech models by model number, their control tables, units and encodings, as data.

One table per layout — STS/SMS (STS3215, STS3250, SM8512BL: little-endian) and SCS (SCS0009:
big-endian) — and each model referencing its own. EEPROM is addresses 0–39; it keeps a write
only while Lock (55 on STS, 48 on SCS) is 0. Negative values are sign-magnitude: bit 15 for
positions and speeds, 11 for Homing_Offset, 10 for load (§1.4). Names as LeRobot's tables
spell them (so a LeRobot user finds them). Reference: feetech-sts-and-lerobot.md §2.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

from deltoctl.servo import items


@dataclass(frozen=True)
class Item(items.Item):
    """A Feetech item (the kit's: sign-magnitude where it has a sign bit)."""

    @property
    def eeprom(self) -> bool:
        return self.address < 40

    @property
    def key(self) -> str:
        """The name --allow takes, as config restore spells it: homing-offset."""
        return self.name.lower().replace("_", "-")


def _sts() -> tuple[Item, ...]:
    step, speed = "0.088°", "0.088°/s"
    return (
        Item(0, 1, "Firmware_Major_Version", "R", 3),
        Item(1, 1, "Firmware_Minor_Version", "R", 10),
        Item(2, 1, "END", "R"),  # 0: little-endian
        Item(3, 2, "Model_Number", "R"),
        Item(5, 1, "ID", default=1, low=0, high=253),
        Item(6, 1, "Baud_Rate", low=0, high=7),
        Item(7, 1, "Return_Delay_Time", default=250, low=0, high=254, unit="2 µs"),
        Item(8, 1, "Response_Status_Level", default=1, low=0, high=1),
        Item(9, 2, "Min_Position_Limit", low=0, high=4094, safety=True, unit=step),
        Item(11, 2, "Max_Position_Limit", default=4095, low=1, high=4095, safety=True,
             unit=step),
        Item(13, 1, "Max_Temperature_Limit", default=70, low=0, high=100, safety=True,
             unit="°C"),
        Item(14, 1, "Max_Voltage_Limit", default=140, safety=True, unit="0.1 V"),
        Item(15, 1, "Min_Voltage_Limit", default=50, safety=True, unit="0.1 V"),
        Item(16, 2, "Max_Torque_Limit", default=1000, low=0, high=1000, safety=True,
             unit="0.1 %"),
        Item(18, 1, "Phase", default=0x0C, safety=True),  # bit 4: full-angle feedback
        Item(19, 1, "Unloading_Condition", default=0x2C, safety=True),
        Item(20, 1, "LED_Alarm_Condition", default=0x2F),
        Item(21, 1, "P_Coefficient", default=32),
        Item(22, 1, "D_Coefficient", default=32),
        Item(23, 1, "I_Coefficient"),
        Item(24, 2, "Minimum_Startup_Force", default=16),
        Item(26, 1, "CW_Dead_Zone", default=1),
        Item(27, 1, "CCW_Dead_Zone", default=1),
        Item(28, 2, "Protection_Current", default=500, safety=True, unit="6.5 mA"),
        Item(30, 1, "Angular_Resolution", default=1),
        Item(31, 2, "Homing_Offset", sign_bit=11, safety=True, unit=step),
        Item(33, 1, "Operating_Mode", low=0, high=3, safety=True),
        Item(34, 1, "Protective_Torque", default=20, unit="%"),
        Item(35, 1, "Protection_Time", default=200, unit="10 ms"),
        Item(36, 1, "Overload_Torque", default=80, safety=True, unit="%"),
        Item(37, 1, "Velocity_closed_loop_P_proportional_coefficient", default=10),
        Item(38, 1, "Over_Current_Protection_Time", default=200, unit="10 ms"),
        Item(39, 1, "Velocity_closed_loop_I_integral_coefficient", default=200),
        Item(40, 1, "Torque_Enable", low=0, high=1),
        Item(41, 1, "Acceleration", low=0, high=254, unit="100 steps/s²"),
        Item(42, 2, "Goal_Position", sign_bit=15, unit=step),
        Item(44, 2, "Goal_Time", unit="ms"),
        Item(46, 2, "Goal_Velocity", sign_bit=15, unit=speed),
        Item(48, 2, "Torque_Limit", default=1000, low=0, high=1000, unit="0.1 %"),
        Item(55, 1, "Lock", default=1, low=0, high=1),
        Item(56, 2, "Present_Position", "R", sign_bit=15, unit=step),
        Item(58, 2, "Present_Velocity", "R", sign_bit=15, unit=speed),
        Item(60, 2, "Present_Load", "R", sign_bit=10, unit="0.1 %"),
        Item(62, 1, "Present_Voltage", "R", unit="0.1 V"),
        Item(63, 1, "Present_Temperature", "R", unit="°C"),
        Item(64, 1, "Status_Async_Write", "R"),
        Item(65, 1, "Status", "R"),
        Item(66, 1, "Moving", "R"),
        Item(69, 2, "Present_Current", "R", sign_bit=15, unit="6.5 mA"),
        Item(71, 2, "Goal_Position_2", "R"),
        Item(80, 1, "Moving_Velocity_Threshold"),
        Item(81, 1, "DTs", default=20, unit="ms"),
        Item(82, 1, "Velocity_Unit_factor", default=50),
        Item(83, 1, "Hts", default=1, unit="ns"),
        Item(84, 1, "Maximum_Velocity_Limit", default=65),
        Item(85, 1, "Maximum_Acceleration", default=254),
        Item(86, 1, "Acceleration_Multiplier"),
    )


def _scs() -> tuple[Item, ...]:
    """The SCS layout: 0–27 and 40–66 as the STS's (big-endian, 1024 steps a turn), Lock at
    48, no Homing_Offset nor Operating_Mode, Running_Time at 44 (§2.3). Only the speed keeps
    a sign (bit 15, as Feetech's SDK decodes it); LeRobot reads none."""
    step = "0.29°"
    scs = []
    for i in _sts():
        if 28 <= i.address < 40 or i.address in (44, 48, 55, 69, 71) or i.address >= 67 \
                or i.name == "END":
            continue
        sign = 15 if i.name in ("Goal_Velocity", "Present_Velocity") else None
        unit = step if i.unit == "0.088°" else i.unit
        high = {"Min_Position_Limit": 1022, "Max_Position_Limit": 1023}.get(i.name, i.high)
        default = {"Max_Position_Limit": 1023, "Firmware_Minor_Version": 0}.get(i.name,
                                                                              i.default)
        scs.append(replace(i, big_endian=True, sign_bit=sign, unit=unit, high=high,
                           default=default))
    scs += [Item(37, 1, "Protective_Torque", default=20, unit="%", big_endian=True),
            Item(38, 1, "Protection_Time", default=200, unit="10 ms", big_endian=True),
            Item(44, 2, "Running_Time", unit="ms", big_endian=True),
            Item(48, 1, "Lock", default=1, low=0, high=1, big_endian=True)]
    return tuple(sorted(scs, key=lambda i: i.address))


STS = _sts()
SCS = _scs()
LAYOUTS = {"STS/SMS": STS, "SCS": SCS}

OPERATING_MODES = {0: "position", 1: "constant speed", 2: "PWM (open loop)", 3: "step"}
# Baud_Rate codes, one row each: (code, the rate Feetech's SDK, C++ library and manuals give,
# LeRobot's where it differs — None: it agrees). LeRobot's 5-7 disagree with every Feetech
# source and with the servos; deltoctl follows Feetech's (§1.6)
BAUD_CODES = ((0, 1_000_000, None), (1, 500_000, None), (2, 250_000, None),
              (3, 128_000, None), (4, 115_200, None), (5, 76_800, 57_600),
              (6, 57_600, 38_400), (7, 38_400, 19_200))
BAUD_RATES = {code: rate for code, rate, _ in BAUD_CODES}
LEROBOT_BAUD_RATES = {code: lerobot or rate for code, rate, lerobot in BAUD_CODES}
# what a servo does or is commanded to do: kept in a snapshot, never compared or restored
READINGS = frozenset({
    "Torque_Enable", "Goal_Position", "Goal_Time", "Running_Time", "Goal_Velocity", "Lock",
    "Present_Position", "Present_Velocity", "Present_Load", "Present_Voltage",
    "Present_Temperature", "Status_Async_Write", "Status", "Moving", "Present_Current",
    "Goal_Position_2"})
BUS_ITEMS = frozenset({"ID", "Baud_Rate", "Response_Status_Level"})  # `register set` only


@dataclass(frozen=True)
class Model:
    number: int
    name: str
    layout: str  # LAYOUTS' key
    resolution: int  # steps a turn
    lock: int  # the Lock item's address
    stall_torque: float  # N·m at its rated supply (effort = load × this)
    notes: str = ""
    defaults: dict[str, int] = field(default_factory=dict)  # where it differs from its layout

    @property
    def big_endian(self) -> bool:
        return self.layout == "SCS"

    @property
    def sync_read(self) -> bool:
        """Whether it answers a SYNC READ: the SCS series does not (Feetech's SDK has no sync
        read for it, and LeRobot refuses one on an SCS bus)."""
        return self.layout != "SCS"

    @cached_property
    def table(self) -> tuple[Item, ...]:
        rows = []
        for i in LAYOUTS[self.layout]:
            default = self.defaults.get(i.name, self.number if i.name == "Model_Number"
                                        else i.default)
            rows.append(replace(i, default=default))
        return tuple(rows)

    @cached_property
    def by_name(self) -> dict[str, Item]:
        return {i.name: i for i in self.table}

    @cached_property
    def table_size(self) -> int:
        last = self.table[-1]
        return last.address + last.size

    def model_bytes(self) -> bytes:
        """Model_Number as the servo holds it (addresses 3, 4)."""
        return self.by_name["Model_Number"].encode(self.number)


MODELS = (
    Model(777, "STS3215", "STS/SMS", 4096, 55, 2.942,
          "the SO-100/SO-101's servo (12 V: 30 kg·cm; 7.4 V: 16.5 kg·cm)",
          {"Phase": 0x1C}),
    Model(2825, "STS3250", "STS/SMS", 4096, 55, 4.9),
    Model(11272, "SM8512BL", "STS/SMS", 4096, 55, 11.8),
    Model(1284, "SCS0009", "SCS", 1024, 48, 0.23),
)
BY_NUMBER = {m.number: m for m in MODELS}
BY_KEY = {m.name.lower(): m for m in MODELS}
# (address 3, address 4) as the servo sends them → its model: the byte order is the model's
BY_BYTES = {m.model_bytes(): m for m in MODELS}


def by_number(number: int) -> Model | None:
    return BY_NUMBER.get(number)


def by_bytes(data: bytes) -> Model | None:
    return BY_BYTES.get(bytes(data))


def label(number: int | None) -> str:
    model = BY_NUMBER.get(number) if number is not None else None
    return model.name if model else f"model number {number}"


def expected_model(block: dict[str, str], joint: dict[str, str], name: str) -> int | None:
    """The model the profile names for a joint's servo: its ``model`` (STS3215, as LeRobot's
    ``sts3215``) or ``model_number`` param, the joint's over the block's; None when none."""
    from deltoctl.errors import ProfileError

    for params in (joint, block):
        text = params.get("model") or params.get("motor_type")
        if text:
            model = BY_KEY.get(text.strip().lower())
            if model is None:
                known = ", ".join(m.name for m in MODELS)
                raise ProfileError(f"{name}: model {text!r} is not a Feetech model deltoctl "
                                   f"knows ({known})")
            return model.number
        if params.get("model_number", "").strip().isdigit():
            return int(params["model_number"])
    return None


def item_named(name: str, model: Model) -> Item:
    """An item by name (any case; LeRobot's names, or with spaces or -) or by address."""
    from deltoctl.errors import InvalidInput
    from deltoctl.suggest import did_you_mean

    key = name.lower().replace(" ", "_").replace("-", "_")
    for item in model.table:
        if item.name.lower() == key or (name.isdigit() and item.address == int(name)):
            return item
    close = did_you_mean(name, (i.name.lower() for i in model.table))
    raise InvalidInput(f"no control table item {name!r} in the {model.name}'s table{close}: "
                       "give a name such as present_temperature or homing_offset, or an "
                       "address")


def item_names() -> list[str]:
    """Item names as the register verbs take them (present_position), of every model."""
    return list(dict.fromkeys(i.name.lower() for m in MODELS for i in m.table))


def config_rules() -> dict[str, tuple[int | None, int | None, str | None]]:
    """For `config restore`: each item's documented range over every model (the driver
    checks each servo's own before writing) and the --allow a safety setting needs."""
    rules: dict[str, tuple[int | None, int | None, str | None]] = {}
    for model in MODELS:
        for i in model.table:
            low, high = i.low, i.high
            if i.name in rules:
                old_low, old_high, _ = rules[i.name]
                low = None if low is None or old_low is None else min(low, old_low)
                high = None if high is None or old_high is None else max(high, old_high)
            rules[i.name] = (low, high, i.key if i.safety else None)
    return rules
