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
TACTILE_TYPES = (TACTILE_M, TACTILE_S)

# Radians per position count, exact as the vendor computes them (π/1800, π/18000), not
# math.radians(0.1), which rounds differently in the last bit.
DECI_DEGREE = math.pi / 1800  # 0.1° (every model but the S hands)
CENTI_DEGREE = math.pi / 18000  # 0.01° (DG-5F-S, DG-5F-S15)


@dataclass(frozen=True)
class TactileGrid:
    """One fingertip's tactile grid: its cells on the wire, in the Image the vendor publishes.

    Wire order: row by row, ``cols`` cells a row (``cell_<row>_<col>``); the vendor copies the
    cells into its sensor_msgs/Image in that order, ``height`` = rows, ``width`` = cols.
    Unverified against hardware: which row is the fingertip's distal end and which column
    the thumb side (no drawing of the pad is public); every consumer takes it from here.
    """

    rows: int
    cols: int
    code: str  # struct code of one cell on the wire (big-endian)
    encoding: str  # sensor_msgs/Image encoding (mono16: little-endian in the Image)

    @property
    def cells(self) -> int:
        return self.rows * self.cols

    @property
    def label(self) -> str:
        return f"{self.rows}×{self.cols}"


TACTILE_GRIDS = {TACTILE_M: TactileGrid(5, 3, "B", "mono8"),
                 TACTILE_S: TactileGrid(6, 3, "H", "mono16")}

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
    position_per_count: float = DECI_DEGREE  # rad
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
        return self.position_per_count


MODELS: dict[int, DeltoModel] = {
    m.id: m
    for m in (
        DeltoModel(0x1F02, "DG-1F", 3, 1, gpio=False),
        DeltoModel(0x2F03, "DG-2F", 6, 2, gpio=False),
        # GPIO per Tesollo's README, but developer mode sends no GPIO block and refuses SET_GPIO
        DeltoModel(0x3F01, "DG-3F-B", 12, 3, bytes_per_motor=5, gpio=False,
                   revised_from=(3, 6), legacy_direction=-1),
        DeltoModel(0x3F02, "DG-3F-M", 12, 3, revised_from=(2, 8), legacy_direction=-1),
        DeltoModel(0x4F02, "DG-4F", 18, 4),
        DeltoModel(0x5F02, "DG-5F", 20, 5, gpio=False, revised_from=(2, 8)),
        DeltoModel(0x5F12, "DG-5F-L", 20, 5, revised_from=(2, 8),
                   legacy_direction=DG5F_LEFT_DIR),
        DeltoModel(0x5F22, "DG-5F-R", 20, 5, revised_from=(2, 8),
                   legacy_direction=DG5F_RIGHT_DIR),
        DeltoModel(0x5F14, "DG-5F-S-L", 20, 5, position_per_count=CENTI_DEGREE, gpio=False),
        DeltoModel(0x5F24, "DG-5F-S-R", 20, 5, position_per_count=CENTI_DEGREE, gpio=False),
        DeltoModel(0x5F34, "DG-5F-S15-L", 15, 5, position_per_count=CENTI_DEGREE, gpio=False),
        DeltoModel(0x5F44, "DG-5F-S15-R", 15, 5, position_per_count=CENTI_DEGREE, gpio=False),
    )
}


# The fingertip sensors each model is sold with (TCP README's table; the first is what the
# emulator fits when a profile declares none). Tesollo's README lists no F/T for the S15,
# though the vendor's driver allows it; the GET_VERSION reply says what a given gripper has.
MODEL_SENSORS: dict[int, tuple[int, ...]] = {
    0x3F02: (FT_6AXIS, TACTILE_M), 0x4F02: (FT_6AXIS, TACTILE_M),
    0x5F12: (FT_6AXIS, TACTILE_M), 0x5F22: (FT_6AXIS, TACTILE_M),
    0x5F14: (TACTILE_S, FT_6AXIS), 0x5F24: (TACTILE_S, FT_6AXIS),
    0x5F34: (TACTILE_S,), 0x5F44: (TACTILE_S,),
}


def sensor_label(sensor_type: int | None) -> str:
    """``TACTILE_S, 6×3 cells``, ``FT_6AXIS``, ``NONE``."""
    name = SENSOR_NAMES.get(sensor_type or 0, f"unknown {sensor_type}").upper()
    grid = TACTILE_GRIDS.get(sensor_type or 0)
    return f"{name}, {grid.label} cells" if grid else name


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
