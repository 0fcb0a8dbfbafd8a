"""``--robot ROBOT`` (any verb on one robot's agent) and ``deltoctl fleet``: the robots found,
and one verb (or a bring-up script's verbs) on many robots at once."""

from __future__ import annotations

import sys
from typing import Annotated, Any, NoReturn

import typer

from deltoctl import verbs
from deltoctl.cli.confirm import confirmed_remotely
from deltoctl.cli.context import ARGV, Options, options
from deltoctl.cli.output import emit_error, emit_json, info, stdout_is_terminal, table, warn
from deltoctl.errors import DeltoctlError, InvalidInput

app = typer.Typer(help="The robots whose agents answer over Zenoh, and verbs on many at once.",
                  no_args_is_help=True)

FORWARDED = {"json": "--json", "yes": "--yes", "quiet": "--quiet"}


def register(root: typer.Typer) -> None:
    root.add_typer(app, name="fleet")


# -- --robot ---------------------------------------------------------------------------------

def forward(ctx: typer.Context) -> NoReturn:
    """Run the command line on ``--robot``'s agent: its stdout, stderr (errors naming the
    robot) and exit code, as if run there."""
    from deltoctl.fleet import ACTUATING, check_robot
    from deltoctl.fleet.fleet_run import record_file_dropped, strip_remote, verb_of
    from deltoctl.fleet.remote_call import ErrorLines, RemoteCall, caller_session
    from deltoctl.render.stream import live_lines, write_err, write_out

    opts = options(ctx)
    robot = check_robot(opts.robot or "")
    argv = strip_remote(list(ctx.find_root().meta.get(ARGV, [])))
    errors = ErrorLines(robot, opts.json, write_err)
    try:
        verb = verb_of(record_file_dropped(argv, _value_options), robot)
        if verb == "record" and not {"--help", "-h"} & set(argv):
            raise typer.Exit(_remote_record(opts, robot, argv, errors.feed))
        if verb in ACTUATING and confirmed_remotely(opts, f"robot {robot}: {' '.join(argv)}"):
            argv = ["--yes", *argv]
        drawn = verb == "stream" and not opts.json and not {"-h", "--help"} & set(argv)
        with caller_session(opts.zenoh_config, f"robot {robot}") as session, live_lines(
                f"from robot {robot}", write_out, drawn and stdout_is_terminal()) as out:
            code = RemoteCall(session, robot, argv, out, errors.feed).run()
    except DeltoctlError as exc:  # this side failed (nothing answers): the robot named too
        if not opts.json:
            raise
        emit_error(exc.message, exc.hint, exc.exit_code, True, robot=robot)
        raise typer.Exit(exc.exit_code) from None
    finally:
        errors.close()
    raise typer.Exit(code)


# -- --robot R record: the file on this computer -----------------------------------------------

def _record_command() -> Any:
    """``deltoctl record``'s click command: its options, as the CLI parses them."""
    from typer.main import get_command

    from deltoctl.cli import record_cmd

    holder = typer.Typer()
    record_cmd.register(holder)
    return get_command(holder)


def _value_options() -> set[str]:
    """record's options that take a value, as the CLI parses them."""
    return {o for p in _record_command().params if getattr(p, "opts", None)
            and p.param_type_name == "option" and not p.is_flag for o in p.opts}


def record_options(args: list[str]) -> dict[str, Any]:
    """The record's own options, parsed as ``deltoctl record`` parses them, and checked as
    it checks them; those that make no sense remotely refused."""
    from typer._click import exceptions as click_exceptions

    from deltoctl.app.recording import check_record_options

    try:
        params = _record_command().make_context("record", list(args)).params
    except click_exceptions.ClickException as exc:
        raise InvalidInput(f"record: {exc.format_message()}") from None
    check_record_options(params["rate"], params["duration"], params["gpio_type"])
    return params


def agent_checks(verb: str, argv: list[str]) -> None:
    """What the agent checks in a remote command line with the CLI's own parse: the duration
    of a record it runs (deltoctl.fleet.host.check_record_duration)."""
    from deltoctl.cmdline import hoist_global_options
    from deltoctl.fleet.fleet_run import verb_args
    from deltoctl.fleet.host import check_record_duration

    args = verb_args(hoist_global_options(argv))
    if verb == "record" and not {"--help", "-h"} & set(args):
        check_record_duration(record_options(args)["duration"])


