"""``--robot ROBOT`` (any verb on one robot's agent) and ``deltoctl fleet``: the robots found,
and one verb (or a bring-up script's verbs) on many robots at once."""

from __future__ import annotations

import sys
from typing import Annotated, Any, NoReturn

import typer

from deltoctl.cli.context import Options, options
from deltoctl.errors import DeltoctlError, InvalidInput

app = typer.Typer(help="The robots whose agents answer over Zenoh, and verbs on many at once.",
                  no_args_is_help=True)

FORWARDED = {"json": "--json", "yes": "--yes", "quiet": "--quiet"}
AGENT_RECORD_MAX = 3600.0  # s: the longest record an agent writes in its own directory


def register(root: typer.Typer) -> None:
    root.add_typer(app, name="fleet")


# -- --robot ---------------------------------------------------------------------------------

def strip_remote(argv: list[str]) -> list[str]:
    """The command line without ``--robot R`` and ``--zenoh-config FILE``."""
    out: list[str] = []
    skip = False
    for arg in argv:
        if skip:
            skip = False
        elif arg in ("--robot", "--zenoh-config"):
            skip = True
        elif not arg.startswith(("--robot=", "--zenoh-config=")):
            out.append(arg)
    return out


def _confirmed(opts: Options, verb: str, what: str) -> list[str]:
    """``["--yes"]`` when motion is confirmed here (``--yes``, or yes on a terminal); else
    nothing, and the robot refuses (exit 5) as a local run would."""
    from deltoctl.fleet import MOTION

    if opts.yes or verb not in MOTION or not sys.stdin.isatty():
        return []
    if typer.confirm(f"{what}. Move?", default=False, err=True):
        return ["--yes"]
    from deltoctl.errors import Refused

    raise Refused("not confirmed; nothing moved")


def _write_out(data: bytes) -> None:
    buffer = getattr(sys.stdout, "buffer", None)
    if buffer is not None:
        sys.stdout.flush()
        buffer.write(data)
        buffer.flush()
    else:
        sys.stdout.write(data.decode(errors="replace"))
        sys.stdout.flush()


def _write_err(text: str) -> None:
    sys.stderr.write(text)
    sys.stderr.flush()


def forward(ctx: typer.Context) -> NoReturn:
    """Run the command line on ``--robot``'s agent: its stdout, stderr (errors naming the
    robot) and exit code, as if run there."""
    from deltoctl.cli.main import ARGV
    from deltoctl.fleet import check_robot
    from deltoctl.fleet.client import ErrorLines, RemoteCall, caller_session
    from deltoctl.fleet.run import verb_of

    opts = options(ctx)
    robot = check_robot(opts.robot or "")
    argv = strip_remote(list(ctx.find_root().meta.get(ARGV, [])))
    errors = ErrorLines(robot, opts.json, _write_err)
    try:
        verb = verb_of(_record_file_dropped(argv), robot)
        if verb == "record" and not {"--help", "-h"} & set(argv):
            code = _remote_record(opts, robot, argv, errors.feed)
            raise typer.Exit(code)
        argv = _confirmed(opts, verb, f"robot {robot}: {' '.join(argv)}") + argv
        with caller_session(opts.zenoh_config, f"robot {robot}") as session:
            code = RemoteCall(session, robot, argv, _write_out, errors.feed).run()
    except DeltoctlError as exc:  # this side failed (nothing answers): the robot named too
        if not opts.json:
            raise
        import json

        error = {"message": exc.message, "hint": exc.hint, "exit_code": exc.exit_code,
                 "robot": robot}
        _write_err(json.dumps({"error": error}) + "\n")
        raise typer.Exit(exc.exit_code) from None
    finally:
        errors.close()
    raise typer.Exit(code)


# -- --robot R record: the file on this computer -----------------------------------------------

def _verb_args(argv: list[str]) -> list[str]:
    """The arguments after the verb (global options come first, hoisted)."""
    from deltoctl.cmdline import needs_value

    i = 0
    while i < len(argv) and argv[i].startswith("-"):
        i += 2 if needs_value(argv[i]) else 1
    return argv[i + 1:]


