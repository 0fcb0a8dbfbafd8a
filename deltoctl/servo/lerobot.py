"""LeRobot's calibration file, as servo families share it (reference: feetech-sts-and-lerobot.md
§3.5): per motor ``id``, ``drive_mode``, ``homing_offset``, ``range_min``, ``range_max``
(steps, as in the servos' registers), JSON at
``$HF_LEROBOT_CALIBRATION/{robots|teleoperators}/<robot type>/<id>.json``."""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path

KEYS = ("id", "drive_mode", "homing_offset", "range_min", "range_max")


def root() -> Path:
    """LeRobot's calibration cache: $HF_LEROBOT_CALIBRATION, else $HF_LEROBOT_HOME/calibration,
    else $HF_HOME/lerobot/calibration (~/.cache/huggingface by default)."""
    found = os.environ.get("HF_LEROBOT_CALIBRATION")
    if found is None:
        home = os.environ.get("HF_LEROBOT_HOME") or str(
            Path(os.environ.get("HF_HOME", Path.home() / ".cache" / "huggingface")) / "lerobot")
        found = str(Path(home) / "calibration")
    return Path(found).expanduser()


def path(robot_type: str, device_id: str, leader: bool = False) -> Path:
    """Where LeRobot looks for the calibration of device ``device_id`` of ``robot_type``
    (so_follower, koch_follower; a leader's under teleoperators)."""
    return root() / ("teleoperators" if leader else "robots") / robot_type / f"{device_id}.json"


def dump(motors: Mapping[str, Mapping[str, int]]) -> str:
    """LeRobot's JSON: its keys in its order, 4-space indent."""
    return json.dumps({name: {k: int(m[k]) for k in KEYS} for name, m in motors.items()},
                      indent=4)
