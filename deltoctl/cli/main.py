"""The ``deltoctl`` application: global options, error handling and the verb registry.

Global options are accepted before the verb and after it (``deltoctl --json identify`` and
``deltoctl identify --json -yq``): the root group moves them to the front before parsing.
Every verb's help lists them in a "Global options" panel, with an example and the exit codes.
"""

import functools
import sys
from collections.abc import Sequence
from typing import Annotated, Any

import typer
from typer._click import exceptions as click_exceptions
from typer.core import TyperGroup

from deltoctl import verbs
from deltoctl.cli.completions import complete_blocks, complete_profile
from deltoctl.cli.context import ARGV, DOCUMENT, TEACH, Options, parse_pairs
from deltoctl.cmdline import GLOBAL_OPTIONS, given_options, hoist_global_options
from deltoctl.errors import DeltoctlError, InvalidInput
from deltoctl.verb_help import EXIT_LINE
from deltoctl.version import __version__

# verb → the module of deltoctl.cli whose register(app) adds it (deltoctl.verbs declares
# them). A module is imported only when one of its verbs runs: every line of a bring-up script
# pays for what it imports.
VERBS = verbs.modules()


class DeltoctlGroup(TyperGroup):
    """Loads verbs on demand, hoists global options, suggests verbs, and turns DeltoctlError
    into one line (one JSON object with --json) and its exit code."""

    def list_commands(self, ctx: Any) -> list[str]:
        return verbs.by_stage()  # the root's help shows them by stage, in this order

    def get_command(self, ctx: Any, cmd_name: str) -> Any:
        if cmd_name not in self.commands and cmd_name in VERBS:
            import importlib

            from typer.main import get_group

            module = importlib.import_module(f"deltoctl.cli.{VERBS[cmd_name]}")
            holder = typer.Typer()
            module.register(holder)
            loaded = get_group(holder).commands
            if ctx.resilient_parsing or ctx.meta.get(TEACH):  # help or completion only
                from deltoctl.verb_help import teach_verbs

                teach_verbs(self, loaded)
            self.commands.update(loaded)
        return self.commands.get(cmd_name)

    def resolve_command(self, ctx: Any, args: list[str]) -> Any:
        try:
            return self._click_resolve_command(ctx, args)
        except click_exceptions.UsageError as exc:
            from deltoctl.suggest import close_matches

            close = close_matches(args[0], VERBS) if args else []
            if close:
                exc.message = (f"{exc.message.rstrip('.')}. Did you mean "
                               f"{', '.join(repr(c) for c in close)}?")
            raise

    def parse_args(self, ctx: Any, args: list[str]) -> list[str]:
        args = hoist_global_options(list(args))
        options_part = args[:args.index("--")] if "--" in args else args
        ctx.meta[TEACH] = "-h" in options_part or "--help" in options_part
        ctx.meta[ARGV] = list(args)  # what --robot forwards to the robot's agent
        try:
            return super().parse_args(ctx, args)
        except click_exceptions.UsageError as exc:
            if "--json" in options_part and not ctx.resilient_parsing and not isinstance(
                    exc, click_exceptions.NoArgsIsHelpError):
                _usage_error(exc, True)
            raise

    def invoke(self, ctx: Any) -> Any:
        """The verb, then its JSON document in the envelope that knows its exit code."""
        code = 1
        try:
            result = self._invoke(ctx)
            code = 0
            return result
        except typer.Exit as exc:
            code = exc.exit_code
            raise
        finally:
            if ctx.meta.get(DOCUMENT) is not None:
                from deltoctl.cli.output import flush_document

                flush_document(ctx, code)

    def _invoke(self, ctx: Any) -> Any:
        try:
            return super().invoke(ctx)
        except DeltoctlError as exc:
            emit_error(exc.message, exc.hint, exc.exit_code, _json(ctx))
            raise typer.Exit(exc.exit_code) from None
        except KeyboardInterrupt:
            emit_error("interrupted", None, 130, _json(ctx))
            raise typer.Exit(130) from None
        except click_exceptions.NoArgsIsHelpError:
            raise
        except click_exceptions.UsageError as exc:
            if isinstance(exc, click_exceptions.NoSuchOption):
                _suggest_option(exc)
            _usage_error(exc, _json(ctx))
            raise
        except (typer.Exit, typer.Abort, click_exceptions.ClickException):
            raise
        except BrokenPipeError:  # the reader went away (`| head`): stop quietly
            import os

            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            raise typer.Exit(0) from None
        except Exception as exc:  # a bug: one line for people, the traceback with -v
            if ctx.obj is not None and getattr(ctx.obj, "verbose", 0):
                raise
            emit_error(f"internal error: {type(exc).__name__}: {exc}",
                       "run with -v for the traceback, and please report it", 1, _json(ctx))
            raise typer.Exit(1) from None


