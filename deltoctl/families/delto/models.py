"""The Delto model table and the conversion constants: one place to correct a wrong fact.

Sources: ../shared/reference/delto-protocol.md §1.6 (layouts), §2.1 (direction rules),
§2.2 (effort → duty constants, read from the vendor's helper library: marked derived).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

# SensorType byte of GET_VERSION.
SENSOR_NONE, FT_6AXIS, FT_3AXIS, TACTILE_M, FT_4AXIS, TACTILE_S = 0, 1, 2, 3, 4, 5
SENSOR_NAMES = {SENSOR_NONE: "none", FT_6AXIS: "ft_6axis", FT_3AXIS: "ft_3axis",
                TACTILE_M: "tactile_m", FT_4AXIS: "ft_4axis", TACTILE_S: "tactile_s"}
FT_TYPES = (FT_6AXIS, FT_3AXIS, FT_4AXIS)

# Effort (N·m) → duty, and the current limiter (derived from the helper library; verify).
RM = 13.875  # winding resistance, ohm
KT = 1.15  # torque constant, N·m/A
MAX_VOLTAGE = 12.0  # V
MAX_ABS_DUTY = 100.0  # %
LIMIT_CURRENT = 150  # mA
CURRENT_HYSTERESIS = 20  # mA
MAX_CURRENT_INTEGRAL = 30.0
DUTY_WIRE_LIMIT = 1000  # wire units of 0.1 %

DG5F_LEFT_DIR = (1, 1, 1, 1, -1, 1, 1, 1, -1, 1, 1, 1, -1, 1, 1, 1, -1, 1, -1, -1)
DG5F_RIGHT_DIR = (1, 1, -1, -1, -1, 1, 1, 1, -1, 1, 1, 1, -1, 1, 1, 1, -1, -1, -1, -1)


@dataclass(frozen=True)
class DeltoModel:
    id: int
    name: str
    motors: int
    fingers: int
    bytes_per_motor: int = 8
    position_unit_deg: float = 0.1  # one position count on the wire
    gpio: bool = True
    revised_from: tuple[int, int] | None = None  # firmware from which every direction is +1
    legacy_direction: tuple[int, ...] | int = 1  # per motor, or one sign for all

    @property
    def legacy(self) -> bool:
        """The discontinued DG-3F-B: 5-byte records, no sensors, no GPIO block."""
        return self.bytes_per_motor == 5

    def direction(self, firmware: tuple[int, int]) -> tuple[int, ...]:
        """Per-motor duty signs for this firmware (reference §2.1)."""
        if self.revised_from is None or firmware >= self.revised_from:
            return (1,) * self.motors
        d = self.legacy_direction
        return tuple(d) if isinstance(d, tuple) else (d,) * self.motors

    def position_scale(self) -> float:
        """Radians per position count."""
        return math.radians(self.position_unit_deg)


MODELS: dict[int, DeltoModel] = {
    m.id: m
    for m in (
        DeltoModel(0x1F02, "DG-1F", 3, 1, gpio=False),
        DeltoModel(0x2F03, "DG-2F", 6, 2, gpio=False),
        # GPIO per the README, but developer mode sends no GPIO block and refuses SET_GPIO
        DeltoModel(0x3F01, "DG-3F-B", 12, 3, bytes_per_motor=5, gpio=False,
                   revised_from=(3, 6), legacy_direction=-1),
        DeltoModel(0x3F02, "DG-3F-M", 12, 3, revised_from=(2, 8), legacy_direction=-1),
        DeltoModel(0x4F02, "DG-4F", 18, 4),
        DeltoModel(0x5F02, "DG-5F", 20, 5, gpio=False, revised_from=(2, 8)),
        DeltoModel(0x5F12, "DG-5F-L", 20, 5, revised_from=(2, 8),
                   legacy_direction=DG5F_LEFT_DIR),
        DeltoModel(0x5F22, "DG-5F-R", 20, 5, revised_from=(2, 8),
                   legacy_direction=DG5F_RIGHT_DIR),
        DeltoModel(0x5F14, "DG-5F-S-L", 20, 5, position_unit_deg=0.01, gpio=False),
        DeltoModel(0x5F24, "DG-5F-S-R", 20, 5, position_unit_deg=0.01, gpio=False),
        DeltoModel(0x5F34, "DG-5F-S15-L", 15, 5, position_unit_deg=0.01, gpio=False),
        DeltoModel(0x5F44, "DG-5F-S15-R", 15, 5, position_unit_deg=0.01, gpio=False),
    )
}


def model_label(model_id: int) -> str:
    model = MODELS.get(model_id)
    return f"{model.name} ({model_id:#06x})" if model else f"unknown ({model_id:#06x})"


def effort_to_duty_percent(effort: float) -> float:
    """Torque command (N·m) → duty %, clamped (ConvertDuty of the helper library)."""
    duty = effort * (RM / KT) / MAX_VOLTAGE * 100.0
    return max(-MAX_ABS_DUTY, min(MAX_ABS_DUTY, duty))


class CurrentLimiter:
    """Shrinks a joint's command while its current stays above LIMIT_CURRENT (per joint).

    Same shape as the helper library's CurrentControl: latch above limit+hysteresis, release
    below limit−hysteresis, and integrate the excess current into a bounded correction.
    """

    def __init__(self, limit: float = LIMIT_CURRENT) -> None:
        self.limit = limit
        self.latched = False
        self.integral = 0.0

    def __call__(self, target: float, current_ma: float) -> float:
        magnitude = abs(current_ma)
        if magnitude > self.limit + CURRENT_HYSTERESIS:
            self.latched = True
        elif magnitude < self.limit - CURRENT_HYSTERESIS:
            self.latched = False
            self.integral = 0.0
        sign = -math.copysign(1.0, target) if target else 1.0
        delta = 0.0
        if self.latched:
            delta = (magnitude - self.limit) / 300000.0
            self.integral = max(-MAX_CURRENT_INTEGRAL,
                                min(MAX_CURRENT_INTEGRAL, self.integral + delta))
        return target + sign * (self.integral + delta)
