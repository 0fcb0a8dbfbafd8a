"""Every deltoctl verb and sub-command, declared once: the module of ``deltoctl.cli`` that adds
it, what it does to the robot (reads, actuates an output or a setting, moves a joint), whether
a robot's agent runs it for a remote caller, and the example its help shows.

The CLI loads verbs and teaches their help from this table; the fleet agent judges a remote
command line by it. A command's effect may depend on its options (``report`` actuates: it
tares the F/T sensors and runs the IMUs' self-tests; with ``--yes`` it moves the joints): the
options a command line gives, as the CLI parses them, raise its effect. Fail-closed: a command
whose effect is not declared here counts as one that moves the robot. No typer or click here:
the fleet reads the table without loading the CLI, and finds which command a command line runs
through the resolver the CLI provides (``provide_resolver``), the very parse that will run it.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Collection, Mapping, Sequence

READS, ACTUATES, MOVES = "reads", "actuates", "moves"
_RANK = {READS: 0, ACTUATES: 1, MOVES: 2}  # anything else ranks as MOVES
UNRESOLVED = "?"  # the path of a command line no resolver could read: it counts as moving


class Verb:
    """A verb or a sub-command. A group's own effect is what it does with no sub-command
    (show its help). ``when``: an option's spellings (``("--yes", "-y")``, global options
    too) → the effect of the command when it is given. (A plain class: the table is read at
    every start-up.)"""

    __slots__ = ("effect", "example", "module", "remote", "stage", "subs", "when")

    def __init__(self, effect: str, example: str = "", module: str = "", remote: bool = True,
                 subs: Mapping[str, Verb] | None = None,
                 when: Mapping[tuple[str, ...], str] | None = None, stage: str = "") -> None:
        self.effect = effect
        self.example = example
        self.module = module  # top-level verbs: the deltoctl.cli module whose register(app) adds it
        self.remote = remote
        self.stage = stage  # top-level verbs: one of STAGES, the panel of the root's help
        self.subs: Mapping[str, Verb] = subs or {}
        self.when: Mapping[tuple[str, ...], str] = when or {}

    def effects(self) -> frozenset[str]:
        """Every effect the command may have, with or without its options."""
        return frozenset((self.effect, *self.when.values()))

    def effect_given(self, given: Collection[str]) -> str:
        """The effect with the options ``given`` (their spellings): the strongest of its own
        and of theirs."""
        found = [e for spellings, e in self.when.items() if set(spellings) & set(given)]
        return max((self.effect, *found), key=lambda e: _RANK.get(e, 2))


YES = ("--yes", "-y")  # the global option that confirms motion without asking

# the stages of a bring-up, in the order the root's help shows their verbs
LIFECYCLE, DATA, CONFIGURATION, TOOLS, REMOTE = (
    "lifecycle", "data", "configuration", "tools", "remote")
STAGES = (LIFECYCLE, DATA, CONFIGURATION, TOOLS, REMOTE)
TITLES = {LIFECYCLE: "Lifecycle: reach, identify, move and actuate a device",
          DATA: "Data: stream, record, replay and read recordings",
          CONFIGURATION: "Configuration: profiles, device settings and registers",
          TOOLS: "Tools", REMOTE: "Remote: robots over Zenoh"}


TABLE: dict[str, Verb] = {
    "config": Verb(READS, "deltoctl -p mh5 config snapshot", "config_cmd", stage=CONFIGURATION,
                   subs={
        "snapshot": Verb(READS, "deltoctl -p mh5 config snapshot -o mh5.yaml"),
        "diff": Verb(READS, "deltoctl -p mh5 config diff mh5.yaml"),
        "restore": Verb(ACTUATES, "deltoctl -p mh5 config restore mh5.yaml --allow torque-off"),
    }),
    "info": Verb(READS, "deltoctl info run.mcap --json", "data_cmd", stage=DATA),
    "plot": Verb(READS, "deltoctl plot run.mcap 'rj_dg_1_*/position' --out plot.png",
                 "data_cmd", stage=DATA),
    "profile": Verb(READS, "deltoctl profile show dg-5f-right rj_dg_1_2", "profile_cmd",
                    stage=CONFIGURATION, subs={
        "list": Verb(READS, "deltoctl profile list --json"),
        "show": Verb(READS, "deltoctl profile show dg-5f-right rj_dg_1_2"),
        "validate": Verb(READS, "deltoctl profile validate my_robot.yaml --strict"),
        "import": Verb(READS, "deltoctl profile import robot.urdf.xacro -o robot.yaml"),
        "export": Verb(READS, "deltoctl profile export dg-5f-right --format xacro -o dg5f.xacro"),
        "tests": Verb(READS, "deltoctl profile tests mh5 -o tests/"),
    }),
    "connect": Verb(READS, "deltoctl -p dg-5f-right -t tcp://169.254.186.72:502 connect",
                    "device_cmd", stage=LIFECYCLE),
    "identify": Verb(READS, "deltoctl -p dg-5f-right --sim identify --json", "device_cmd",
                     stage=LIFECYCLE),
    "detect": Verb(READS, "deltoctl -p mh5 --hardware upper_body detect", "device_cmd",
                   stage=LIFECYCLE),
    "home": Verb(MOVES, "deltoctl -p bioscara-arm home -j j1 --yes", "motion_cmd", stage=LIFECYCLE),
    "jog": Verb(MOVES, "deltoctl -p dg-5f-right jog rj_dg_2_2 5deg -y", "motion_cmd",
                stage=LIFECYCLE),
    "calibrate": Verb(READS, "deltoctl -p dg-5f-right calibrate ft", "calibrate_cmd",
                      stage=LIFECYCLE, subs={
        "ft": Verb(ACTUATES, "deltoctl -p dg-5f-right calibrate ft --samples 200"),
        "imu": Verb(ACTUATES, "deltoctl -p mh5 calibrate imu --tumble"),  # its self-test
        "servos": Verb(READS, "deltoctl -p so101-follower calibrate servos --half-turn",
                       when={("--half-turn",): ACTUATES}),
        "joints": Verb(ACTUATES, "deltoctl -p koch-arm calibrate joints --allow homing-offset "
                       "--allow min-position-limit --allow max-position-limit"),
    }),
    "gpio": Verb(READS, "deltoctl -p rrbot-gpio gpio set flange_vacuum/vacuum on", "device_cmd",
                 stage=LIFECYCLE, subs={
        "get": Verb(READS, "deltoctl -p dg-5f-right gpio get --json"),
        "set": Verb(ACTUATES, "deltoctl -p rrbot-gpio gpio set flange_vacuum/vacuum on"),
    }),
    "stream": Verb(READS, "deltoctl -p dg-5f-right stream --rate 50 -i 'rj_dg_1_*/position'",
                   "device_cmd", stage=DATA),
    "record": Verb(READS, "deltoctl -p mh5 record run.mcap --duration 60 --foxglove",
                   "record_cmd", stage=DATA),
    # on the profile's simulators; with --device it moves the robot along the recording
    "replay": Verb(READS, "deltoctl replay fault.mcap --tolerance 1deg --json", "replay_cmd",
                   stage=DATA, when={("--device",): MOVES}),
    # the acceptance sequence: with --yes its motion checks move the joints
    "report": Verb(READS, "deltoctl -p dg-5f-right report -o acceptance.html --record 5",
                   "report_cmd", stage=LIFECYCLE, when={YES: MOVES}),
    "torque": Verb(ACTUATES, "deltoctl -p mh5 torque off left_arm", "servo_cmd",
                   stage=LIFECYCLE),
    "reboot": Verb(ACTUATES, "deltoctl -p mh5 reboot head_y", "servo_cmd", stage=LIFECYCLE),
    "register": Verb(READS, "deltoctl -p mh5 register get head_y present_temperature",
                     "servo_cmd", stage=CONFIGURATION, subs={
        "get": Verb(READS, "deltoctl -p mh5 register get head_y present_temperature"),
        "set": Verb(ACTUATES, "deltoctl -p mh5 register set head_y return_delay_time 0"),
    }),
    # the agent's own verbs, and a benchmark that would load the robot's computer while it
    # moves, do not run remotely
    "sim": Verb(READS, "deltoctl sim serve mh5 --missing head_y", "sim_cmd", stage=TOOLS,
                remote=False,
                subs={"serve": Verb(READS, "deltoctl sim serve dg-5f-right --firmware 2.7")}),
    "bench": Verb(READS, "deltoctl bench loop --duration 2", "bench_cmd", stage=TOOLS,
                  remote=False, subs={
        "loop": Verb(READS), "dynamixel": Verb(READS), "feetech": Verb(READS),
        "i2c": Verb(READS),
    }),
    "ports": Verb(READS, "deltoctl ports --json", "ports_cmd", stage=TOOLS),
    "scan": Verb(READS, "deltoctl scan /dev/ttyUSB0 --json", "scan_cmd", stage=TOOLS),
    # writes each servo's ID and baud rate (asks for each part to be connected alone)
    "setup": Verb(ACTUATES, "deltoctl -p koch-arm setup shoulder_pan --yes", "setup_cmd",
                  stage=CONFIGURATION),
    "doctor": Verb(READS, "deltoctl -p dg-5f-right -t tcp://169.254.186.72:502 doctor",
                   "doctor_cmd", stage=TOOLS,
                   when={("--write-udev-rule",): ACTUATES}),  # the host's udev
    "completion": Verb(READS, "deltoctl completion bash > "
                              "~/.local/share/bash-completion/completions/deltoctl",
                       "completion_cmd", stage=TOOLS, remote=False),
    "help": Verb(READS, "deltoctl help exit-codes", "help_cmd", stage=TOOLS),
    "agent": Verb(READS, "deltoctl -p dg-5f-right agent --name hand-1 --sim", "agent_cmd",
                  stage=REMOTE, remote=False),
    "fleet": Verb(READS, "deltoctl fleet run --robots 'hand-*' identify", "fleet_cmd",
                  stage=REMOTE, remote=False, subs={
        "list": Verb(READS, "deltoctl --zenoh-config fleet.json5 fleet list --json"),
        "run": Verb(MOVES, "deltoctl fleet run --robots 'hand-*' identify --json"),
    }),
}


def lookup(path: str) -> Verb | None:
    """The entry of a command path (``jog``, ``gpio set``), or None when it has none."""
    words = path.split()
    entry = TABLE.get(words[0]) if words else None
    for word in words[1:]:
        entry = entry.subs.get(word) if entry is not None else None
    return entry


class Command(str):
    """A command path (``gpio set``) as a command line runs it: the string is the path, and
    ``given`` the spellings of the options that command line gives (``--yes``, ``-y``)."""

    given: frozenset[str]

    def __new__(cls, path: str, given: Collection[str] = ()) -> Command:
        command = super().__new__(cls, path)
        command.given = frozenset(given)
        return command


def effect(path: str) -> str:
    """What a command does to the robot — with a Command, as its options make it; MOVES for
    one the table does not declare."""
    entry = lookup(path)
    if entry is None:
        return MOVES
    return entry.effect_given(path.given) if isinstance(path, Command) else entry.effect


def describe(path: str) -> str:
    """The effect of a command in words, for its help: ``reads the robot; moves with
    --yes/-y``."""
    entry = lookup(path)
    if entry is None:
        return "moves the robot (not declared)"
    words = {READS: "reads the robot", ACTUATES: "actuates an output or a setting",
             MOVES: "moves the robot"}
    text = words.get(entry.effect, words[MOVES])
    for spellings, then in entry.when.items():
        if then != entry.effect:
            text += f"; {then if then in _RANK else MOVES} with {'/'.join(spellings)}"
    return text


def remote(path: str) -> bool:
    """Whether a robot's agent runs the command for a remote caller."""
    entry = TABLE.get(path.split(" ", 1)[0])
    return entry.remote if entry is not None else True  # undeclared: judged as motion


