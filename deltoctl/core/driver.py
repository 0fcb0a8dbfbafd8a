"""The driver contract: what every family's driver offers the System and the verbs.

ros2_control's lifecycle (configure, activate, read, write, stop, deactivate, cleanup), then the
capabilities a verb may ask for (identify, detect, home, jog, calibrate_ft, gpio, registers,
torque, reboot, config) — declared in the family's descriptor, so a verb asks what a block can
do, never which family it is. Every driver is built the same way: ``DriverClass(block)``.

The System checks the safety envelope (core/envelope.py) before it calls ``move``, ``write``,
``set_command`` or ``follow``: a driver sends what it is given.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar

from deltoctl.errors import InvalidInput, Unreachable

if TYPE_CHECKING:
    from deltoctl.core.loop import CommLoop
    from deltoctl.profile.model import Hardware, Profile
    from deltoctl.registry import Family

Progress = Callable[[float], None]
HomeProgress = Callable[[str, str, float], None]
# One joint's setpoint of a cycle: (position, velocity, effort), NaN where not commanded
Setpoint = tuple[float, float, float]
SETPOINT_FIELDS = ("position", "velocity", "effort")
# Called by a move loop once a cycle, after its commands went out: (time.time_ns(), the state
# read that cycle, joint → the setpoint sent)
CycleHook = Callable[[int, dict[str, float], dict[str, Setpoint]], None]


@dataclass
class MoveResult:
    """How a move ended. A joint has settled when its device says it stopped (a servo's
    moving flag, a drive's target-reached bit, or its velocity near zero over consecutive reads
    where the device has no such signal) within the profile's home_tolerance of its target;
    being within tolerance while still on the way is not settled. A joint that has not when the
    move's time runs out is unsettled."""

    settled: bool
    seconds: float
    errors: dict[str, float]  # final |error| per joint
    unsettled: list[str]


class Links:
    """The transports of one System, opened once per URL and shared by the blocks on it (the
    Bioscara joints and an IMU on one I2C bus); closed with the System."""

    def __init__(self) -> None:
        self.open: dict[str, Any] = {}
        self._lock = threading.Lock()  # blocks are configured at the same time

    def shared(self, url: str, opener: Callable[[], Any]) -> Any:
        with self._lock:
            link = self.open.get(url)
            if link is None:
                link = self.open[url] = opener()
            return link

    def close(self) -> None:
        for link in self.open.values():
            link.close()
        self.open.clear()


@dataclass
class Block:
    """What a driver is built from: one ``<ros2_control>`` block and where it is."""

    profile: Profile
    hw: Hardware
    family: Family
    url: str = ""  # "" for a family with no transport
    probe: bool = False  # opened only to look at the bus (detect): silence is no error
    allow_model_mismatch: bool = False
    links: Links = field(default_factory=Links)
    # where the driver keeps its values: the System's one dict, shared by every block (their
    # interface names never collide), so a cycle merges nothing
    values: dict[str, float] = field(default_factory=dict)


class Unsupported(InvalidInput):
    """A verb asked a block for something its family does not offer."""


