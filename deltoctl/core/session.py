"""A session on one device: target resolution, an optional in-process simulator, the driver
and its lifecycle, and the safe state on the way out (duty 0 / stop), whatever happens."""

from __future__ import annotations

from deltoctl.core.lifecycle import Lifecycle
from deltoctl.errors import InvalidInput
from deltoctl.profile.model import Hardware, Profile

DRIVEN = ("delto", "generic", "dynamixel", "bioscara", "lsm6ds3")  # families with a driver


def resolve_target(profile: Profile, hw: Hardware, targets: list[str]) -> str:
    """``--target`` values ``[BUS=]URL`` override the profile's bus URLs."""
    bus = hw.bus
    for item in targets:
        name, found, url = item.partition("=")
        if found and "://" not in name:
            if name not in profile.buses:
                raise InvalidInput(f"--target names unknown bus {name!r} "
                                   f"(the profile's buses: {', '.join(profile.buses)})")
            if name == bus:
                return url
        else:
            return item
    if bus is None or bus not in profile.buses:
        raise InvalidInput(f"{hw.name!r} has no bus URL: pass --target URL")
    return profile.buses[bus]


class Session:
    """``with Session(profile, opts) as s: s.driver.read()``."""

    def __init__(self, profile: Profile, targets: list[str], sim: bool = False,
                 allow_model_mismatch: bool = False, probe: bool = False):
        """``probe``: a bus where nothing answers is still opened (for ``detect``, which is
        what a technician runs then); otherwise it is unreachable."""
        self.profile = profile
        self.probe = probe
        self.hw = self._driven_block(profile)
        self.sim = None
        self.lifecycle = Lifecycle()
        self._sim_i2c = None
        family = profile.family_of(self.hw)
        if family in ("dynamixel", "lsm6ds3"):
            self._open_buses(targets, sim)
            return
        if family == "bioscara":
            from deltoctl.families.bioscara.driver import BioscaraDriver

            smbus, self.url = self._i2c(self.hw, targets, sim)
            self.driver = BioscaraDriver(profile, self.hw, self.url, smbus, probe)
            return
        if family == "generic":  # simulated only: no transport
            from deltoctl.families.generic.driver import GenericDriver

            self.url = "mock://" + profile.name
            self.driver = GenericDriver(profile, [h for h in profile.hardware
                                                  if profile.family_of(h) == "generic"])
            return
        if sim:
            self.sim = self._start_sim()
            self.url = self.sim.endpoint
        else:
            self.url = resolve_target(profile, self.hw, targets)
        self.driver = self._make_driver(allow_model_mismatch)

    @staticmethod
    def _driven_block(profile: Profile) -> Hardware:
        for hw in profile.hardware:
            if profile.family_of(hw) in DRIVEN:
                return hw
        families = sorted({profile.family_of(h) or "none" for h in profile.hardware})
        raise InvalidInput(f"profile {profile.name!r} has no block deltoctl can drive yet "
                           f"(families: {', '.join(families)}; supported: "
                           f"{', '.join(DRIVEN)})")

    def _i2c(self, hw: Hardware, targets: list[str], sim: bool):  # type: ignore[no-untyped-def]
        """``(smbus, url)`` for an I2C block: the in-process simulated bus with --sim (one
        per session, every simulated I2C device of the profile on it), else the target."""
        if not sim:
            return None, resolve_target(self.profile, hw, targets)
        if self._sim_i2c is None:
            from deltoctl.sim.i2c_bus import bus_for_profile

            self._sim_i2c = bus_for_profile(self.profile)
        return self._sim_i2c, f"i2c+sim://{self.profile.name}"

    def _open_buses(self, targets: list[str], sim: bool) -> None:
        """One driver per Dynamixel bus (with --sim, a pseudo-terminal bus for each), and
        one per I2C sensor block."""
        from deltoctl.families.dynamixel.driver import BusesDriver, DynamixelDriver
        from deltoctl.families.lsm6ds3.driver import Lsm6ds3Driver

        drivers: list = []
        servers = []
        for hw in self.profile.hardware:
            if self.profile.family_of(hw) == "lsm6ds3":
                smbus, url = self._i2c(hw, targets, sim)
                drivers.append(Lsm6ds3Driver(self.profile, hw, url, smbus))
                continue
            if self.profile.family_of(hw) != "dynamixel":
                continue
            if sim:
                from deltoctl.families.dynamixel.emulator import DynamixelBus, DynamixelPtyServer, Servo

                servos = [Servo(j.address) for j in hw.joints if j.address is not None]
                server = DynamixelPtyServer(DynamixelBus(servos, baud=1000000)).start()
                servers.append(server)
                url = f"serial://{server.port}?baud=1000000"
            else:
                url = resolve_target(self.profile, hw, targets)
            drivers.append(DynamixelDriver(self.profile, hw, url, self.probe))
        self.sim = _Servers(servers) if servers else None
        self.url = ", ".join(d.url for d in drivers)
        self.driver = BusesDriver(drivers)

    def _start_sim(self):  # type: ignore[no-untyped-def]
        from deltoctl.families.delto.emulator import DeltoServer, firmware_for_profile

        return DeltoServer(firmware_for_profile(self.profile)).start()

    def _make_driver(self, allow_model_mismatch: bool):  # type: ignore[no-untyped-def]
        from deltoctl.families.delto.driver import DeltoDriver

        return DeltoDriver(self.profile, self.hw, self.url, allow_model_mismatch)

    def __enter__(self) -> Session:
        try:
            self.lifecycle.transition("configure", self.driver.configure)
            self.lifecycle.transition("activate")
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Leave the device safe, then release it (runs on errors and Ctrl-C too)."""
        try:
            if self.lifecycle.state == "active":
                self.driver.stop()
                self.lifecycle.transition("deactivate")
            if self.lifecycle.state == "inactive":
                self.lifecycle.transition("cleanup", self.driver.cleanup)
            else:
                self.driver.cleanup()
            self.lifecycle.transition("shutdown")
        finally:
            if self.sim is not None:
                self.sim.close()
                self.sim = None


class _Servers:
    """Several simulator servers closed together."""

    def __init__(self, servers: list) -> None:
        self.servers = servers

    def close(self) -> None:
        for server in self.servers:
            server.close()
