"""deltoctl: configuration-driven bring-up toolkit for robot hardware.

    from deltoctl import open_robot
    with open_robot("dg-5f-right", sim=True) as robot:
        robot.identify()
        robot.move({"rj_dg_2_2": 0.2})

``open_robot`` and the result types are imported on first use: ``import deltoctl`` stays as
cheap as the CLI's start-up needs."""

from __future__ import annotations

from typing import Any

__version__ = "0.1.0"
__all__ = ["Frame", "Robot", "__version__", "open_robot"]


def __getattr__(name: str) -> Any:
    if name in ("Frame", "Robot", "open_robot"):
        import importlib  # by name, so the modules that read __version__ stay below the app


        return getattr(importlib.import_module("deltoctl.app.robot"), name)
    raise AttributeError(f"module 'deltoctl' has no attribute {name!r}")
