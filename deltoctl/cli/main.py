"""The ``deltoctl`` application: global options, error handling and the verb registry.

Global options are accepted before the verb and after it (``deltoctl --json identify`` and
``deltoctl identify --json``): the root group moves them to the front before parsing.
"""

import re
import sys
from typing import Annotated, Any

import typer
from typer._click import exceptions as click_exceptions
from typer.core import TyperGroup

from deltoctl import __version__
from deltoctl.cli.context import Options, parse_pairs
from deltoctl.errors import DeltoctlError

# option spellings → whether they take a value
GLOBAL_OPTIONS: dict[str, bool] = {
    "--profile": True, "-p": True, "--target": True, "-t": True, "--arg": True,
    "--package-path": True, "--hardware": True, "--xacro": False, "--sim": False,
    "--json": False, "--yes": False, "-y": False, "--verbose": False, "--quiet": False, "-q": False,
}
_VERBOSE = re.compile(r"^-v+$")


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
        name = arg.split("=", 1)[0]
        is_global = name in GLOBAL_OPTIONS or bool(_VERBOSE.match(arg))
        takes_value = GLOBAL_OPTIONS.get(name, False) and "=" not in arg
        if not tail and not arg.startswith("-"):
            tail.append(arg)  # the verb
        elif tail and not is_global:
            tail.append(arg)
        else:
            group = hoisted if tail else head
            group.append(arg)
            if takes_value and i + 1 < len(args):
                group.append(args[i + 1])
                i += 1
        i += 1
    return head + hoisted + tail


# verb → the module of deltoctl.cli whose register(app) adds it. A module is imported only
# when one of its verbs runs: every line of a bring-up script pays for what it imports.
VERBS = {
    "profile": "profile_cmd", "connect": "device_cmd", "identify": "device_cmd",
    "detect": "device_cmd", "home": "motion_cmd", "jog": "motion_cmd",
    "calibrate": "calibrate_cmd", "gpio": "device_cmd", "stream": "device_cmd",
    "record": "record_cmd", "torque": "servo_cmd", "reboot": "servo_cmd",
    "register": "servo_cmd",
    "sim": "sim_cmd", "bench": "bench_cmd",
    "completion": "completion_cmd",
}


class DeltoctlGroup(TyperGroup):
    """Loads verbs on demand, hoists global options, and turns DeltoctlError into one line
    and its exit code."""

    def list_commands(self, ctx: Any) -> list[str]:
        return list(VERBS)

    def get_command(self, ctx: Any, cmd_name: str) -> Any:
        if cmd_name not in self.commands and cmd_name in VERBS:
            import importlib

            from typer.main import get_group

            module = importlib.import_module(f"deltoctl.cli.{VERBS[cmd_name]}")
            holder = typer.Typer()
            module.register(holder)
            self.commands.update(get_group(holder).commands)
        return self.commands.get(cmd_name)

    def parse_args(self, ctx: Any, args: list[str]) -> list[str]:
        return super().parse_args(ctx, hoist_global_options(list(args)))

    def invoke(self, ctx: Any) -> Any:
        try:
            return super().invoke(ctx)
        except DeltoctlError as exc:
            typer.echo(f"deltoctl: error: {exc.message}", err=True)
            if exc.hint:
                typer.echo(f"  hint: {exc.hint}", err=True)
            raise typer.Exit(exc.exit_code) from None
        except KeyboardInterrupt:
            typer.echo("deltoctl: interrupted", err=True)
            raise typer.Exit(130) from None
        except (typer.Exit, typer.Abort, click_exceptions.ClickException):
            raise
        except BrokenPipeError:  # the reader went away (`| head`): stop quietly
            import os
            import sys

            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            raise typer.Exit(0) from None
        except Exception as exc:  # a bug: one line for people, the traceback with -v
            if ctx.obj is not None and getattr(ctx.obj, "verbose", 0):
                raise
            typer.echo(f"deltoctl: internal error: {type(exc).__name__}: {exc} "
                       "(run with -v for the traceback, and please report it)", err=True)
            raise typer.Exit(1) from None


app = typer.Typer(
    cls=DeltoctlGroup,
    name="deltoctl",
    help="Bring-up toolkit for robot hardware: profiles, lifecycle verbs, simulated devices.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"deltoctl {__version__}")
        raise typer.Exit()


def _complete_profile(incomplete: str) -> list[str]:
    from deltoctl.profile.catalog import catalog_names

    return [n for n in catalog_names() if n.startswith(incomplete)]


def _complete_hardware(ctx: typer.Context, incomplete: str) -> list[str]:
    from deltoctl.cli.profile_cmd import complete_blocks

    return complete_blocks(ctx, incomplete)


@app.callback()
def root(
    ctx: typer.Context,
    profile: Annotated[str | None, typer.Option(
        "--profile", "-p", envvar="DELTOCTL_PROFILE", autocompletion=_complete_profile,
        help="Device profile: a catalog name or a YAML/URDF/xacro file.")] = None,
    target: Annotated[list[str] | None, typer.Option(
        "--target", "-t", envvar="DELTOCTL_TARGET",
        help="Where the device is: [BUS=]URL, e.g. tcp://169.254.186.72:502 (repeatable).")] = None,
    sim: Annotated[bool, typer.Option(
        "--sim", help="Run against a simulated device started for this command.")] = False,
    json_out: Annotated[bool, typer.Option(
        "--json", help="Write one JSON document (NDJSON for streams) on stdout.")] = False,
    yes: Annotated[bool, typer.Option(
        "--yes", "-y", help="Do not ask for confirmation before motion.")] = False,
    verbose: Annotated[int, typer.Option(
        "--verbose", "-v", count=True, help="More diagnostics on stderr.")] = 0,
    quiet: Annotated[bool, typer.Option(
        "--quiet", "-q", help="Fewer diagnostics on stderr.")] = False,
    xacro_arg: Annotated[list[str] | None, typer.Option(
        "--arg", metavar="NAME:=VALUE", help="A xacro argument (repeatable).")] = None,
    hardware: Annotated[list[str] | None, typer.Option(
        "--hardware", metavar="NAME", autocompletion=_complete_hardware,
        help="Only this <ros2_control> block of the profile (repeatable; default: all).")]
        = None,
    xacro: Annotated[bool, typer.Option(
        "--xacro", help="Run xacro on a profile file that is not named .xacro.")] = False,
    package_path: Annotated[list[str] | None, typer.Option(
        "--package-path", metavar="PKG=DIR",
        help="Where $(find PKG) points, for xacro files (repeatable).")] = None,
    version: Annotated[bool, typer.Option(
        "--version", callback=_version, is_eager=True, help="Show the version and exit.")] = False,
) -> None:
    """Global options may come before or after the verb."""
    try:
        ctx.obj = Options(
            profile=profile,
            target=list(target or []),
            sim=sim,
            json=json_out,
            yes=yes,
            verbose=verbose,
            quiet=quiet,
            xacro_args=parse_pairs(list(xacro_arg or []), ":=", "--arg", "NAME:=VALUE"),
            hardware=list(hardware or []),
            xacro=xacro,
            package_paths=parse_pairs(list(package_path or []), "=", "--package-path", "PKG=DIR"),
        )
    except DeltoctlError as exc:
        typer.echo(f"deltoctl: error: {exc.message}", err=True)
        raise typer.Exit(exc.exit_code) from None


def main() -> None:
    try:
        app(prog_name="deltoctl")
    except BrokenPipeError:  # e.g. `deltoctl stream | head`
        sys.stderr.close()
        sys.exit(0)
