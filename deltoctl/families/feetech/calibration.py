"""LeRobot's calibration file of a Feetech bus, and its conversion of positions (reference
§3.3–3.5): per motor ``id``, ``drive_mode``, ``homing_offset``, ``range_min``, ``range_max``
(steps, as written into the servos' EEPROM), saved as JSON at
``$HF_LEROBOT_CALIBRATION/{robots|teleoperators}/{so_follower|so_leader}/<id>.json``.

The three normalisation modes convert exactly as LeRobot's bus does: RANGE_M100_100 and
RANGE_0_100 clamp to the range and follow drive_mode; DEGREES is centred on the range's middle,
unclamped, and ignores drive_mode. Back to steps, a value is bounded (range modes) and
truncated toward zero, as LeRobot's ``int()``.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

from deltoctl.errors import InvalidInput

DEGREES, RANGE_M100_100, RANGE_0_100 = "degrees", "range_m100_100", "range_0_100"
MODES = (DEGREES, RANGE_M100_100, RANGE_0_100)
KEYS = ("id", "drive_mode", "homing_offset", "range_min", "range_max")


@dataclass(frozen=True)
class MotorCalibration:
    id: int
    drive_mode: int
    homing_offset: int
    range_min: int
    range_max: int


def load(path: Path) -> dict[str, MotorCalibration]:
    """A calibration file; anything else than LeRobot's shape is one InvalidInput naming it."""
    from deltoctl.servo.lerobot import read_json

    data = read_json(Path(path))
    if not isinstance(data, dict) or not data:
        raise InvalidInput(f"{path}: a LeRobot calibration file is an object of motors")
    motors = {}
    for name, entry in data.items():
        if not isinstance(entry, dict) or set(entry) != set(KEYS) or not all(
                isinstance(entry[k], int) and not isinstance(entry[k], bool) for k in KEYS):
            raise InvalidInput(f"{path}: motor {name!r} must have the integers "
                               f"{', '.join(KEYS)}")
        motors[name] = MotorCalibration(**{k: entry[k] for k in KEYS})
    return motors


def dump(motors: dict[str, MotorCalibration]) -> str:
    """LeRobot's JSON (4-space indent, its key order)."""
    return json.dumps({name: asdict(m) for name, m in motors.items()}, indent=4)


def save(path: Path, motors: dict[str, MotorCalibration]) -> Path:
    """Write LeRobot's file (its folders made), as LeRobot's calibrate saves it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(dump(motors))
    return path


def default_path(device_id: str, leader: bool = False) -> Path:
    """Where LeRobot looks for a calibration: its cache, by device kind and id."""
    from deltoctl.servo import lerobot

    return lerobot.path("so_leader" if leader else "so_follower", device_id, leader)


def _range(m: MotorCalibration) -> tuple[int, int]:
    if m.range_min == m.range_max:
        raise InvalidInput(f"invalid calibration of motor {m.id}: range_min = range_max = "
                           f"{m.range_min}")
    return m.range_min, m.range_max


def normalize(raw: int, m: MotorCalibration, mode: str, resolution: int = 4096) -> float:
    low, high = _range(m)
    if mode == DEGREES:
        return (raw - (low + high) / 2) * 360 / (resolution - 1)
    bounded = min(high, max(low, raw))
    if mode == RANGE_M100_100:
        value = (bounded - low) / (high - low) * 200 - 100
        return -value if m.drive_mode else value
    value = (bounded - low) / (high - low) * 100
    return 100 - value if m.drive_mode else value


def unnormalize(value: float, m: MotorCalibration, mode: str, resolution: int = 4096) -> int:
    low, high = _range(m)
    if mode == DEGREES:
        return int(value * (resolution - 1) / 360 + (low + high) / 2)
    if mode == RANGE_M100_100:
        bounded = min(100.0, max(-100.0, value))
        bounded = -bounded if m.drive_mode else bounded
        return int((bounded + 100) / 200 * (high - low) + low)
    bounded = min(100.0, max(0.0, value))
    bounded = 100 - bounded if m.drive_mode else bounded
    return int(bounded / 100 * (high - low) + low)
