"""The pytest plugin deltoctl registers, for users' own bring-up test suites: one suite runs
on the simulators or on the robot.

    def test_gripper_comes_up(deltoctl_robot):
        robot = deltoctl_robot("dg-5f-right")      # its simulators, or the robot under test
        assert robot.identify()["blocks"]

    @pytest.mark.deltoctl_moves                    # on hardware: --deltoctl-allow-motion only
    def test_homing(deltoctl_robot):
        assert deltoctl_robot("dg-5f-right").home()["settled"]

The robot under test comes from the command line (``--deltoctl-profile mh5 --deltoctl-target
upper_body=serial:///dev/…``) or from the ``[pytest]`` table of a ``deltoctl.toml`` (the
invocation directory upward to pytest's rootdir; the command line wins). Without a target
the fixtures serve simulators; with targets they open those devices, a test of another
profile or one that asks for simulator faults is skipped, and so is a test marked
``deltoctl_moves`` unless ``--deltoctl-allow-motion`` is on the command line (a file cannot
allow motion). Without it the robot the fixture opens on hardware refuses every move,
command and actuation (``Refused``) before a byte is sent.

``deltoctl_robot(profile=None, hardware=(), allow_model_mismatch=False, **faults)`` opens the
robot (``deltoctl.open_robot``), released when the test ends; ``profile`` defaults to the
configured one; what goes wrong raises deltoctl's errors, as ``open_robot`` does.
``deltoctl_sim(profile, firmware="3.0", short_version=False, model_id=None)`` returns the
target URL of a one-bus device (``tcp://`` for a Delto gripper, ``i2c+tcp://`` for the
Bioscara arm); ``deltoctl_sim.buses(profile, **faults)`` returns ``{bus: URL}`` for any
profile (the MH5: two serial buses and the I2C bus), with the faults of ``deltoctl sim
serve`` (``missing=("head_y",)``, ``wrong_baud=…``, ``pace=True``, ``who_am_i=0x12`` …);
``deltoctl_sim.control("face -x")`` runs a control line of ``sim serve``'s standard input on
the devices served (it returns the reply). The devices stop when the test ends; on hardware,
a test that asks for them is skipped, unless ``--deltoctl-allow-motion`` gives it the robot's
targets (whatever it runs on them drives the hardware).

Kept import-light: pytest loads this module in every run; deltoctl's own modules are imported
only when a robot is configured or a fixture is used. Neither the options nor the file run
code: they name a profile and targets, checked as ``--profile`` and ``--target`` are.
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

if TYPE_CHECKING:
    from deltoctl.profile.model import Profile

CONFIG_FILE = "deltoctl.toml"
TABLE = "pytest"  # the table of deltoctl.toml this plugin reads
KEYS = ("profile", "target")
MAX_CONFIG_BYTES = 1 << 20
MOVES = "deltoctl_moves"


class RobotUnderTest:
    """What the command line and deltoctl.toml name: the profile (given, and loaded), the
    targets (none: the simulators), whether motion is allowed, and where they came from."""

    def __init__(self, spec: str | None = None, profile: Profile | None = None,
                 targets: tuple[str, ...] = (), allow_motion: bool = False,
                 source: str = "") -> None:
        self.spec, self.profile, self.targets = spec, profile, targets
        self.allow_motion, self.source = allow_motion, source

    @property
    def hardware(self) -> bool:
        return bool(self.targets)

    def chosen(self, spec: str | Path | None) -> str | Path | Profile:
        """The profile a fixture opens for a test that names ``spec`` (or none). On hardware
        a test written for another profile is skipped."""
        if spec is None:
            if self.profile is None:
                pytest.fail("deltoctl: no profile: name one in the fixture, or pass "
                            "--deltoctl-profile NAME|PATH", pytrace=False)
            return self.profile
        if not self.hardware:
            return spec
        assert self.profile is not None  # targets need a profile (checked at start)
        if str(spec) != self.spec and _loaded(spec).name != self.profile.name:
            pytest.skip(f"written for {spec}; the robot under test is {self.profile.name}")
        return self.profile

    def buses(self) -> dict[str, str]:
        """The targets by bus (a bare URL: the profile's one bus)."""
        from deltoctl.core.system import parse_targets

        assert self.profile is not None
        named, bare = parse_targets(self.profile, self.targets)
        buses = list(self.profile.buses)
        if len(bare) > 1 or (bare and len(buses) > 1):
            from deltoctl.errors import InvalidInput

            raise InvalidInput(f"{self.profile.name} has several buses ({', '.join(buses)}): "
                               "name each target, BUS=URL")
        return {**dict.fromkeys(buses, bare[0]), **named} if bare else named


def _loaded(spec: str | Path) -> Profile:
    from deltoctl.profile.catalog import load_profile

    return load_profile(spec)


ROBOT = pytest.StashKey[RobotUnderTest]()


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("deltoctl", "deltoctl: the robot under test")
    group.addoption("--deltoctl-profile", metavar="NAME|PATH", default=None,
                    help="The robot's profile (a catalog name or a file): the profile of "
                         "deltoctl_robot() and of the targets.")
    group.addoption("--deltoctl-target", metavar="BUS=URL", action="append", default=[],
                    help="Where a bus of the robot is, as deltoctl's --target (repeat per "
                         "bus): the fixtures open these devices instead of simulators.")
    group.addoption("--deltoctl-allow-motion", action="store_true", default=False,
                    help="Run the tests marked deltoctl_moves on hardware (they move the "
                         "robot's joints); without it they are skipped.")


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", f"{MOVES}: the test moves the robot's joints; with "
                            "--deltoctl-target it runs only with --deltoctl-allow-motion")
    config.stash[ROBOT] = _robot_under_test(config)


