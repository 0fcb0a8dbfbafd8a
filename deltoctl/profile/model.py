"""The profile model: ros2_control's component model plus what deltoctl adds.

ros2_control part: hardware blocks (name, type, plugin, params) holding joints, sensors and GPIOs,
each with command and state interfaces. deltoctl part: the driver family, named buses with
endpoint URLs, per-part addressing and conversions, and the safety and homing settings.
Source positions (``line``) are kept for error messages and ignored by equality.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace

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
    enable_limits: bool = True  # False: <limits enable="false"/> inside the interface
    line: int | None = field(default=None, compare=False, repr=False)


@dataclass
class Limits:
    """Joint limits as ros2_control computes them (SI units): the URDF ``<limit>`` tightened by
    the command interfaces' ``min``/``max``. ``None`` where there is no such limit (ros2_control's
    ``has_*_limits`` false)."""

    lower: float | None = None
    upper: float | None = None
    velocity: float | None = None
    effort: float | None = None
    acceleration: float | None = None
    deceleration: float | None = None
    jerk: float | None = None

    def contains(self, value: float, tol: float = 1e-9) -> bool:
        return not (
            (self.lower is not None and value < self.lower - tol)
            or (self.upper is not None and value > self.upper + tol)
        )


@dataclass
class SoftLimits:
    """A URDF ``<safety_controller>``, kept apart from the hard limits as ros2_control does:
    the soft position range (already inside the hard one) and the gains of its soft limiter."""

    lower: float = 0.0
    upper: float = 0.0
    k_position: float = 0.0
    k_velocity: float = 0.0

    def contains(self, value: float, tol: float = 1e-9) -> bool:
        return self.lower - tol <= value <= self.upper + tol


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
    soft_limits: SoftLimits | None = None
    enable_limits: bool = True  # False: <limits enable="false"/> on the joint disables them all
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
class TransmissionEnd:
    """A ``<joint>`` or ``<actuator>`` of a ``<transmission>``. The interface names of a joint
    are the block's joint's, as ros2_control fills them in."""

    name: str
    role: str = ""
    mechanical_reduction: float = 1.0
    offset: float = 0.0
    read_only: bool = False
    command_interfaces: list[str] = field(default_factory=list)
    state_interfaces: list[str] = field(default_factory=list)
    implicit: bool = False  # the "actuator1" ros2_control adds to an actuator block


@dataclass
class Transmission:
    """A ``<transmission>`` inside a ``<ros2_control>`` block (its ``<plugin>`` is ``type``)."""

    name: str
    type: str = ""
    joints: list[TransmissionEnd] = field(default_factory=list)
    actuators: list[TransmissionEnd] = field(default_factory=list)
    params: dict[str, str] = field(default_factory=dict)
    line: int | None = field(default=None, compare=False, repr=False)


def fill_transmission(hw: Hardware, transmission: Transmission) -> None:
    """What ros2_control fills in, whichever form the profile came in: each transmission
    joint's interfaces from the block's joint, and for an actuator block the one joint's
    "actuator1". Raises ValueError naming what is wrong."""
    for end in transmission.joints:
        joint = next((j for j in hw.joints if j.name == end.name), None)
        if joint is None:
            raise ValueError(f"transmission {transmission.name!r} declared joint {end.name!r} "
                             f"is not available in component {hw.name!r}")
        end.command_interfaces = [i.name for i in joint.command_interfaces]
        end.state_interfaces = [i.name for i in joint.state_interfaces]
    if hw.type != "actuator":
        return
    if len(transmission.joints) != 1:
        raise ValueError(f"transmission {transmission.name!r} of actuator {hw.name!r}: there "
                         "should be exactly one joint defined in this component but found "
                         f"{len(transmission.joints)}")
    joint_end = transmission.joints[0]
    transmission.actuators = [a for a in transmission.actuators if not a.implicit]
    transmission.actuators.append(TransmissionEnd(
        "actuator1", "actuator1", command_interfaces=list(joint_end.command_interfaces),
        state_interfaces=list(joint_end.state_interfaces), implicit=True))


@dataclass
class AsyncParams:
    """ros2_control's HardwareAsyncParams: how an ``is_async`` block's thread runs."""

    thread_priority: int = 50
    scheduling_policy: str = "synchronized"
    cpu_affinity_cores: list[int] = field(default_factory=list)
    print_warnings: bool = True


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
    transmissions: list[Transmission] = field(default_factory=list)
    async_properties: dict[str, str] = field(default_factory=dict)  # <properties><async …/>
    line: int | None = field(default=None, compare=False, repr=False)

    def components(self) -> Iterator[Component]:
        yield from self.joints
        yield from self.sensors
        yield from self.gpios

    # The block's attributes, typed as ros2_control reads them (validation has checked them).
    @property
    def rw_rate(self) -> int:
        """Read/write rate in Hz; 0: the controller manager's rate."""
        return parse_rw_rate(self.attributes.get("rw_rate", "0"))[0]

    @property
    def is_async(self) -> bool:
        return parse_bool(self.attributes.get("is_async", "false"))

    @property
    def async_params(self) -> AsyncParams | None:
        """The async thread's settings; ``None`` for a block that is not ``is_async`` (its
        thread priority is then ros2_control's "none", INT_MAX)."""
        if not self.is_async:
            return None
        params = AsyncParams(parse_thread_priority(self.attributes.get("thread_priority", "50")))
        props = self.async_properties
        if "thread_priority" in props:
            params.thread_priority = parse_thread_priority(props["thread_priority"])
        if "scheduling_policy" in props:
            params.scheduling_policy = props["scheduling_policy"].strip().lower()
        if "affinity" in props:
            params.cpu_affinity_cores = parse_int_array(props["affinity"])
        if "print_warnings" in props:
            params.print_warnings = parse_bool(props["print_warnings"])
        return params