def _record_file_dropped(argv: list[str]) -> list[str]:
    """The command line as the agent judges it: a remote record's FILE is written on this
    computer and never sent, so the agent's path rule (files in its directory only) does not
    judge it. Any other command line as it is."""
    from deltoctl.cli.main import command_path
    from deltoctl.cmdline import hoist_global_options

    hoisted = hoist_global_options(argv)
    args = _verb_args(hoisted)
    try:
        if command_path(hoisted) != ("record",) or {"--help", "-h"} & set(args):
            return argv
    except InvalidInput:
        return argv
    at = _positional(args)
    if at is None:
        return argv
    return hoisted[:len(hoisted) - len(args)] + args[:at] + args[at + 1:]


def _positional(args: list[str]) -> int | None:
    """Where record's FILE argument stands among its arguments."""
    from typer.main import get_command

    from deltoctl.cli import record_cmd

    holder = typer.Typer()
    record_cmd.register(holder)
    takes_value = {o for p in get_command(holder).params if getattr(p, "opts", None)
                   and p.param_type_name == "option" and not p.is_flag for o in p.opts}
    i = 0
    while i < len(args):
        arg = args[i]
        if arg == "--":
            return i + 1 if i + 1 < len(args) else None
        if not arg.startswith("-") or arg == "-":
            return i
        i += 2 if arg in takes_value else 1
    return None


def _output_name(template: Any, identities: dict[str, dict[str, Any]], force: bool) -> Any:
    """A remote record's file: ``{serial}`` from the robot's blocks, as a local record fills
    it; refused when it exists (without --force)."""
    from deltoctl.app.recording import SERIAL, block_serial, output_path, refuse_existing

    path = template
    if SERIAL in path.name:
        path = output_path(path, [block_serial(block, ident.get("target"), ident)
                                  for block, ident in identities.items()])
    refuse_existing(path, force)
    return path


def _record_params(args: list[str], robot: str) -> dict[str, Any]:
    """The record's own options, checked here; its file's directory must be there."""
    params = record_options(args)
    from pathlib import Path

    from deltoctl.app.recording import planned_output

    params["output"] = planned_output(Path(params["output"]), params["force"])
    return params


def record_options(args: list[str]) -> dict[str, Any]:
    """The record's own options, parsed as ``deltoctl record`` parses them, and checked as
    it checks them; those that make no sense remotely refused."""
    from typer.main import get_command

    from deltoctl.cli import record_cmd
    from deltoctl.cli.device_cmd import check_loop
    from deltoctl.cli.main import click_exceptions
    from deltoctl.record.ros2_msgs import GPIO_TYPES

    holder = typer.Typer()
    record_cmd.register(holder)
    try:
        params = get_command(holder).make_context("record", list(args)).params
    except click_exceptions.ClickException as exc:
        raise InvalidInput(f"record: {exc.format_message()}") from None
    check_loop(params["rate"], params["duration"])
    if params["gpio_type"] not in GPIO_TYPES:
        raise InvalidInput(f"--gpio-type {params['gpio_type']!r}: one of "
                           f"{', '.join(GPIO_TYPES)}")
    return params


def agent_checks(verb: str, argv: list[str]) -> None:
    """What the agent checks in a remote command line with the CLI's own parse: a record it
    runs (``fleet run record``, its file in the agent's directory) has a duration of at most
    AGENT_RECORD_MAX, so that no caller fills the robot's computer's disk."""
    from deltoctl.cmdline import hoist_global_options

    args = _verb_args(hoist_global_options(argv))
    if verb != "record" or {"--help", "-h"} & set(args):
        return
    duration = record_options(args)["duration"]
    if duration is None or duration > AGENT_RECORD_MAX:
        raise InvalidInput(f"a record written on the robot's computer needs --duration of at "
                           f"most {AGENT_RECORD_MAX:g} s"
                           + ("" if duration is None else f", got {duration:g}"),
                           "or write the file on this computer: deltoctl --robot ROBOT record "
                           "FILE (Ctrl-C ends it)")