def pytest_report_header(config: pytest.Config) -> str | None:
    robot = config.stash.get(ROBOT, None)
    if robot is None or robot.profile is None:
        return None
    if not robot.hardware:
        return f"deltoctl: {robot.profile.name} on its simulators ({robot.source})"
    motion = "allowed" if robot.allow_motion else f"skipped (tests marked {MOVES})"
    return (f"deltoctl: {robot.profile.name} on {' '.join(robot.targets)} ({robot.source}); "
            f"motion: {motion}")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    robot = config.stash[ROBOT]
    if not robot.hardware or robot.allow_motion:
        return
    skip = pytest.mark.skip(reason="moves the robot: on hardware it runs only with "
                                   "--deltoctl-allow-motion")
    for item in items:
        if item.get_closest_marker(MOVES) is not None:
            item.add_marker(skip)


def _robot_under_test(config: pytest.Config) -> RobotUnderTest:
    """The options over deltoctl.toml, checked: any problem is one usage error."""
    spec: str | None = config.getoption("deltoctl_profile")
    targets: list[str] = list(config.getoption("deltoctl_target"))
    allow = bool(config.getoption("deltoctl_allow_motion"))
    sources = ["command line"] if spec or targets else []
    path, table = _config_file(config.invocation_params.dir, config.rootpath)
    if path is not None and table:
        sources.append(str(path))
        if spec is None and "profile" in table:
            spec = _relative_profile(table["profile"], path.parent)
        if not targets:
            targets = table.get("target", [])
    robot = RobotUnderTest(spec, None, tuple(targets), allow, " and ".join(sources))
    if spec is None:
        if targets:
            raise pytest.UsageError("--deltoctl-target needs the robot's profile: pass "
                                    "--deltoctl-profile NAME|PATH (or profile in "
                                    f"{CONFIG_FILE})")
        return robot
    from deltoctl import registry
    from deltoctl.errors import DeltoctlError

    try:
        robot.profile = _loaded(spec)
        for url in robot.buses().values():  # every bus named is the profile's
            registry.transport_of(url)
    except DeltoctlError as exc:
        where = f" ({robot.source})" if robot.source else ""
        hint = f"; {exc.hint}" if exc.hint else ""
        raise pytest.UsageError(f"deltoctl{where}: {exc.message}{hint}") from None
    return robot


def _relative_profile(spec: str, folder: Path) -> str:
    """A profile file named in deltoctl.toml is relative to the file; a catalog name stays."""
    beside = folder / spec
    return str(beside) if beside.is_file() else spec