def _suggest_option(exc: Any) -> None:
    """An unknown option after a verb: the nearest of its own options and the global ones
    (which the verb's parser does not know: they were hoisted)."""
    from deltoctl.suggest import close_matches

    own = [o for p in exc.ctx.command.params for o in getattr(p, "opts", ())] if exc.ctx else []
    names = [*own, *(o for o in GLOBAL_OPTIONS if o.startswith("--"))]
    exc.possibilities = close_matches(exc.option_name, names)


def emit_error(message: str, hint: str | None, exit_code: int, as_json: bool) -> None:
    from deltoctl.cli.output import emit_error as emit  # only when something went wrong

    emit(message, hint, exit_code, as_json)


def _json(ctx: Any) -> bool:
    """Whether --json was given (parsed by the root, or its Options built already)."""
    return bool(getattr(ctx.obj, "json", False) or ctx.params.get("json_out"))


def _usage_error(exc: Any, as_json: bool) -> None:
    """A usage error as one JSON object (exit 2); without --json typer draws its panel."""
    if not as_json:
        return
    where = getattr(exc, "ctx", None)
    hint = f"see '{where.command_path} -h'" if where is not None else None
    emit_error(exc.format_message(), hint, exc.exit_code, True)
    raise typer.Exit(exc.exit_code)


app = typer.Typer(
    cls=DeltoctlGroup,
    name="deltoctl",
    help="Bring-up toolkit for robot hardware: profiles, lifecycle verbs, simulated devices.",
    epilog="Example: deltoctl -p dg-5f-right --sim identify\n\n" + EXIT_LINE
           + " ('deltoctl help exit-codes').",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)


def _version(ctx: typer.Context, value: bool) -> None:
    if value and not ctx.resilient_parsing:  # not while a command line is only resolved
        typer.echo(f"deltoctl {__version__}")
        raise typer.Exit()


# the global options (root's), each declared once here
ProfileOpt = Annotated[str | None, typer.Option(
    "--profile", "-p", envvar="DELTOCTL_PROFILE", autocompletion=complete_profile,
    help="Device profile: a catalog name or a YAML/URDF/xacro file.")]
TargetOpt = Annotated[list[str] | None, typer.Option(
    "--target", "-t", envvar="DELTOCTL_TARGET", metavar="[BUS=]URL",
    help="Where the device is, e.g. tcp://169.254.186.72:502 (repeatable; in the variable, "
         "several apart by spaces).")]
SimOpt = Annotated[bool, typer.Option(
    "--sim", help="Run against a simulated device: the 'sim serve' of this profile running "
                  "for you, else one started for this command only (it forgets, e.g. homing, "
                  "when the command ends).")]
SimFreshOpt = Annotated[bool, typer.Option(
    "--sim-fresh", help="Like --sim, always on a simulator started for this command.")]
SimOptionOpt = Annotated[list[str] | None, typer.Option(
    "--sim-option", metavar="NAME=VALUE",
    help="With --sim: a fault or setting of the simulator, as 'sim serve --NAME VALUE' takes "
         "it, e.g. faces=+z:2,-z:2 (repeatable).")]
JsonOpt = Annotated[bool, typer.Option(
    "--json", help="Write one JSON document (NDJSON for streams) on stdout; an error is "
                   "one JSON object on stderr.")]
YesOpt = Annotated[bool, typer.Option(
    "--yes", "-y", help="Do not ask for confirmation before a command that actuates or "
                        "moves (needed without a terminal).")]
VerboseOpt = Annotated[int, typer.Option(
    "--verbose", "-v", count=True, metavar="", show_default=False,
    help="More diagnostics on stderr: -v each link, -vv every packet too.")]
QuietOpt = Annotated[bool, typer.Option(
    "--quiet", "-q", help="No progress or notes on stderr (results and warnings stay).")]
LogFileOpt = Annotated[str | None, typer.Option(
    "--log-file", envvar="DELTOCTL_LOG", metavar="FILE",
    help="Append the log and the packet trace to FILE as NDJSON.")]
XacroArgOpt = Annotated[list[str] | None, typer.Option(
    "--arg", metavar="NAME:=VALUE", help="A xacro argument (repeatable).")]
HardwareOpt = Annotated[list[str] | None, typer.Option(
    "--hardware", metavar="NAME", autocompletion=complete_blocks,
    help="Only this <ros2_control> block of the profile (repeatable; default: all).")]
XacroOpt = Annotated[bool, typer.Option(
    "--xacro", help="Run xacro on a profile file that is not named .xacro.")]
PackagePathOpt = Annotated[list[str] | None, typer.Option(
    "--package-path", metavar="PKG=DIR",
    help="Where $(find PKG) points, for xacro files (repeatable).")]