def _remote_record(opts: Options, robot: str, argv: list[str],
                   err: Any) -> int:
    """``--robot R record FILE``: the robot streams its cycles, FILE is written here (with the
    robot's profile, identity and cycle times). The exit code of the stream on the robot
    (4 when its link was down at the end, 3 when lost and back), 3 when cycles it ran did not
    arrive, 4 when the robot was lost (the file finished), 130 when interrupted before the
    stream started."""
    from deltoctl.cli.output import emit_json, info, warn
    from deltoctl.errors import WARNINGS
    from deltoctl.fleet.client import caller_session
    from deltoctl.fleet.remote_record import RemoteRecord, cancelled_by_signals

    params = _record_params(_verb_args(argv), robot)
    failure: DeltoctlError | None = None
    with caller_session(opts.zenoh_config, f"robot {robot}") as session:
        rec = RemoteRecord(session, robot, params["output"], params["rate"],
                           params["duration"], [f"--hardware={h}" for h in opts.hardware],
                           params["gpio_type"], params["allow_model_mismatch"], err,
                           opened=lambda: info(f"recording {rec.output} from robot {robot} "
                                               "(its cycle times; Ctrl-C ends it)"),
                           name=lambda template, identities: _output_name(
                               template, identities, params["force"]))
        with cancelled_by_signals(rec.cancel):
            try:
                code = rec.run()
            except DeltoctlError as exc:
                failure, code = exc, exc.exit_code
    from deltoctl.errors import Unreachable

    if rec.result and (failure is None or isinstance(failure, Unreachable)):
        loop = rec.result["loop"]
        if opts.json:
            emit_json(rec.result)
        else:
            info(f"wrote {params['output']}: {sum(rec.result['messages'].values())} messages "
                 f"on {len(rec.result['messages'])} topics, {loop['cycles']} cycles of robot "
                 f"{robot} at {loop['real_rate']} Hz (its cycle times)")
        if rec.result["link_losses"]:
            info("the gaps are marked on /diagnostics")
        if loop["cycles_not_received"]:
            warn(f"robot {robot}: {loop['cycles_not_received']} of its {loop['robot_cycles']} "
                 "cycles did not arrive (the gaps are marked on /diagnostics)")
            code = code or WARNINGS
    if failure is not None:
        raise failure
    return code


# -- fleet list ------------------------------------------------------------------------------

def _identity_text(identity: dict[str, Any]) -> str:
    """Each block as its family shows its identity (``Family.identity_fields``: model,
    firmware, parts …); a family not installed here, or one declaring none, by its name."""
    from deltoctl import registry

    if "error" in identity:
        return f"identify failed: {identity['error']}"
    parts = []
    for block, fields in identity.items():
        family = registry.get(str(fields.get("family")))
        shown = [template.format(fields[key]).split(" (0x")[0]  # a model's number: too long
                 for key, template in (family.identity_fields if family else ())
                 if fields.get(key) not in (None, "")]
        parts.append(f"{block}: {' '.join(shown) or fields.get('family')}")
    return "; ".join(parts)


@app.command("list")
def list_cmd(
    ctx: typer.Context,
    wait: Annotated[float, typer.Option(help="Seconds to wait for the agents' answers.")]
        = 2.0,
) -> None:
    """The robots whose agents answer (their liveliness tokens), with profile, identity and
    state."""
    from deltoctl.cli.output import emit_json, info, table
    from deltoctl.fleet.client import agents, caller_session, infos

    opts = options(ctx)
    if not 0 < wait <= 60:
        raise InvalidInput(f"--wait must be 0 to 60 seconds, got {wait:g}")
    with caller_session(opts.zenoh_config, "fleet") as session:
        found = agents(session, wait=wait)
        details = infos(session, wait=wait) if found else {}
    robots = [{"robot": name, "profile": profile, **{
        k: v for k, v in details.get(name, {"state": "unknown"}).items() if k != "robot"}}
        for name, profile in sorted(found.items())]
    if opts.json:
        emit_json(robots)
    elif robots:
        table(None, ["robot", "profile", "identity", "state", "motion"],
              [[r["robot"], r["profile"], _identity_text(r.get("identity", {})), r["state"],
                r.get("motion", "?")] for r in robots])
    if not robots:
        info("no robot found: no agent answers on this Zenoh network")


# -- fleet run -------------------------------------------------------------------------------

