"""``deltoctl agent``: serve this computer's robot over Zenoh, so that any verb runs from
another computer (``deltoctl --robot ROBOT VERB …``, ``deltoctl fleet …``)."""

from __future__ import annotations

import sys
from typing import Annotated

import typer

from deltoctl.cli.context import options
from deltoctl.errors import InvalidInput
from deltoctl.verb_help import DESCRIPTIONS

# the agent's verb processes: argv[1] the profile, then host.SIMULATED when --sim serves the
# robot (the zygote's socket comes last)
SPARE = ("import sys; from deltoctl.cli.agent_cmd import verb_process; "
         "verb_process(sys.argv[1], 'simulated' in sys.argv[2:])")
ZYGOTE = ("import sys; from deltoctl.cli.agent_cmd import verb_process; "
          "verb_process(sys.argv[1], 'simulated' in sys.argv[2:-1], int(sys.argv[-1]))")


def register(root: typer.Typer) -> None:
    root.command("agent", help=DESCRIPTIONS["agent"])(agent)


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
    from deltoctl.cli.fleet_cmd import agent_checks
    from deltoctl.fleet import host

    opts = options(ctx)
    if opts.robot:
        raise InvalidInput("the agent serves this computer's robot: drop --robot")
    if opts.sim_options:
        raise InvalidInput("--sim-option is not for the agent: its simulator serves the "
                           "profile as 'sim serve' does by default")
    host.run_agent(opts, name, (listen, connect), deadline, allow_unauthenticated_motion,
                   workdir, (ZYGOTE, SPARE), agent_checks)


# -- the agent's warm verb processes (deltoctl/fleet/host.py): deltoctl's own command line ---

# what every verb imports, loaded once by a warm process
VERB_MODULES = ("deltoctl.cli.main", "deltoctl.cli.device_cmd", "deltoctl.cli.motion_cmd",
                "deltoctl.cli.output", "deltoctl.profile.catalog", "deltoctl.core.system",
                "deltoctl.core.runner")


def verb_process(spec: str, simulated: bool, zygote_socket: int | None = None) -> None:
    """The agent's warm verb process, its zygote given the socket, else a spare: it runs each
    command line as ``deltoctl`` does; with ``simulated`` (``agent --sim``), every block the
    verbs open is marked simulated."""
    from deltoctl.fleet import host

    host.warm_process(spec, VERB_MODULES, _served_simulated if simulated else None, _run,
                      zygote_socket)


def _served_simulated() -> None:
    from deltoctl.cli import device_cmd

    device_cmd.SERVED_SIMULATED = "deltoctl agent --sim"


def _run(argv: list[str]) -> int:
    """One command line, as ``deltoctl`` runs it; its exit code."""
    from deltoctl.cli import device_cmd
    from deltoctl.cli import main as cli
    from deltoctl.fleet import SET_SAFE

    if argv[:1] == [SET_SAFE]:  # the agent's own, after it killed a motion verb
        device_cmd.SET_SAFE, argv = True, argv[1:]
    sys.argv = ["deltoctl", *argv]
    try:
        cli.main()
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except KeyboardInterrupt:  # interrupted before the verb ran (or after): nothing moved
        cli.emit_error("interrupted", None, 130, "--json" in argv)
        return 130
    return 0