@dataclass
class Safety:
    home_pose: dict[str, float] = field(default_factory=dict)
    max_jog_step: float | None = None  # largest single jog, rad or m
    current_cap: float | None = None  # mA, for current-bounded motion
    home_tolerance: float | None = None  # rad or m
    home_timeout: float | None = None  # s
    homing_order: list[str] = field(default_factory=list)


@dataclass
class ProfileWarning:
    """Something ros2_control lets through that deltoctl thinks wrong or unsafe (an error
    under ``strict``)."""

    message: str
    source: str | None = None
    line: int | None = None

    def __str__(self) -> str:
        where = self.source or "<profile>"
        return f"{where}:{self.line}: {self.message}" if self.line else f"{where}: {self.message}"


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
    # the commissioning report's limits (REPORT_LIMITS names them), over its defaults
    report: dict[str, float] = field(default_factory=dict)
    source: str | None = field(default=None, compare=False, repr=False)
    warnings: list[ProfileWarning] = field(default_factory=list, compare=False, repr=False)

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


# -- ros2_control's readings of attribute text ----------------------------------------------------

INT_MAX = 2**31 - 1
_LEADING_INT = re.compile(r"[+-]?\d+")
_POSITIVE_INT = re.compile(r"[1-9][0-9]*")
_DECIMAL = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")


def parse_rw_rate(text: str) -> tuple[int, bool]:
    """``rw_rate`` read as ros2_control does (``std::stoi``: a leading whole number, the rest
    ignored), and whether anything was ignored. Raises ValueError."""
    text = text.strip()
    match = _LEADING_INT.match(text)
    if match is None:
        raise ValueError(f"rw_rate must be a whole number of Hz (0: the controller manager's "
                         f"rate), got {text!r}")
    value = int(match.group())
    if not -INT_MAX - 1 <= value <= INT_MAX:
        raise ValueError(f"rw_rate {text!r} is out of range (at most {INT_MAX} Hz)")
    if value < 0:
        raise ValueError(f"rw_rate must be a positive whole number of Hz (0: the controller "
                         f"manager's rate), got {text!r}")
    return value, match.end() < len(text)