class Effects:
    """The command paths of some effects, as a set: ``"jog" in MOTION``; a Command (what a
    command line runs) is in it by the effect its options give it. A path the table does not
    declare is in every set that holds MOVES (fail-closed)."""

    def __init__(self, *effects: str) -> None:
        self.effects = frozenset(effects)

    def __contains__(self, path: object) -> bool:
        return isinstance(path, str) and effect(path) in self.effects

    def declared(self) -> frozenset[str]:
        """The declared paths that may have one of these effects (with some option)."""
        return frozenset(p for p, v in walk() if v.effects() & self.effects)


def walk() -> list[tuple[str, Verb]]:
    """Every declared command path and its entry, verbs before their sub-commands."""
    out: list[tuple[str, Verb]] = []

    def visit(prefix: str, entries: Mapping[str, Verb]) -> None:
        for name, entry in entries.items():
            path = f"{prefix} {name}".strip()
            out.append((path, entry))
            visit(path, entry.subs)

    visit("", TABLE)
    return out


def modules() -> dict[str, str]:
    """verb → the module of deltoctl.cli that adds it."""
    return {name: entry.module for name, entry in TABLE.items()}


def by_stage() -> list[str]:
    """The verbs in the order of their stages of a bring-up (STAGES), table order within
    one; a verb of no stage last."""
    def rank(name: str) -> int:
        stage = TABLE[name].stage
        return STAGES.index(stage) if stage in STAGES else len(STAGES)

    return sorted(TABLE, key=rank)


def examples() -> dict[str, str]:
    """command path → the example its help shows."""
    return {path: entry.example for path, entry in walk() if entry.example}


# -- which command a command line runs --------------------------------------------------------

# a command line → (its command path, the spellings of the options it gives)
Resolver = Callable[[Sequence[str]], tuple[tuple[str, ...], Collection[str]]]
_resolver: list[Resolver] = []
_lock = threading.Lock()  # the CLI's command tree loads verbs as it resolves: one at a time


def provide_resolver(resolver: Resolver) -> None:
    """The CLI's resolution of a command line into its command path (``("gpio", "set")``)
    and the options it gives, global ones too (``{"--yes", "-y"}``): click's own, as the
    command line will be parsed when it runs."""
    _resolver[:] = [resolver]


def resolve(args: Sequence[str]) -> Command:
    """The command (``gpio set``) a command line runs and the options it gives, by the CLI's
    own parse; an empty path when it names no verb, UNRESOLVED without a CLI to resolve
    it."""
    if not _resolver:
        return Command(UNRESOLVED)
    with _lock:
        path, given = _resolver[0](args)
    return Command(" ".join(path), given)
