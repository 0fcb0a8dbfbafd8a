"""The X-series control table as data, the XL430-W250's (ROBOTIS e-manual; reference §3.3);
the other models' tables derive from it (models.py).

One row per item: address, size in bytes, name, access (R or RW), default, sign, the range the
e-manual documents (docs/en/dxl/x/xl430-w250.md) and whether it is a safety setting. EEPROM
items (addresses below 64) are writable only while Torque Enable is 0.
"""

from __future__ import annotations

from dataclasses import dataclass

from deltoctl.servo import items


@dataclass(frozen=True)
class Item(items.Item):
    """An X-series item (the kit's, little-endian, two's complement where signed)."""

    @property
    def eeprom(self) -> bool:
        return self.address < 64


XL430_W250 = 1060

XL430: tuple[Item, ...] = (
    Item(0, 2, "Model Number", "R", XL430_W250),
    Item(2, 4, "Model Information", "R"),
    Item(6, 1, "Firmware Version", "R", 46),
    Item(7, 1, "ID", default=1, low=0, high=252),
    Item(8, 1, "Baud Rate", default=1, low=0, high=7),
    Item(9, 1, "Return Delay Time", default=250, low=0, high=254),
    Item(10, 1, "Drive Mode", low=0, high=13, safety=True),
    Item(11, 1, "Operating Mode", default=3, low=0, high=16, safety=True),
    Item(12, 1, "Secondary ID", default=255, low=0, high=255),  # 253 and above: none
    Item(13, 1, "Protocol Type", default=2, low=1, high=2),
    Item(20, 4, "Homing Offset", signed=True, low=-1_044_479, high=1_044_479, safety=True),
    Item(24, 4, "Moving Threshold", default=10, low=0, high=1023),
    Item(31, 1, "Temperature Limit", default=72, low=0, high=100, safety=True),
    Item(32, 2, "Max Voltage Limit", default=140, low=60, high=140, safety=True),
    Item(34, 2, "Min Voltage Limit", default=60, low=60, high=140, safety=True),
    Item(36, 2, "PWM Limit", default=885, low=0, high=885, safety=True),
    Item(44, 4, "Velocity Limit", default=265, low=0, high=1023, safety=True),
    Item(48, 4, "Max Position Limit", default=4095, low=0, high=4095, safety=True),
    Item(52, 4, "Min Position Limit", low=0, high=4095, safety=True),
    Item(60, 1, "Startup Configuration", low=0, high=3, safety=True),  # bit 0: torque on
    Item(63, 1, "Shutdown", default=52, low=0, high=63, safety=True),  # bits 0-5
    Item(64, 1, "Torque Enable", low=0, high=1),
    Item(65, 1, "LED", low=0, high=1),
    Item(68, 1, "Status Return Level", default=2, low=0, high=2),
    Item(69, 1, "Registered Instruction", "R"),
    Item(70, 1, "Hardware Error Status", "R"),
    Item(76, 2, "Velocity I Gain", default=1000, low=0, high=16383),
    Item(78, 2, "Velocity P Gain", default=100, low=0, high=16383),
    Item(80, 2, "Position D Gain", default=4000, low=0, high=16383),
    Item(82, 2, "Position I Gain", low=0, high=16383),
    Item(84, 2, "Position P Gain", default=640, low=0, high=16383),
    Item(88, 2, "Feedforward 2nd Gain", low=0, high=16383),
    Item(90, 2, "Feedforward 1st Gain", low=0, high=16383),
    Item(98, 1, "Bus Watchdog", low=0, high=127, safety=True),  # 0: off; 255 (-1): tripped
    Item(100, 2, "Goal PWM", signed=True),
    Item(104, 4, "Goal Velocity", signed=True),
    Item(108, 4, "Profile Acceleration", low=0, high=32767),
    Item(112, 4, "Profile Velocity", low=0, high=32767),
    Item(116, 4, "Goal Position", signed=True),
    Item(120, 2, "Realtime Tick", "R"),
    Item(122, 1, "Moving", "R"),
    Item(123, 1, "Moving Status", "R"),
    Item(124, 2, "Present PWM", "R", signed=True),
    Item(126, 2, "Present Load", "R", signed=True),
    Item(128, 4, "Present Velocity", "R", signed=True),
    Item(132, 4, "Present Position", "R", signed=True),
    Item(136, 4, "Velocity Trajectory", "R", signed=True),
    Item(140, 4, "Position Trajectory", "R", signed=True),
    Item(144, 2, "Present Input Voltage", "R"),
    Item(146, 1, "Present Temperature", "R"),
    Item(147, 1, "Backup Ready", "R"),
)