RobotOpt = Annotated[str | None, typer.Option(
    "--robot", metavar="ROBOT",
    help="Run the verb on this robot, through its 'deltoctl agent' over Zenoh.")]
ZenohConfigOpt = Annotated[str | None, typer.Option(
    "--zenoh-config", envvar="DELTOCTL_ZENOH_CONFIG", metavar="FILE",
    help="Zenoh configuration (JSON5: endpoints, TLS) for --robot, agent and fleet.")]
VersionOpt = Annotated[bool, typer.Option(
    "--version", callback=_version, is_eager=True, help="Show the version and exit.")]


@app.callback()
def root(
    ctx: typer.Context,
    profile: ProfileOpt = None,
    target: TargetOpt = None,
    sim: SimOpt = False,
    sim_fresh: SimFreshOpt = False,
    sim_option: SimOptionOpt = None,
    json_out: JsonOpt = False,
    yes: YesOpt = False,
    verbose: VerboseOpt = 0,
    quiet: QuietOpt = False,
    log_file: LogFileOpt = None,
    xacro_arg: XacroArgOpt = None,
    hardware: HardwareOpt = None,
    xacro: XacroOpt = False,
    package_path: PackagePathOpt = None,
    robot: RobotOpt = None,
    zenoh_config: ZenohConfigOpt = None,
    version: VersionOpt = False,
) -> None:
    """Global options may come before or after the verb."""
    # --robot: the robot's agent refuses --log-file (a file on its computer): none is made here
    _logging(verbose, None if robot else log_file)
    ctx.obj = Options(
        profile=profile,
        target=list(target or []),
        sim=sim or sim_fresh,
        sim_fresh=sim_fresh,
        sim_options=list(sim_option or []),
        json=json_out,
        yes=yes,
        verbose=verbose,
        quiet=quiet,
        xacro_args=parse_pairs(list(xacro_arg or []), ":=", "--arg", "NAME:=VALUE"),
        hardware=list(hardware or []),
        xacro=xacro,
        package_paths=parse_pairs(list(package_path or []), "=", "--package-path", "PKG=DIR"),
        robot=robot,
        zenoh_config=zenoh_config,
    )
    if sim_option and not (sim or sim_fresh) and not ctx.resilient_parsing:
        raise InvalidInput("--sim-option is for the simulator --sim starts: add --sim "
                           "(or give the option to 'deltoctl sim serve')")
    if robot and not ctx.resilient_parsing:
        from deltoctl.cli.fleet_cmd import forward

        forward(ctx)  # runs the verb on the robot and exits with its code


def _logging(verbose: int, log_file: str | None) -> None:
    """Logging and the packet trace, set up only when asked for (and reset when a previous
    command in this process asked: CliRunner runs many)."""
    if verbose or log_file or "deltoctl.trace" in sys.modules:
        from deltoctl import trace

        trace.configure(verbose, log_file)


@functools.cache
def _command_tree() -> Any:
    return typer.main.get_command(app)


def command_path(args: Sequence[str]) -> tuple[tuple[str, ...], frozenset[str]]:
    """The verb and sub-commands a command line runs (``("gpio", "set")``) and the spellings
    of the options it gives (a flag set, an option with a value; global ones too), resolved
    as DeltoctlGroup.invoke resolves them — click's own parse, ``--`` and hoisted global
    options included — but resiliently: no callback, prompt or help runs. A command line
    click would refuse is InvalidInput; one that cannot be read otherwise is UNRESOLVED (it
    counts as moving)."""
    try:
        ctx = _command_tree().make_context("deltoctl", list(args), resilient_parsing=True)
        path: list[str] = []
        given = set(given_options(ctx))
        rest = [*ctx._protected_args, *ctx.args]
        while rest and hasattr(ctx.command, "resolve_command"):
            word = rest[0]
            name, command, rest = ctx.command.resolve_command(ctx, rest)
            if command is None:
                from deltoctl.suggest import did_you_mean

                raise InvalidInput(f"no command {' '.join([*path, word])!r}"
                                   + did_you_mean(word, ctx.command.list_commands(ctx)))
            path.append(name)
            ctx = command.make_context(name, rest, parent=ctx, resilient_parsing=True)
            given.update(given_options(ctx))
            rest = [*ctx._protected_args, *ctx.args]
        return tuple(path), frozenset(given)
    except click_exceptions.UsageError as exc:
        raise InvalidInput(exc.format_message()) from None
    except (click_exceptions.ClickException, typer.Exit, typer.Abort):
        return (verbs.UNRESOLVED,), frozenset()


verbs.provide_resolver(command_path)


def main() -> None:
    try:
        app(prog_name="deltoctl")
    except BrokenPipeError:  # e.g. `deltoctl stream | head`
        sys.stderr.close()
        sys.exit(0)
