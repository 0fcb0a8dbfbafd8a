"""The agent's side on the robot's computer: its name and directory, the files it keeps to
itself, when it allows motion, the robot's links it serves (with ``--sim``, a simulator's), and
its warm verb processes (the zygote, the spares) that run a command line as ``deltoctl`` does.

What runs a command line (``deltoctl``'s own entry) and what a verb imports come from the
caller of these functions: the fleet knows nothing of the command line above it."""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Callable, Iterable, Iterator
from typing import TYPE_CHECKING, Any

from deltoctl.errors import InvalidInput

if TYPE_CHECKING:
    from deltoctl.cmdline import Options
    from deltoctl.fleet.agent import Agent

AGENT_RECORD_MAX = 3600.0  # s: the longest record an agent writes in its own directory
# runs one command line (without ``deltoctl``) as ``deltoctl`` does; returns its exit code
Run = Callable[[list[str]], int]
SIMULATED = "simulated"  # after the profile on a verb process's command line: agent --sim


def default_name() -> str:
    """This computer's host name as a robot's name."""
    import re
    import socket

    name = re.sub(r"[^A-Za-z0-9_.-]", "-", socket.gethostname().split(".")[0])
    return name.strip("-.")[:63] or "robot"


def workdir(given: str | None, robot: str) -> str:
    """Where remote verbs run: ``given`` (--workdir, which must exist), or the agent's own."""
    if given is None:
        return os.path.abspath(own_workdir(robot))
    if not os.path.isdir(given):
        raise InvalidInput(f"--workdir {given}: no such directory")
    return os.path.abspath(given)


def own_workdir(robot: str) -> str:
    """The agent's own directory for remote verbs: $XDG_STATE_HOME/deltoctl/agent/ROBOT
    (~/.local/state/… by default), made if need be; none of the agent's files is there."""
    state = os.environ.get("XDG_STATE_HOME", "")
    if not os.path.isabs(state):
        state = os.path.join(os.path.expanduser("~"), ".local", "state")
    path = os.path.join(state, "deltoctl", "agent", robot)
    try:
        os.makedirs(path, mode=0o700, exist_ok=True)
    except OSError as exc:
        raise InvalidInput(f"cannot make the agent's directory {path}: "
                           f"{exc.strerror or exc}", "pass --workdir DIR") from None
    return path


def profile_files(profile: str | None, xacro: bool) -> list[str]:
    """The files the robot's profile (--profile, read with xacro or not) was read from: the
    profile, and what xacro included."""
    from deltoctl.profile.catalog import resolve, runs_xacro

    path = resolve(profile) if profile else None
    if path is None:
        return []
    files = [str(path)]
    if runs_xacro(path, xacro):
        from deltoctl.profile.xacro_runner import included_files

        files += included_files()
    return files


def motion_rule(config: object, allow_unauthenticated: bool) -> tuple[bool, str]:
    """(motion allowed, why not): only over mutual TLS, or on a loopback-only lab bench
    with --allow-unauthenticated-motion."""
    from deltoctl.fleet import config as zconfig

    if zconfig.mutual_tls(config):
        return True, ""
    if allow_unauthenticated:
        if not zconfig.loopback_only(config):
            raise InvalidInput("--allow-unauthenticated-motion takes loopback endpoints only "
                               f"(tcp/127.0.0.1:PORT); this agent is {zconfig.describe(config)}",
                               "configure mutual TLS to allow motion over a network")
        return True, ""
    return False, ("motion and outputs need an authenticated caller, and this agent's Zenoh "
                   "links are not all mutual TLS")


def check_deadline(deadline: float) -> None:
    """Seconds without the caller's heartbeat before a verb is interrupted: 0.1 to 10."""
    import math

    if not (math.isfinite(deadline) and 0.1 <= deadline <= 10):
        raise InvalidInput(f"--deadline must be 0.1 to 10 seconds, got {deadline:g}")


def profile_spec(given: str | None, name: str) -> str:
    """How the verb processes name the profile: its file's absolute path, or its name."""
    spec = given or name
    return os.path.abspath(spec) if os.path.exists(spec) else spec


def verb_links(spec: str, targets: Iterable[str], xacro_args: dict[str, str],
               package_paths: dict[str, str], hardware: Iterable[str],
               xacro: bool) -> list[str]:
    """The global options that point a verb at the robot: its profile, its links."""
    links = ["-p", spec, *(f"--target={t}" for t in targets)]
    links += [f"--arg={k}:={v}" for k, v in xacro_args.items()]
    links += [f"--package-path={k}={v}" for k, v in package_paths.items()]
    links += [f"--hardware={h}" for h in hardware]
    return links + (["--xacro"] if xacro else [])


def check_record_duration(duration: float | None) -> None:
    """A record the agent runs (``fleet run record``, its file in the agent's directory) has a
    duration of at most AGENT_RECORD_MAX, so that no caller fills the robot's computer's
    disk."""
    if duration is None or duration > AGENT_RECORD_MAX:
        raise InvalidInput(f"a record written on the robot's computer needs --duration of at "
                           f"most {AGENT_RECORD_MAX:g} s"
                           + ("" if duration is None else f", got {duration:g}"),
                           "or write the file on this computer: deltoctl --robot ROBOT record "
                           "FILE (Ctrl-C ends it)")