def _remote_record(opts: Options, robot: str, argv: list[str], err: Any) -> int:
    """``--robot R record FILE``: the robot streams its cycles, FILE is written here (with the
    robot's profile, identity and cycle times). The exit code of the stream on the robot
    (4 when its link was down at the end, 3 when lost and back), 3 when cycles it ran did not
    arrive, 4 when the robot was lost (the file finished), 130 when interrupted before the
    stream started."""
    from deltoctl.app.recording import record_from_robot
    from deltoctl.fleet.fleet_run import verb_args
    from deltoctl.render.fleet import not_received_text
    from deltoctl.render.recording import recorded_lines

    done = record_from_robot(opts.zenoh_config, robot, record_options(verb_args(argv)),
                             opts.hardware, err, lambda path: info(
                                 f"recording {path} from robot {robot} (its cycle times; "
                                 "Ctrl-C ends it)"))
    if done.result:
        if opts.json:
            emit_json(done.result, profile=done.profile)
        for line in recorded_lines(done.result, robot)[1 if opts.json else 0:]:
            info(line)
        if done.not_received:
            warn(not_received_text(robot, done.result))
    if done.failure is not None:
        raise done.failure
    return done.code


# -- fleet list ------------------------------------------------------------------------------

@app.command("list")
def list_cmd(
    ctx: typer.Context,
    wait: Annotated[float, typer.Option(help="Seconds to wait for the agents' answers.")]
        = 2.0,
) -> None:
    """The robots whose agents answer (their liveliness tokens), with profile, identity and
    state."""
    from deltoctl.fleet.fleet_run import robots_found
    from deltoctl.fleet.remote_call import caller_session
    from deltoctl.render.fleet import list_rows

    opts = options(ctx)
    if not 0 < wait <= 60:
        raise InvalidInput(f"--wait must be 0 to 60 seconds, got {wait:g}")
    with caller_session(opts.zenoh_config, "fleet") as session:
        robots = robots_found(session, wait)
    if opts.json:
        emit_json(robots)
    elif robots:
        table(None, ["robot", "profile", "identity", "state", "motion"], list_rows(robots))
    if not robots:
        info("no robot found: no agent answers on this Zenoh network")


# -- fleet run -------------------------------------------------------------------------------

@app.command("run", context_settings={"ignore_unknown_options": True,
                                      "allow_interspersed_args": False})
def run_cmd(
    ctx: typer.Context,
    command: Annotated[list[str], typer.Argument(
        metavar="VERB [ARGS]... | SCRIPT",
        help="A verb and its arguments, or a bring-up script whose deltoctl lines run in "
             "order on each robot.")],
    robots: Annotated[str, typer.Option(
        "--robots", help="Glob of robot names (default: every robot found).")] = "*",
    wait: Annotated[float, typer.Option(help="Seconds to wait for the agents to answer.")]
        = 2.0,
) -> None:
    """Run one verb (or a script's verbs) on many robots in parallel: a live table while they
    run, one report at the end; the exit code is the worst of the robots'."""
    from deltoctl.fleet.fleet_run import (
        choose,
        command_lines,
        confirmed,
        start,
        verb_of,
        wait_for,
        worst,
    )
    from deltoctl.fleet.remote_call import agents, caller_session
    from deltoctl.render.fleet import live_run, run_rows

    opts = options(ctx)
    lines, skipped, one_verb = command_lines(command, verbs.modules())
    lines = [[*(flag for name, flag in FORWARDED.items() if getattr(opts, name)),
              *(f"--hardware={h}" for h in opts.hardware), *ln] for ln in lines]
    for note in skipped:
        info(f"skipped {note}")
    with caller_session(opts.zenoh_config, "fleet") as session:
        chosen = choose(agents(session, wait=wait), robots)
        if one_verb:  # checked once the robots are known, to name them
            verb_of(lines[0], ", ".join(sorted(chosen)))
        lines = confirmed(lines, lambda: confirmed_remotely(
            opts, f"actuate or move {len(chosen)} robots ({', '.join(sorted(chosen))})"))
        report = len(lines) == 1 and verb_of(lines[0]) == "report"
        if report and "--json" not in lines[0]:  # each robot's JSON, gathered below
            lines = [[*lines[0], "--json"]]
        jobs, threads = start(session, chosen, lines)
        with live_run(jobs, not (opts.json or opts.quiet) and sys.stderr.isatty()) as tick:
            wait_for(jobs, threads, tick)  # Ctrl-C interrupts every robot
    code = worst([j.code for j in jobs])
    if report:
        from deltoctl.cli.report_cmd import fleet_summary

        fleet_summary([j.report() for j in jobs], opts.json, code)
    if opts.json:
        emit_json({"command": lines[0] if len(lines) == 1 else lines, "skipped": skipped,
                   "exit_code": code, "robots": [j.report() for j in jobs]})
    else:
        table(None, ["robot", "profile", "exit", "seconds", "lines", "result"], run_rows(jobs))
    raise typer.Exit(code)

