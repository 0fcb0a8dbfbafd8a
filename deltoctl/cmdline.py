"""The grammar of a deltoctl command line that is not the verbs': which global options there
are, whether each takes a value, and where they may stand; and their values once parsed
(Options). The CLI parses with it, and the fleet agent judges a remote command line with the
same rules."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from deltoctl.errors import InvalidInput

if TYPE_CHECKING:
    from deltoctl.profile.model import Profile

# option spellings → whether they take a value: the root command's options (cli/main.py), which
# the fleet reads without loading the CLI; a test holds the two equal
GLOBAL_OPTIONS: dict[str, bool] = {
    "--profile": True, "-p": True, "--target": True, "-t": True, "--arg": True,
    "--package-path": True, "--hardware": True, "--log-file": True, "--xacro": False,
    "--sim": False, "--sim-fresh": False, "--sim-option": True, "--json": False, "--yes": False,
    "-y": False, "--verbose": False, "-v": False, "--quiet": False, "-q": False, "--robot": True,
    "--zenoh-config": True,
}
# single letters of the global short options, for clusters such as -yq or -vvp NAME
SHORT_FLAGS = frozenset("yqv")
SHORT_VALUED = frozenset("pt")


def split_cluster(arg: str) -> tuple[str, str, bool]:
    """A short-option cluster (``-yq``, ``-yn5``, ``-5deg``) → (its global options, the rest,
    whether the global part still needs the next argument as its value).

    The global part runs from the start up to the first letter that is not a global short
    option; a global option that takes a value ends it, its value attached or next."""
    if len(arg) < 2 or arg[0] != "-" or arg[1] == "-":
        return "", arg, False
    for i, letter in enumerate(arg[1:], start=1):
        if letter in SHORT_VALUED:
            return arg, "", i == len(arg) - 1
        if letter not in SHORT_FLAGS:
            return (arg[:i] if i > 1 else ""), "-" + arg[i:], False
    return arg, "", False


def needs_value(arg: str) -> bool:
    """Whether a global option before the verb takes the next argument (``-p NAME``,
    ``-yp NAME``, not ``--profile=NAME``)."""
    if arg.startswith("--"):
        return GLOBAL_OPTIONS.get(arg, False)
    return split_cluster(arg)[2]


def hoist_global_options(args: list[str]) -> list[str]:
    """Move global options found after the verb to just before it."""
    head: list[str] = []  # options before the verb
    hoisted: list[str] = []  # global options after it
    tail: list[str] = []  # the verb and everything else
    i = 0
    while i < len(args):
        arg = args[i]
        if tail and arg == "--":
            tail.extend(args[i:])
            break
        if not tail and not arg.startswith("-"):
            tail.append(arg)  # the verb
        elif not tail:
            head.append(arg)
            if needs_value(arg) and i + 1 < len(args):
                head.append(args[i + 1])
                i += 1
        elif arg.startswith("--"):
            name = arg.split("=", 1)[0]
            if name not in GLOBAL_OPTIONS:
                tail.append(arg)
            else:
                hoisted.append(arg)
                if GLOBAL_OPTIONS[name] and "=" not in arg and i + 1 < len(args):
                    hoisted.append(args[i + 1])
                    i += 1
        else:
            ours, rest, takes_value = split_cluster(arg)
            if ours:
                hoisted.append(ours)
                if takes_value and i + 1 < len(args):
                    hoisted.append(args[i + 1])
                    i += 1
            if rest:
                tail.append(rest)
        i += 1
    return head + hoisted + tail


def first_argument(args: list[str], takes_value: set[str]) -> int | None:
    """Where the first argument stands among a command's ``args`` (after ``--``, or the
    first word that is neither an option nor the value of one in ``takes_value``)."""
    i = 0
    while i < len(args):
        arg = args[i]
        if arg == "--":
            return i + 1 if i + 1 < len(args) else None
        if not arg.startswith("-") or arg == "-":
            return i
        i += 2 if arg in takes_value else 1
    return None


def given_options(ctx: Any) -> list[str]:
    """The spellings of the options a context's command line (or environment) gave: not
    their defaults, nor a flag given as off."""
    from typer._click.core import ParameterSource

    given: list[str] = []
    for param in ctx.command.params:
        if param.param_type_name != "option":
            continue
        source = ctx.get_parameter_source(param.name) if param.name else None
        if source in (None, ParameterSource.DEFAULT, ParameterSource.DEFAULT_MAP):
            continue
        if ctx.params.get(param.name) is not False:
            given += getattr(param, "opts", [])
    return given


class Options:
    """The parsed global options (a plain class: dataclasses cost start-up time)."""

    def __init__(
        self,
        profile: str | None = None,
        target: list[str] | None = None,
        sim: bool = False,
        sim_fresh: bool = False,
        sim_options: list[str] | None = None,
        json: bool = False,
        yes: bool = False,
        verbose: int = 0,
        quiet: bool = False,
        xacro_args: dict[str, str] | None = None,
        package_paths: dict[str, str] | None = None,
        hardware: list[str] | None = None,
        xacro: bool = False,
        robot: str | None = None,
        zenoh_config: str | None = None,
    ) -> None:
        self.profile = profile
        self.target = target or []
        self.sim = sim
        self.sim_fresh = sim_fresh  # --sim-fresh: never a running 'sim serve'
        self.sim_options = sim_options or []  # --sim-option NAME=VALUE, as given
        self.json = json
        self.yes = yes
        self.verbose = verbose
        self.quiet = quiet
        self.xacro_args = xacro_args or {}
        self.package_paths = package_paths or {}
        self.hardware = hardware or []  # --hardware: the blocks a verb works on (all if empty)
        self.xacro = xacro  # run xacro on a file not named .xacro
        self.robot = robot  # --robot: the verb runs on that robot's agent, over Zenoh
        self.zenoh_config = zenoh_config  # --zenoh-config: endpoints and TLS of the session

    def load_profile(self, spec: str | None = None) -> Profile:
        from deltoctl.profile.catalog import load_profile

        spec = spec or self.profile
        if not spec:
            raise InvalidInput("no profile given: pass --profile NAME|PATH (or set "
                               "DELTOCTL_PROFILE); 'deltoctl profile list' shows the catalog")
        return load_profile(spec, self.xacro_args, self.package_paths, xacro=self.xacro)

    def sim_of(self, prof: Profile) -> Any:
        """What ``open_robot(sim=…)`` takes: --sim, with its --sim-option faults checked."""
        if not (self.sim and self.sim_options):
            return self.sim
        from deltoctl.sim.serve import options_given

        return options_given(self.sim_options, "--sim-option", prof, self.hardware)


def parse_pairs(items: list[str], sep: str, what: str, example: str) -> dict[str, str]:
    pairs: dict[str, str] = {}
    for item in items:
        key, found, value = item.partition(sep)
        if not found or not key:
            raise InvalidInput(f"{what} {item!r} is not of the form {example}")
        pairs[key] = value
    return pairs
