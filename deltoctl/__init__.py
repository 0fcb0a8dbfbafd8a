"""deltoctl: configuration-driven bring-up toolkit for robot hardware.

    from deltoctl import open_robot
    with open_robot("dg-5f-right", sim=True) as robot:
        robot.identify()
        robot.move({"rj_dg_2_2": 0.2})

``open_robot`` and the result types are imported on first use: ``import deltoctl`` stays as
cheap as the CLI's start-up needs. The errors (``deltoctl.errors``, each with its exit code)
are here too, so a script tells a refusal of the envelope (``OutsideEnvelope``) from a servo
that did not answer (``NoAnswer``), one that answered with an error (``DeviceFault``, its
``code``) and a link that went away (``LinkLost``)."""

from __future__ import annotations

from typing import Any

from deltoctl.errors import (
    DeltoctlError,
    DeviceError,
    DeviceFault,
    InvalidInput,
    LinkLost,
    NoAnswer,
    NotHomed,
    OutsideEnvelope,
    ProfileError,
    ProtocolError,
    Refused,
    Unreachable,
)
from deltoctl.version import __version__

__all__ = [
    "DeltoctlError", "DeviceError", "DeviceFault", "Frame", "InvalidInput", "LinkLost",
    "NoAnswer", "NotHomed", "OutsideEnvelope", "ProfileError", "ProtocolError", "Refused",
    "Robot", "Unreachable", "__version__", "open_robot",
]


def __getattr__(name: str) -> Any:
    if name in ("Frame", "Robot", "open_robot"):
        import importlib  # the library, on first use of one of its names

        return getattr(importlib.import_module("deltoctl.app.robot"), name)
    raise AttributeError(f"module 'deltoctl' has no attribute {name!r}")
