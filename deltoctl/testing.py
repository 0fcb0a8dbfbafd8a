"""The pytest plugin deltoctl registers, for users' own bring-up test suites.

    def test_gripper_comes_up(deltoctl_sim):
        target = deltoctl_sim("dg-5f-right")                # a simulated gripper on loopback
        result = CliRunner().invoke(app, ["-p", "dg-5f-right", "-t", target, "identify"])
        assert result.exit_code == 0

``deltoctl_sim(profile, firmware="3.0", short_version=False, model_id=None)`` returns the
target URL of a one-bus device (``tcp://`` for a Delto gripper, ``i2c+tcp://`` for the
Bioscara arm); ``deltoctl_sim.buses(profile, **faults)`` returns ``{bus: URL}`` for any
profile (the MH5: two serial buses and the I2C bus), with the faults of ``deltoctl sim serve``
(``missing=("head_y",)``, ``wrong_baud=…``, ``pace=True``, ``who_am_i=0x12`` …);
``deltoctl_sim.control("face -x")`` runs a control line of ``sim serve``'s standard input on
the devices served (it returns the reply). The devices stop when the test ends. Kept
import-light: pytest loads this module in every run, deltoctl's own modules are imported only
when the fixture is used.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from typing import Any

import pytest


class SimDevices:
    """What ``deltoctl_sim`` yields: called, the target URL of a one-bus device; ``buses``,
    ``{bus: URL}`` for any profile. Every device stops with ``stack``."""

    def __init__(self, stack: contextlib.ExitStack) -> None:
        from deltoctl.sim.controls import Controls

        self._stack = stack
        self._controls = Controls()

    def buses(self, profile: str, **faults: Any) -> dict[str, str]:
        from deltoctl.profile.catalog import load_profile
        from deltoctl.sim.serve import ServeOptions, serve_profile

        options = ServeOptions(**faults)
        buses: dict[str, str] = serve_profile(self._stack, load_profile(profile),
                                              options, controls=self._controls)["buses"]
        return buses

    def control(self, line: str) -> str:
        """Run a control line (``face -x``, ``tilt 10 0``) on the devices served; its reply,
        or one InvalidInput naming what is wrong."""
        return self._controls.run(line)

    def __call__(self, profile: str, firmware: str = "3.0", short_version: bool = False,
                 model_id: int | None = None) -> str:
        served = self.buses(profile, firmware=firmware, short_version=short_version,
                            model_id=model_id)
        if len(served) != 1:
            raise ValueError(f"{profile} has {len(served)} buses "
                             f"({', '.join(served)}): use deltoctl_sim.buses({profile!r})")
        return next(iter(served.values()))


@pytest.fixture
def deltoctl_sim() -> Iterator[SimDevices]:
    with contextlib.ExitStack() as stack:
        yield SimDevices(stack)


@pytest.fixture
def deltoctl_robot() -> Iterator[Callable[..., object]]:
    with contextlib.ExitStack() as stack:

        def open_one(profile: str, hardware: tuple[str, ...] = (),
                     allow_model_mismatch: bool = False, **faults: object) -> object:
            from deltoctl.app.robot import open_robot

            return stack.enter_context(open_robot(profile, sim=faults or True, hardware=hardware,
                                                  allow_model_mismatch=allow_model_mismatch))

        yield open_one