def parse_bool(text: str) -> bool:
    """``true``/``false`` in any case, as ros2_control's parse_bool. Raises ValueError."""
    lowered = text.strip().lower()
    if lowered not in ("true", "false"):
        raise ValueError(f"expected 'true' or 'false', got {text!r}")
    return lowered == "true"


def parse_thread_priority(text: str) -> int:
    """A non-zero positive whole number, as ros2_control reads ``thread_priority``."""
    stripped = text.strip()
    if not _POSITIVE_INT.fullmatch(stripped) or int(stripped) > INT_MAX:
        raise ValueError(f"thread_priority must be a non-zero positive integer, got {text!r}")
    return int(stripped)


def parse_int_array(text: str) -> list[int]:
    """A flat ``[1, 2,3]`` list of whole numbers (``<async affinity=…>``)."""
    stripped = text.strip()
    if not (stripped.startswith("[") and stripped.endswith("]")):
        raise ValueError(f"expected a flat array like [1, 2], got {text!r}")
    inner = stripped[1:-1].strip()
    if not inner:
        return []
    items = [item.strip() for item in inner.split(",")]
    if any(not _DECIMAL.fullmatch(item) or "[" in item for item in items):
        raise ValueError(f"expected a flat array of numbers like [1, 2], got {text!r}")
    return [int(float(item)) for item in items]


def parse_number(text: str) -> float | None:
    """A finite decimal number as ros2_control and urdfdom read one (no units, no ``inf`` or
    ``nan``, no trailing text); ``None`` when ``text`` is not one."""
    stripped = text.strip()
    if not _DECIMAL.fullmatch(stripped):
        return None
    value = float(stripped)
    return value if math.isfinite(value) else None


# -- joint limits, merged as ros2_control's getJointLimits + update_interface_limits ---------------

def merge_interface_limits(urdf: Limits | None, joint: Component) -> Limits | None:
    """The joint's limits from its URDF ``<limit>`` (already read as ``getJointLimits`` does) and
    its command interfaces' ``min``/``max``: the stricter wins, a velocity or effort range's
    ``|min|`` counts too, ``enable="false"`` drops a limit. ``None`` when no limit is left."""
    if not joint.enable_limits:
        return None
    lim = replace(urdf) if urdf is not None else Limits()
    for itf in joint.command_interfaces:
        on = itf.enable_limits
        if itf.name == "position":
            if not on:
                lim.lower = lim.upper = None
                continue
            lim.lower = _tighter(lim.lower, itf.min, max)
            lim.upper = _tighter(lim.upper, itf.max, min)
        elif itf.name in ("velocity", "effort"):
            current = getattr(lim, itf.name)
            if not on:
                setattr(lim, itf.name, None)
                continue
            bound = _tighter(None if itf.min is None else abs(itf.min), itf.max, min)
            setattr(lim, itf.name, _tighter(current, bound, min))
        elif itf.name == "acceleration":
            # min bounds the deceleration (by its size), max the acceleration
            if itf.min is not None:
                lim.deceleration = abs(itf.min) if on else None
            if itf.max is not None:
                lim.acceleration = itf.max if on else None
        elif itf.name == "jerk" and itf.max is not None:
            lim.jerk = abs(itf.max) if on else None
    return None if lim == Limits() else lim


def _tighter(current: float | None, bound: float | None,
             pick: Callable[[float, float], float]) -> float | None:
    if bound is None:
        return current
    return bound if current is None else pick(current, bound)


def clamp_soft_limits(soft: SoftLimits, hard: Limits | None) -> SoftLimits:
    """Soft limits inside the hard position range, as ros2_control clamps them."""
    if hard is None:
        return soft
    lower = soft.lower if hard.lower is None else max(soft.lower, hard.lower)
    upper = soft.upper if hard.upper is None else min(soft.upper, hard.upper)
    return replace(soft, lower=lower, upper=upper)