def _globals(opts: Options) -> list[str]:
    return [flag for name, flag in FORWARDED.items() if getattr(opts, name)] + \
        [f"--hardware={h}" for h in opts.hardware]


def _live(jobs: list[Any]) -> Any:
    from rich.table import Table

    t = Table(title="fleet run", title_justify="left")
    for column in ("robot", "profile", "now", "lines", "seconds"):
        t.add_column(column)
    for j in jobs:
        t.add_row(j.robot, j.profile, j.state, f"{j.done}/{len(j.lines)}", f"{j.seconds():.1f}")
    return t


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
    import os

    from deltoctl.cli.main import VERBS
    from deltoctl.cli.output import emit_json, info, table
    from deltoctl.cmdline import hoist_global_options
    from deltoctl.fleet import MOTION
    from deltoctl.fleet.client import agents, caller_session
    from deltoctl.fleet.run import choose, script_lines, start, verb_of, worst

    opts = options(ctx)
    skipped: list[str] = []
    one_verb = not (command[0] not in VERBS and os.path.isfile(command[0]) and len(command) == 1)
    if one_verb:  # checked once the robots are known, to name them
        lines = [hoist_global_options(list(command))]
    else:
        lines, skipped = script_lines(command[0])
    lines = [_globals(opts) + ln for ln in lines]
    for note in skipped:
        info(f"skipped {note}")
    with caller_session(opts.zenoh_config, "fleet") as session:
        chosen = choose(agents(session, wait=wait), robots)
        if one_verb:
            verb_of(lines[0], ", ".join(sorted(chosen)))
        lines = _confirm_motion(opts, chosen, lines, MOTION)
        report = len(lines) == 1 and verb_of(lines[0]) == "report"
        if report and "--json" not in lines[0]:  # each robot's JSON, gathered below
            lines = [[*lines[0], "--json"]]
        jobs, threads = start(session, chosen, lines)
        _watch(jobs, threads, opts)
    code = worst([j.code for j in jobs])
    if report:
        from deltoctl.cli.report_cmd import fleet_summary

        fleet_summary([j.report() for j in jobs], opts.json, code)
    if opts.json:
        emit_json({"command": lines[0] if len(lines) == 1 else lines, "skipped": skipped,
                   "exit_code": code, "robots": [j.report() for j in jobs]})
    else:
        table(None, ["robot", "profile", "exit", "seconds", "lines", "result"],
              [[j.robot, j.profile, j.code, f"{j.seconds():.2f}", f"{j.done}/{len(j.lines)}",
                "ok" if j.code == 0 else j.last_error()] for j in jobs])
    raise typer.Exit(code)


def _confirm_motion(opts: Options, chosen: dict[str, str], lines: list[list[str]],
                    motion: Any) -> list[list[str]]:
    """Motion on many robots is confirmed here, once (--yes, or yes on a terminal); each
    moving line then carries --yes."""
    from deltoctl.fleet.run import verb_of

    if not any(verb_of(ln) in motion for ln in lines) or opts.yes or not sys.stdin.isatty():
        return lines
    names = ", ".join(sorted(chosen))
    if not typer.confirm(f"motion on {len(chosen)} robots ({names}). Move?", default=False,
                         err=True):
        from deltoctl.errors import Refused

        raise Refused("not confirmed; nothing moved")
    return [["--yes", *ln] if verb_of(ln) in motion else ln for ln in lines]


def _watch(jobs: list[Any], threads: list[Any], opts: Options) -> None:
    """Wait for every robot, with a live table on a terminal; Ctrl-C interrupts them all."""
    live = None
    if not (opts.json or opts.quiet) and sys.stderr.isatty():
        from rich.console import Console
        from rich.live import Live

        live = Live(_live(jobs), console=Console(stderr=True), auto_refresh=False)
        live.start()
    try:
        while any(t.is_alive() for t in threads):
            try:
                for t in threads:
                    t.join(0.1)
                    if live is not None:
                        live.update(_live(jobs), refresh=True)
            except KeyboardInterrupt:
                for j in jobs:
                    if j.call is not None:
                        j.call.cancel()
    finally:
        if live is not None:
            live.stop()