BY_NAME = {item.name: item for item in XL430}
TABLE_SIZE = 148
BAUD_RATES = {0: 9600, 1: 57600, 2: 115200, 3: 1_000_000, 4: 2_000_000, 5: 3_000_000,
              6: 4_000_000, 7: 4_500_000}


def item_at(address: int, table: tuple[Item, ...] = XL430) -> Item | None:
    return items.item_at(address, table)  # type: ignore[return-value]


def item_named(name: str, table: tuple[Item, ...] = XL430, model: str = "") -> Item:
    """A control table item by name (any case; spaces, - or _) or by address, in ``table``
    (the servo's model's, named ``model`` in the message when it has no such item)."""
    from deltoctl.errors import InvalidInput

    key = name.lower().replace("_", " ").replace("-", " ")
    for item in table:
        if item.name.lower() == key or (name.isdigit() and item.address == int(name)):
            return item
    from deltoctl.suggest import did_you_mean

    close = did_you_mean(name, (i.name.replace(" ", "_").lower() for i in table))
    where = f" in the {model}'s table" if model else ""
    raise InvalidInput(f"no control table item {name!r}{where}{close}: give a name such as "
                       "return_delay_time or present_temperature, or an address")


# the unit of one raw step (ROBOTIS e-manual); items not named are codes, flags or counts.
# Profile Acceleration and Velocity count ms instead when Drive Mode selects a time profile.
UNITS = {
    "Return Delay Time": "2 µs", "Homing Offset": "0.088°", "Moving Threshold": "0.229 rpm",
    "Temperature Limit": "°C", "Max Voltage Limit": "0.1 V", "Min Voltage Limit": "0.1 V",
    "PWM Limit": "0.113 %", "Velocity Limit": "0.229 rpm", "Max Position Limit": "0.088°",
    "Min Position Limit": "0.088°", "Bus Watchdog": "20 ms", "Goal PWM": "0.113 %",
    "Goal Velocity": "0.229 rpm", "Profile Acceleration": "214.577 rev/min²",
    "Profile Velocity": "0.229 rpm", "Goal Position": "0.088°", "Realtime Tick": "ms",
    "Present PWM": "0.113 %", "Present Load": "0.1 %", "Present Velocity": "0.229 rpm",
    "Present Position": "0.088°", "Velocity Trajectory": "0.229 rpm",
    "Position Trajectory": "0.088°", "Present Input Voltage": "0.1 V",
    "Present Temperature": "°C",
}
# what a servo does or is commanded to do, not how it is configured: kept in a configuration
# snapshot, never compared or restored (restoring a goal would move the servo)
READINGS = frozenset({
    "Torque Enable", "Registered Instruction", "Hardware Error Status", "Goal PWM",
    "Goal Velocity", "Goal Position", "Realtime Tick", "Moving", "Moving Status",
    "Present PWM", "Present Load", "Present Velocity", "Present Position",
    "Velocity Trajectory", "Position Trajectory", "Present Input Voltage",
    "Present Temperature", "Backup Ready",
    # Protocol 1.0's
    "Moving Speed", "Present Speed", "Present Voltage", "Registered", "Goal Torque",
    "Current",
})
# how the servo is addressed and answers on its bus: a restore that changed one would lose the
# servo (the profile addresses it by ID at the bus's rate); `register set` changes them
BUS_ITEMS = frozenset({"ID", "Baud Rate", "Protocol Type", "Status Return Level"})
OPERATING_MODES = {1: "velocity", 3: "position", 4: "extended position", 16: "PWM"}