def _config_file(start: Path, rootdir: Path) -> tuple[Path | None, dict[str, Any]]:
    """The nearest deltoctl.toml from ``start`` up to ``rootdir`` and its [pytest] table,
    checked."""
    folders = [start, *start.parents]
    folders = folders[:folders.index(rootdir) + 1] if rootdir in folders else [start]
    path = next((f / CONFIG_FILE for f in folders if (f / CONFIG_FILE).is_file()), None)
    if path is None:
        return None, {}
    if sys.version_info < (3, 11):
        raise pytest.UsageError(f"{path}: reading {CONFIG_FILE} needs Python 3.11 or later "
                                "(tomllib); pass --deltoctl-profile and --deltoctl-target")
    import tomllib

    try:
        with path.open("rb") as f:
            raw = f.read(MAX_CONFIG_BYTES + 1)
        if len(raw) > MAX_CONFIG_BYTES:
            raise pytest.UsageError(f"{path}: larger than {MAX_CONFIG_BYTES} bytes")
        data = tomllib.loads(raw.decode("utf-8"))
    except OSError as exc:
        raise pytest.UsageError(f"{path}: cannot read it: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise pytest.UsageError(f"{path}: not UTF-8 text") from None
    except tomllib.TOMLDecodeError as exc:
        raise pytest.UsageError(f"{path}: not valid TOML: {exc}") from None
    return path, _checked_table(path, data.get(TABLE, {}))


def _checked_table(path: Path, table: Any) -> dict[str, Any]:
    if not isinstance(table, dict):
        raise pytest.UsageError(f"{path}: [{TABLE}] is a table (profile = …, target = […])")
    unknown = sorted(set(table) - set(KEYS))
    if unknown:
        raise pytest.UsageError(f"{path}: [{TABLE}] has no key {unknown[0]!r} (its keys: "
                                f"{', '.join(KEYS)})")
    profile, target = table.get("profile", ""), table.get("target", [])
    target = [target] if isinstance(target, str) else target
    if not isinstance(profile, str) or ("profile" in table and not profile):
        raise pytest.UsageError(f"{path}: [{TABLE}] profile is a catalog name or a file, as "
                                f"a string; got {profile!r}")
    if not isinstance(target, list) or not all(isinstance(t, str) and t for t in target):
        raise pytest.UsageError(f"{path}: [{TABLE}] target is a list of \"BUS=URL\" strings; "
                                f"got {table['target']!r}")
    return {**table, "target": target}


# -- the fixtures ----------------------------------------------------------------------------

def _no_faults(robot: RobotUnderTest, faults: dict[str, Any]) -> None:
    given = sorted(name for name, value in faults.items() if value not in (None, False, ()))
    if robot.hardware and given:
        pytest.skip(f"simulator faults ({', '.join(given)}) need the simulators; the robot "
                    "under test is hardware")


class SimDevices:
    """What ``deltoctl_sim`` yields: called, the target URL of a one-bus device; ``buses``,
    ``{bus: URL}`` for any profile. Every device stops with ``stack``. On hardware: the
    robot under test's targets."""

    def __init__(self, stack: contextlib.ExitStack, robot: RobotUnderTest) -> None:
        from deltoctl.sim.controls import Controls

        self._stack, self._robot = stack, robot
        self._controls = Controls()

    def buses(self, profile: str, **faults: Any) -> dict[str, str]:
        if self._robot.hardware:
            _no_faults(self._robot, faults)
            return self._hardware(profile)
        from deltoctl.sim.serve import ServeOptions, serve_profile

        options = ServeOptions(**faults)
        buses: dict[str, str] = serve_profile(self._stack, _loaded(profile), options,
                                              controls=self._controls)["buses"]
        return buses

    def _hardware(self, profile: str) -> dict[str, str]:
        """The robot under test's targets, for a test of ``profile``: only with motion
        allowed, as any command line or library call run on them drives the hardware."""
        self._robot.chosen(profile)
        if not self._robot.allow_motion:
            pytest.skip("needs the simulators: the robot under test is hardware (with "
                        "--deltoctl-allow-motion, deltoctl_sim gives its targets)")
        return self._robot.buses()

    def control(self, line: str) -> str:
        """Run a control line (``face -x``, ``tilt 10 0``) on the devices served; its reply,
        or one InvalidInput naming what is wrong."""
        return self._controls.run(line)

    def __call__(self, profile: str, firmware: str = "3.0", short_version: bool = False,
                 model_id: int | None = None) -> str:
        if self._robot.hardware:  # a firmware of the simulator's own is a fault too
            _no_faults(self._robot, {"firmware": firmware if firmware != "3.0" else None,
                                     "short_version": short_version, "model_id": model_id})
            served = self._hardware(profile)
        else:
            served = self.buses(profile, firmware=firmware, short_version=short_version,
                                model_id=model_id)
        if len(served) != 1:
            raise ValueError(f"{profile} has {len(served)} buses "
                             f"({', '.join(served)}): use deltoctl_sim.buses({profile!r})")
        return next(iter(served.values()))


@pytest.fixture
def deltoctl_sim(request: pytest.FixtureRequest) -> Iterator[SimDevices]:
    with contextlib.ExitStack() as stack:
        yield SimDevices(stack, request.config.stash[ROBOT])


@pytest.fixture
def deltoctl_robot(request: pytest.FixtureRequest) -> Iterator[Callable[..., Any]]:
    robot: RobotUnderTest = request.config.stash[ROBOT]
    with contextlib.ExitStack() as stack:

        def open_one(profile: str | Path | None = None, hardware: tuple[str, ...] = (),
                     allow_model_mismatch: bool = False, **faults: Any) -> Any:
            from deltoctl.app.robot import open_robot

            _no_faults(robot, faults)
            chosen = robot.chosen(profile)
            if robot.hardware:  # no motion nor actuation without --deltoctl-allow-motion
                opened = open_robot(chosen, robot.targets, hardware=hardware,
                                    allow_model_mismatch=allow_model_mismatch,
                                    allow_motion=robot.allow_motion)
            else:
                opened = open_robot(chosen, sim=faults or True, hardware=hardware,
                                    allow_model_mismatch=allow_model_mismatch)
            return stack.enter_context(opened)

        yield open_one
