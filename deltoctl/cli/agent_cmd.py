"""``deltoctl agent``: serve this computer's robot over Zenoh, so that any verb runs from
another computer (``deltoctl --robot ROBOT VERB …``, ``deltoctl fleet …``)."""

from __future__ import annotations

import contextlib
import math
import os
import sys
from collections.abc import Iterator
from typing import TYPE_CHECKING, Annotated

import typer

from deltoctl.cli.context import Options, options
from deltoctl.errors import InvalidInput

if TYPE_CHECKING:
    from deltoctl.fleet.agent import Agent

# the agent's verb processes: argv[1] the profile, then SIMULATED when --sim serves the robot
# (the zygote's socket comes last)
SPARE = ("import sys; from deltoctl.cli.agent_cmd import spare; "
         "spare(sys.argv[1], 'simulated' in sys.argv[2:])")
ZYGOTE = ("import sys; from deltoctl.cli.agent_cmd import zygote; "
          "zygote(sys.argv[1], int(sys.argv[-1]), 'simulated' in sys.argv[2:-1])")
SIMULATED = "simulated"


def register(root: typer.Typer) -> None:
    root.command("agent")(agent)


def _links(opts: Options, spec: str) -> list[str]:
    """The global options that point a verb at the robot: its profile, its links."""
    links = ["-p", spec, *(f"--target={t}" for t in opts.target)]
    links += [f"--arg={k}:={v}" for k, v in opts.xacro_args.items()]
    links += [f"--package-path={k}={v}" for k, v in opts.package_paths.items()]
    links += [f"--hardware={h}" for h in opts.hardware]
    return links + (["--xacro"] if opts.xacro else [])


def _default_name() -> str:
    import re
    import socket

    name = re.sub(r"[^A-Za-z0-9_.-]", "-", socket.gethostname().split(".")[0])
    return name.strip("-.")[:63] or "robot"


NameOpt = Annotated[str | None, typer.Option(
    "--name", help="The robot's name on the network (default: this computer's).")]
ListenOpt = Annotated[list[str] | None, typer.Option(
    "--listen", metavar="ENDPOINT",
    help="Zenoh endpoint to listen on (repeatable; default tcp/127.0.0.1:7447, or the "
         "config file's).")]
ConnectOpt = Annotated[list[str] | None, typer.Option(
    "--connect", metavar="ENDPOINT",
    help="Zenoh endpoint to connect to, e.g. a router (repeatable).")]
DeadlineOpt = Annotated[float, typer.Option(
    "--deadline", help="Seconds without the caller's heartbeat before a verb is "
                       "interrupted (motion stops).")]
UnauthenticatedOpt = Annotated[bool, typer.Option(
    "--allow-unauthenticated-motion",
    help="Lab bench: allow motion and outputs without mutual TLS; only when every "
         "endpoint is on loopback.")]
WorkdirOpt = Annotated[str | None, typer.Option(
    "--workdir", metavar="DIR",
    help="Where remote verbs run (their reports and recordings go there; default: a "
         "directory of the agent's own, $XDG_STATE_HOME/deltoctl/agent/NAME).")]


def agent(
    ctx: typer.Context,
    name: NameOpt = None,
    listen: ListenOpt = None,
    connect: ConnectOpt = None,
    deadline: DeadlineOpt = 0.2,
    allow_unauthenticated_motion: UnauthenticatedOpt = False,
    workdir: WorkdirOpt = None,
) -> None:
    """Serve the robot of --profile (its links from --target, or --sim) over Zenoh until
    Ctrl-C or SIGTERM: every verb as a queryable, a liveliness token, a deadman on motion.

    Motion and outputs are served only to authenticated callers: when every link of the
    agent is mutual TLS (see the README, Remote robots)."""
    from deltoctl.cli.fleet_cmd import agent_checks
    from deltoctl.fleet import check_robot
    from deltoctl.fleet import config as zconfig
    from deltoctl.fleet.agent import Agent
    from deltoctl.profile.exporter import to_yaml

    opts = options(ctx)
    if opts.robot:
        raise InvalidInput("the agent serves this computer's robot: drop --robot")
    robot = check_robot(name or _default_name())
    if not (math.isfinite(deadline) and 0.1 <= deadline <= 10):
        raise InvalidInput(f"--deadline must be 0.1 to 10 seconds, got {deadline:g}")
    workdir = _workdir(workdir, robot)
    profile = opts.load_profile()  # a bad profile stops here, with its file:line
    own_files = _profile_files(opts)
    spec = opts.profile or profile.name
    if os.path.exists(spec):
        spec = os.path.abspath(spec)
    config_path = zconfig.config_file(opts.zenoh_config)
    config = zconfig.load(config_path, "agent", listen, connect)
    own_files += [*([config_path] if config_path else []), *zconfig.tls_files(config)]
    motion, why_not = _motion_rule(config, allow_unauthenticated_motion)
    with _served_links(opts, spec) as links:
        marks = [SIMULATED] if opts.sim else []
        children = ([sys.executable, "-c", ZYGOTE, spec, *marks],
                    [sys.executable, "-c", SPARE, spec, *marks])
        node = Agent(robot, spec, profile.name, links, children, config, motion, why_not,
                     deadline, workdir, simulated=opts.sim,
                     profile_yaml=to_yaml(profile), own_files=own_files, check=agent_checks)
        _serve(node, f"robot {robot}: serving {profile.name} on Zenoh "
                     f"({zconfig.describe(config)}); motion "
                     f"{'allowed' if motion else 'refused: ' + why_not}")


