"""The profile model: ros2_control's component model plus what deltoctl adds.

ros2_control part: hardware blocks (name, type, plugin, params) holding joints, sensors and GPIOs,
each with command and state interfaces. deltoctl part: the driver family, named buses with
endpoint URLs, per-part addressing and conversions, and the safety and homing settings.
Source positions (``line``) are kept for error messages and ignored by equality.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

COMPONENT_KINDS = ("joint", "sensor", "gpio")
HARDWARE_TYPES = ("system", "actuator", "sensor")
JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")
DATA_TYPES = (
    "double", "float32", "bool", "uint8", "int8", "uint16", "int16", "uint32", "int32",
)


@dataclass
class Interface:
    name: str
    min: float | None = None
    max: float | None = None
    initial_value: str | None = None  # text, as ros2_control keeps it
    data_type: str | None = None
    size: int | None = None
    params: dict[str, str] = field(default_factory=dict)
    line: int | None = field(default=None, compare=False, repr=False)


@dataclass
class Limits:
    """URDF joint limits (SI units); ``None`` where the URDF gives none."""

    lower: float | None = None
    upper: float | None = None
    velocity: float | None = None
    effort: float | None = None

    def contains(self, value: float, tol: float = 1e-9) -> bool:
        return not (
            (self.lower is not None and value < self.lower - tol)
            or (self.upper is not None and value > self.upper + tol)
        )


@dataclass
class Mimic:
    joint: str
    multiplier: float = 1.0
    offset: float = 0.0


@dataclass
class Component:
    """A ``<joint>``, ``<sensor>`` or ``<gpio>`` of a ros2_control block."""

    kind: str
    name: str
    command_interfaces: list[Interface] = field(default_factory=list)
    state_interfaces: list[Interface] = field(default_factory=list)
    params: dict[str, str] = field(default_factory=dict)
    # joints only
    joint_type: str = "revolute"
    limits: Limits | None = None
    mimic: Mimic | None = None
    # deltoctl: where the part sits and how its values convert
    bus: str | None = None
    address: int | None = None
    inverse: bool = False
    offset: float = 0.0
    line: int | None = field(default=None, compare=False, repr=False)

    def interface_names(self, which: str = "state") -> list[str]:
        items = self.state_interfaces if which == "state" else self.command_interfaces
        return [f"{self.name}/{i.name}" for i in items]

    def command(self, name: str) -> Interface | None:
        return next((i for i in self.command_interfaces if i.name == name), None)

    def state(self, name: str) -> Interface | None:
        return next((i for i in self.state_interfaces if i.name == name), None)


@dataclass
class Hardware:
    """One ``<ros2_control>`` block."""

    name: str
    type: str = "system"
    plugin: str = ""
    params: dict[str, str] = field(default_factory=dict)
    group: str | None = None  # ros2_control error-propagation group
    family: str | None = None
    bus: str | None = None
    joints: list[Component] = field(default_factory=list)
    sensors: list[Component] = field(default_factory=list)
    gpios: list[Component] = field(default_factory=list)
    attributes: dict[str, str] = field(default_factory=dict)  # rw_rate, is_async, ...
    line: int | None = field(default=None, compare=False, repr=False)

    def components(self) -> Iterator[Component]:
        yield from self.joints
        yield from self.sensors
        yield from self.gpios


@dataclass
class Safety:
    home_pose: dict[str, float] = field(default_factory=dict)
    max_jog_step: float | None = None  # largest single jog, rad or m
    current_cap: float | None = None  # mA, for current-bounded motion
    home_tolerance: float | None = None  # rad or m
    home_timeout: float | None = None  # s
    homing_order: list[str] = field(default_factory=list)


@dataclass
class Profile:
    name: str
    description: str = ""
    family: str | None = None
    model: str | None = None
    status: str = "current"
    buses: dict[str, str] = field(default_factory=dict)
    safety: Safety = field(default_factory=Safety)
    hardware: list[Hardware] = field(default_factory=list)
    source: str | None = field(default=None, compare=False, repr=False)

    # -- lookups ---------------------------------------------------------------------------
    def components(self) -> Iterator[tuple[Hardware, Component]]:
        for hw in self.hardware:
            for comp in hw.components():
                yield hw, comp

    def joints(self) -> list[Component]:
        return [j for hw in self.hardware for j in hw.joints]

    def component(self, name: str) -> Component | None:
        return next((c for _, c in self.components() if c.name == name), None)

    def state_interfaces(self) -> list[str]:
        return [n for _, c in self.components() for n in c.interface_names("state")]

    def command_interfaces(self) -> list[str]:
        return [n for _, c in self.components() for n in c.interface_names("command")]

    def family_of(self, hw: Hardware) -> str | None:
        return hw.family or self.family

    def bus_of(self, hw: Hardware, comp: Component | None = None) -> str | None:
        return (comp.bus if comp else None) or hw.bus

    def counts(self) -> dict[str, int]:
        return {
            "hardware": len(self.hardware),
            "joints": sum(len(h.joints) for h in self.hardware),
            "sensors": sum(len(h.sensors) for h in self.hardware),
            "gpios": sum(len(h.gpios) for h in self.hardware),
        }