def zenoh_config(option: str | None, listen: list[str] | None,
                connect: list[str] | None) -> tuple[Any, list[str]]:
    """The agent's Zenoh configuration (the file ``option`` or $DELTOCTL_ZENOH_CONFIG names,
    ``listen`` and ``connect`` replacing its endpoints), and its files: that file, and the
    certificates and keys it names."""
    from deltoctl.fleet import config as zconfig

    path = zconfig.config_file(option)
    config = zconfig.load(path, "agent", listen, connect)
    return config, [*([path] if path else []), *zconfig.tls_files(config)]


@contextlib.contextmanager
def served_links(links: list[str], sim: bool) -> Iterator[list[str]]:
    """The global options that point a verb at the robot (``links``); with ``sim``, at the
    simulator started here from them (stopped on the way out)."""
    from deltoctl.fleet.agent import start_simulator, stop_process

    if not sim:
        yield links
        return
    simulator, served = start_simulator(
        [sys.executable, "-m", "deltoctl", *links, "sim", "serve", "--json", "--private"],
        env={k: v for k, v in os.environ.items() if not k.startswith("DELTOCTL_")})
    try:
        links = [a for a in links if not a.startswith("--target=")]
        yield links + [f"--target={bus}={url}" for bus, url in served["buses"].items()]
    finally:
        stop_process(simulator)


def run_agent(opts: Options, name: str | None,
              endpoints: tuple[list[str] | None, list[str] | None], deadline: float,
              allow_unauthenticated: bool, given_workdir: str | None, runners: tuple[str, str],
              check: Callable[[str, list[str]], None]) -> None:
    """Serve the robot of the global options ``opts`` (profile, targets or --sim, Zenoh
    configuration) as ``name`` until a signal stops the agent. ``endpoints``: listen and
    connect, replacing the configuration's; ``runners``: the Python code of the zygote and of
    a spare verb process; ``check``: what the agent checks in a remote command line."""
    from deltoctl.fleet import check_robot
    from deltoctl.fleet.agent import Agent
    from deltoctl.profile.exporter import to_yaml

    robot = check_robot(name or default_name())
    check_deadline(deadline)
    directory = workdir(given_workdir, robot)
    profile = opts.load_profile()  # a bad profile stops here, with its file:line
    own_files = profile_files(opts.profile, opts.xacro)
    spec = profile_spec(opts.profile, profile.name)
    config, config_files = zenoh_config(opts.zenoh_config, *endpoints)
    motion, why_not = motion_rule(config, allow_unauthenticated)
    links = verb_links(spec, opts.target, opts.xacro_args, opts.package_paths, opts.hardware,
                       opts.xacro)
    with served_links(links, opts.sim) as links:
        marks = [SIMULATED] if opts.sim else []
        zygote, spare = ([sys.executable, "-c", code, spec, *marks] for code in runners)
        serve(Agent(robot, spec, profile.name, links, (zygote, spare), config, motion, why_not,
                    deadline, directory, simulated=opts.sim, profile_yaml=to_yaml(profile),
                    own_files=own_files + config_files, check=check))


def serve(node: Agent) -> None:
    """Serve until a signal stops the agent; what it serves is said once it is up."""
    from deltoctl.fleet import config as zconfig
    from deltoctl.fleet.agent import log, signals_stop

    signals_stop(node.stop)
    try:
        node.start()
        log(f"robot {node.robot}: serving {node.profile_name} on Zenoh "
            f"({zconfig.describe(node.config)}); motion "
            f"{'allowed' if node.motion_allowed else 'refused: ' + node.why_not}")
        node.serve()
        log(f"robot {node.robot}: stopping")
    finally:
        node.close()


def warm(spec: str, modules: Iterable[str], simulated: Callable[[], None] | None = None) -> None:
    """What every verb imports (``modules``), and the robot's profile (``spec``) and drivers:
    loaded once. ``simulated`` (``agent --sim``) marks every block the verbs open simulated."""
    import importlib

    for module in modules:
        importlib.import_module(module)
    if simulated is not None:
        simulated()
    with contextlib.suppress(Exception):  # only a head start: the verb reports any problem
        from deltoctl import registry
        from deltoctl.profile.catalog import load_profile

        prof = load_profile(spec)
        for hw in prof.hardware:
            family = registry.of_block(prof.family_of(hw), hw.plugin)
            if family is not None:
                family.driver_class()


def warm_process(spec: str, modules: Iterable[str], simulated: Callable[[], None] | None,
                 run: Run, zygote_socket: int | None = None) -> None:
    """An agent's warm verb process, ``warm`` first: its zygote, given the socket to the agent
    (one child forked per verb, which ``run``s its command line: deltoctl/fleet/forks.py), else
    a spare."""
    from deltoctl.fleet.forks import serve as serve_forks

    warm(spec, modules, simulated)
    if zygote_socket is None:
        spare(run)
    else:
        serve_forks(zygote_socket, run)


def spare(run: Run) -> None:
    """A deltoctl process started ahead by the agent (when it has no zygote), warm: it waits
    for its command line (one JSON list) on stdin, then ``run``s it and exits with its code."""
    import json
    import signal
    import threading
    import time

    parent = os.getppid()
    line = sys.stdin.readline()
    if not line:
        return

    def orphaned() -> None:  # the agent is gone: stop as on Ctrl-C (motion stops)
        while os.getppid() == parent:
            time.sleep(0.05)
        os.kill(os.getpid(), signal.SIGINT)

    threading.Thread(target=orphaned, daemon=True).start()
    null = os.open(os.devnull, os.O_RDONLY)
    os.dup2(null, 0)
    sys.exit(run(json.loads(line)))