class Driver:
    extra_states: tuple[str, ...] = ()  # per-joint values beyond the profile's interfaces
    # set by a verb that records the commands (``jog --record``): each move loop calls it
    # once a cycle; None (the default) costs one attribute test a cycle
    on_cycle: CycleHook | None = None
    _follow_plan: dict[str, tuple[bool, ...]] | None = None  # per joint: fields it takes

    def __init__(self, block: Block) -> None:
        self.block = block
        self.profile, self.hw, self.url, self.probe = block.profile, block.hw, block.url, \
            block.probe
        self.values = block.values
        self.warnings: list[str] = []
        self.connected = False
        self.halted = threading.Event()  # set by the System: a move in progress ends now
        self._stats = {"packets": 0, "errors": 0, "reconnects": 0}

    @property
    def stats(self) -> dict[str, int]:
        """packets, errors, reconnects: the block's communication statistics."""
        return self._stats

    # -- lifecycle ---------------------------------------------------------------------------
    def configure(self) -> None:
        """Open the link and find the device(s); Unreachable when nothing answers."""
        raise NotImplementedError

    def activate(self) -> None:
        """Ready for commands (most devices need nothing more than configure)."""

    def start_read(self) -> None:
        """Send this cycle's read request, so that blocks on different links wait for their
        replies at the same time; ``read`` then takes the reply. Optional."""

    def read(self) -> dict[str, float]:
        """The state interfaces (and extras) by name, after one exchange with the device."""
        raise NotImplementedError

    def write(self, commands: dict[str, float]) -> None:
        """Command interfaces by name."""
        for name, value in commands.items():
            self.set_command(name, value)

    def set_command(self, name: str, value: float) -> None:
        raise Unsupported(f"{self.hw.name} takes no command {name}")

    def stop(self) -> None:
        """The safe state (duty 0, stop and disable, torque as found) of what this session
        commanded: a device it never commanded is left as it is."""

    def make_safe(self) -> None:
        """The safe state whatever this session sent: after another process that commanded
        the device was killed before its own stop."""
        self.stop()

    def deactivate(self) -> None:
        self.stop()

    def cleanup(self) -> None:
        """Release the link."""

    # -- what connect and the loops use --------------------------------------------------------
    def round_trip(self) -> None:
        """The smallest exchange with the device: what `connect` times."""
        self.read()

    def comm_loops(self) -> list[CommLoop]:
        """Bus loops that run at their own rates inside the verb's cycle."""
        return []

    # -- capabilities (declared in the family's descriptor) ------------------------------------
    def identify(self) -> dict[str, Any]:
        raise Unsupported(f"{self.hw.name} cannot identify")

    def detect(self) -> dict[str, Any]:
        """``{"checks": [{what, profile, device, match}], "summary": str, ...}``; a check
        about one part of the profile names it (``part``: its id in the report) and says
        when it does not answer (``missing``: a failure; other differences warn)."""
        raise Unsupported(f"{self.hw.name} cannot detect")

    def check_motion(self, joints: list[str]) -> None:
        """Raise Refused when these joints may not move now (before anyone is asked)."""

    def effort_cap(self) -> float | None:
        """The largest effort (N·m) this family lets a command ask for, from the profile's
        safety section (a current cap); None: the joints' effort limits alone bound it."""
        return None

    def move(self, targets: dict[str, float], velocity: float | None = None,
             progress: Progress | None = None) -> MoveResult:
        """Send each joint to its target and return once every one has settled (see
        MoveResult), the move's time has run out, or ``halted`` is set."""
        raise Unsupported(f"{self.hw.name} cannot move its joints")

    def follow(self, setpoints: dict[str, Setpoint]) -> None:
        """Send one cycle's recorded setpoints (``replay``) the way this family's move loop
        sent them; the System checked them against the envelope first. By default,
        each field that is one of the joint's command interfaces goes to ``write`` (NaN: not
        commanded); a family whose move sends goals rather than setpoints overrides it."""
        commands = self._follow_plan
        if commands is None:
            commands = self._follow_plan = {
                j.name: tuple(j.command(f) is not None for f in SETPOINT_FIELDS)
                for j in self.hw.joints}
        sent = {f"{joint}/{f}": v for joint, fields in setpoints.items()
                for f, v, ok in zip(SETPOINT_FIELDS, fields, commands.get(joint, ()))
                if ok and v == v}
        if sent:
            self.write(sent)

    def home(self, joints: list[str], force: bool = False,
             progress: HomeProgress | None = None) -> dict[str, str]:
        """A homing routine (joints with a ``home`` command interface, and those the family's
        ``homing_joints`` names): joint → outcome."""
        raise Unsupported(f"{self.hw.name} has no homing routine")

    def tare_ft(self) -> None:
        raise Unsupported(f"{self.hw.name} has no F/T sensors to tare")

    def calibrate_servos(self, half_turn: bool, name: str) -> dict[str, Any]:
        """The servos' calibration in their family's file format: ``text`` (the file), its
        default ``file`` for device ``name``, per part its values (``parts``); with
        ``half_turn``, each servo's present pose is made the middle of its turn first (its
        zero written into the servo)."""
        raise Unsupported(f"{self.hw.name} has no servo calibration")

    # joint calibration (``calibrate joints``): LeRobot's keys → the family's registers
    calibration_registers: ClassVar[dict[str, str]] = {}
    # LeRobot's robot types of a follower and a leader of this family (its calibration file)
    lerobot_types: tuple[str, str] | None = None

    def uncalibrated_joints(self) -> list[str]:
        """The joints whose servo has no homing offset register (a block with no
        ``calibration_registers`` has none at all): calibrate joints refuses them."""
        return [] if self.calibration_registers else [j.name for j in self.hw.joints]

    def joint_calibration(self) -> dict[str, dict[str, int]]:
        """Per joint, the calibration its servo holds as LeRobot's file has it: ``id``,
        ``drive_mode``, ``homing_offset``, ``range_min``, ``range_max`` (steps, as in the
        registers), and its ``resolution`` (steps a turn)."""
        raise Unsupported(f"{self.hw.name} has no joint calibration")

    def middle_offsets(self) -> dict[str, int]:
        """Per joint, the homing offset that makes the present pose read the middle of the
        turn (LeRobot's half-turn homing); nothing written. A DeviceError naming a joint whose
        offset would be beyond its register's reach."""
        raise Unsupported(f"{self.hw.name} has no joint calibration")

    def positions_under(self, offsets: dict[str, int],
                        held: dict[str, int]) -> dict[str, int]:
        """The present positions (steps, one read) as they would read with ``offsets`` in
        the servos in place of the ``held`` ones; a joint that does not answer is left out."""
        raise Unsupported(f"{self.hw.name} has no joint calibration")

    def write_joint_calibration(self, values: dict[str, dict[str, int]]) -> None:
        """Write each joint's ``homing_offset``, ``range_min`` and ``range_max`` into its
        servo (its torque off, its EEPROM unlocked and locked again where it has a lock)."""
        raise Unsupported(f"{self.hw.name} has no joint calibration")

    def register_items(self) -> list[str]:
        raise Unsupported(f"{self.hw.name} has no registers")

    def read_registers(self, joint: str, items: list[str]) -> dict[str, Any]:
        raise Unsupported(f"{self.hw.name} has no registers")

    def write_register(self, joint: str, item: str, value: int) -> int:
        raise Unsupported(f"{self.hw.name} has no registers")

    def set_torque(self, joints: list[str], on: bool) -> list[str]:
        raise Unsupported(f"{self.hw.name} has no torque switch")

    def reboot(self, joints: list[str]) -> list[str]:
        raise Unsupported(f"{self.hw.name} cannot reboot")

    def config_read(self) -> dict[str, dict[str, dict[str, Any]]]:
        """Every configurable value of the block, part → item → entry. An entry holds
        ``value`` (int, float, str, bool or None) and ``access`` ("RW", "R", or "profile":
        set from the profile at each start), and may hold ``unit``, ``area``, ``meaning``,
        ``note``, ``min``/``max`` (an integer's range), ``state`` (a reading or a command,
        never compared), ``fixed`` (writable, but restore leaves it: why), ``needs`` (written
        only with this permission, refused otherwise: "torque-off") and ``opt_in`` (written
        only with this permission, skipped otherwise: "home-offset")."""
        raise Unsupported(f"{self.hw.name} cannot report its configuration")

    def config_write(self, changes: dict[str, dict[str, Any]],
                     allow: frozenset[str] = frozenset()) -> dict[str, dict[str, Any]]:
        """Write these values (part → item → value) in the order the device requires, with
        the permissions in ``allow``; returns part → item → the value read back. Raises
        Refused, before writing anything, when a change needs a permission not given."""
        raise Unsupported(f"{self.hw.name} cannot write its configuration")

    # -- shared by the bus drivers -------------------------------------------------------------
    def roll_call(self, missing: list[str], answered: bool, parts: str, hint: str) -> None:
        """After configure's pings of a bus: nothing answering is unreachable (exit 4) unless
        the verb only probes the bus (``detect``); parts missing are a warning."""
        if not answered and not self.probe:
            raise Unreachable(f"no {parts} of {self.hw.name!r} answers on {self.url}",
                              hint=hint)
        if missing:
            self.warnings.append(f"{self.hw.name}: no answer from {', '.join(missing)}")
