"""LeRobot's calibration file, as servo families share it (reference: feetech-sts-and-lerobot.md
§3.5): per motor ``id``, ``drive_mode``, ``homing_offset``, ``range_min``, ``range_max``
(steps, as in the servos' registers), JSON at
``$HF_LEROBOT_CALIBRATION/{robots|teleoperators}/<robot type>/<id>.json``."""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from deltoctl.errors import InvalidInput

KEYS = ("id", "drive_mode", "homing_offset", "range_min", "range_max")
MAX_BYTES = 1 << 20  # a calibration file's largest size


def read_json(path: Path) -> Any:
    """A calibration file's JSON (LeRobot's or deltoctl's): a regular file (a device or a FIFO
    would never end) of at most MAX_BYTES; anything else is one InvalidInput naming it."""
    import stat

    try:
        if not stat.S_ISREG(path.stat().st_mode):
            raise InvalidInput(f"{path}: a calibration file must be a regular file")
        with path.open("rb") as file:
            text = file.read(MAX_BYTES + 1)
        if len(text) > MAX_BYTES:
            raise InvalidInput(f"{path}: larger than 1 MiB, not a calibration file")
        return json.loads(text.decode())
    except OSError as exc:
        raise InvalidInput(f"{path}: cannot read the calibration ({exc.strerror})") from None
    except RecursionError:
        raise InvalidInput(f"{path}: not a calibration file (nested too deep)") from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise InvalidInput(f"{path}: not a calibration file ({exc})") from None


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
