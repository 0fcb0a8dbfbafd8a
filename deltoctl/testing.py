"""The pytest plugin deltoctl registers, for users' own bring-up test suites.

    def test_gripper_comes_up(deltoctl_sim):
        target = deltoctl_sim("dg-5f-right")                # a simulated gripper on loopback
        result = CliRunner().invoke(app, ["-p", "dg-5f-right", "-t", target, "identify"])
        assert result.exit_code == 0

``deltoctl_sim(profile, firmware="3.0", short_version=False, model_id=None)`` returns the
target URL (``tcp://`` for a Delto gripper, ``i2c+tcp://`` for the Bioscara arm's I2C bus; the
firmware options are the gripper's); the device is stopped when the test ends. Kept
import-light: pytest loads this module in every run, deltoctl's own modules are imported only
when the fixture is used.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest


@pytest.fixture
def deltoctl_sim() -> Iterator[Callable[..., str]]:
    servers = []

    def start(profile: str, firmware: str = "3.0", short_version: bool = False,
              model_id: int | None = None) -> str:
        from deltoctl.profile.catalog import load_profile

        prof = load_profile(profile)
        if any(prof.family_of(h) == "bioscara" for h in prof.hardware):
            from deltoctl.sim.i2c_bus import I2CSocketServer, bus_for_profile

            i2c = I2CSocketServer(bus_for_profile(prof)).start()
            servers.append(i2c)
            return i2c.url
        from deltoctl.sim.delto import DeltoServer, firmware_for_profile

        major, minor = (int(x) for x in firmware.split("."))
        device = firmware_for_profile(prof, model_id=model_id, firmware=(major, minor),
                                      short_version=short_version)
        server = DeltoServer(device).start()
        servers.append(server)
        return server.endpoint

    yield start
    for server in servers:
        server.close()
