"""The global options every verb shares, the profile they select, and the keys of the root
context's meta the verbs read."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import typer

from deltoctl.errors import InvalidInput

TEACH = "deltoctl.teach"  # ctx.meta key: this run shows help or completes, so verbs are taught
ARGV = "deltoctl.argv"  # ctx.meta key: the command line, global options first
DOCUMENT = "deltoctl.document"  # ctx.meta key: the verb's JSON document, written as it exits

if TYPE_CHECKING:
    from deltoctl.profile.model import Profile


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


def options(ctx: typer.Context) -> Options:
    root = ctx.find_root()
    if not isinstance(root.obj, Options):
        root.obj = Options()
    return root.obj


def parse_pairs(items: list[str], sep: str, what: str, example: str) -> dict[str, str]:
    pairs: dict[str, str] = {}
    for item in items:
        key, found, value = item.partition(sep)
        if not found or not key:
            raise InvalidInput(f"{what} {item!r} is not of the form {example}")
        pairs[key] = value
    return pairs