def _workdir(given: str | None, robot: str) -> str:
    """Where remote verbs run: --workdir (which must exist), or the agent's own."""
    if given is None:
        return os.path.abspath(_own_workdir(robot))
    if not os.path.isdir(given):
        raise InvalidInput(f"--workdir {given}: no such directory")
    return os.path.abspath(given)


@contextlib.contextmanager
def _served_links(opts: Options, spec: str) -> Iterator[list[str]]:
    """The global options that point a verb at the robot; with --sim, at the simulator
    started here (stopped on the way out)."""
    from deltoctl.fleet.agent import start_simulator, stop_process

    links = _links(opts, spec)
    if not opts.sim:
        yield links
        return
    simulator, served = start_simulator(
        [sys.executable, "-m", "deltoctl", *links, "sim", "serve", "--json"],
        env={k: v for k, v in os.environ.items() if not k.startswith("DELTOCTL_")})
    try:
        links = [a for a in links if not a.startswith("--target=")]
        yield links + [f"--target={bus}={url}" for bus, url in served["buses"].items()]
    finally:
        stop_process(simulator)


def _serve(node: Agent, serving: str) -> None:
    """Serve until a signal stops the agent; ``serving`` is said once it is up."""
    from deltoctl.fleet.agent import log, signals_stop

    signals_stop(node.stop)
    try:
        node.start()
        log(serving)
        node.serve()
        log(f"robot {node.robot}: stopping")
    finally:
        node.close()


def _own_workdir(robot: str) -> str:
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


def _profile_files(opts: Options) -> list[str]:
    """The files the robot's profile was read from: the profile, and what xacro included."""
    from deltoctl.profile.catalog import resolve, runs_xacro

    path = resolve(opts.profile) if opts.profile else None
    if path is None:
        return []
    files = [str(path)]
    if runs_xacro(path, opts.xacro):
        from deltoctl.profile.xacro_runner import included_files

        files += included_files()
    return files


def _motion_rule(config: object, allow_unauthenticated: bool) -> tuple[bool, str]:
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


def _warm(spec: str, simulated: bool = False) -> None:
    """What every verb imports, and the robot's profile and drivers: loaded once. With
    ``simulated`` (``agent --sim``), every block the verbs open is marked simulated."""
    import contextlib
    import importlib

    for module in ("deltoctl.cli.main", "deltoctl.cli.device_cmd", "deltoctl.cli.motion_cmd",
                   "deltoctl.cli.output", "deltoctl.profile.catalog", "deltoctl.core.system",
                   "deltoctl.core.runner"):
        importlib.import_module(module)
    if simulated:
        from deltoctl.cli import device_cmd

        device_cmd.SERVED_SIMULATED = "deltoctl agent --sim"
    with contextlib.suppress(Exception):  # only a head start: the verb reports any problem
        from deltoctl import registry
        from deltoctl.profile.catalog import load_profile

        prof = load_profile(spec)
        for hw in prof.hardware:
            family = registry.of_block(prof.family_of(hw), hw.plugin)
            if family is not None:
                family.driver_class()


def _run(argv: list[str]) -> int:
    """One command line, as ``deltoctl`` runs it; its exit code."""
    from deltoctl.cli import main as cli

    sys.argv = ["deltoctl", *argv]
    try:
        cli.main()
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except KeyboardInterrupt:  # interrupted before the verb ran (or after): nothing moved
        cli.emit_error("interrupted", None, 130, "--json" in argv)
        return 130
    return 0


def zygote(spec: str, sock_fd: int, simulated: bool = False) -> None:
    """The agent's warm process: forks one child per verb (deltoctl/fleet/forks.py)."""
    from deltoctl.fleet.forks import serve

    _warm(spec, simulated)
    serve(sock_fd, _run)


def spare(spec: str = "", simulated: bool = False) -> None:
    """A deltoctl process started ahead by the agent (when it has no zygote): warm, it waits
    for its command line (one JSON list) on stdin, then runs it as ``deltoctl`` would."""
    import json
    import signal
    import threading
    import time

    _warm(spec, simulated)
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
    sys.exit(_run(json.loads(line)))
