"""``deltoctl sim serve PROFILE``: a simulated device in its own process."""

import inspect
from typing import TYPE_CHECKING, Annotated, Any, cast

import typer

from deltoctl.cli.completions import complete_joints, complete_profile
from deltoctl.cli.context import options
from deltoctl.cli.output import emit_error, say, warn
from deltoctl.errors import USAGE, InvalidInput

if TYPE_CHECKING:
    from deltoctl.registry import SimOption

app = typer.Typer(help="Simulated devices that speak the real protocol.", no_args_is_help=True)


def serve(
    ctx: typer.Context,
    profile: Annotated[str | None, typer.Argument(
        metavar="[PROFILE]", autocompletion=complete_profile,
        help="Catalog name or file; default: --profile.")] = None,
    *,
    host: Annotated[str, typer.Option(help="Address to listen on.")] = "127.0.0.1",
    port: Annotated[int, typer.Option(help="Port to listen on (0: any free one).")] = 0,
    env: Annotated[bool, typer.Option(
        "--env", help="Print the targets as one line for a POSIX shell to source: export "
                      "DELTOCTL_TARGET='BUS=URL …'.")] = False,
    private: Annotated[bool, typer.Option(
        "--private", help="Keep this simulator to -t: --sim does not use it.")] = False,
    **given: Any,
) -> None:
    """Serve every block's simulated device until Ctrl-C or SIGTERM, printing one target per
    bus (--target 'BUS=URL', quoted for a POSIX shell; --env: one export line).

    Each family's emulator serves its blocks behind a real link, with the faults and settings
    the family declares (below). --hardware serves some blocks only; --json prints one line.
    A device that can be turned or moved from outside answers control lines on the standard
    input, one a line (face -x, hand elbow_flex 30 …); the line help lists them.

    While it runs, --sim of the same profile (same content and faults) drives it instead of
    starting a simulator of its own, so a robot homed by one command stays homed for the
    next; --sim-fresh or --private keep them apart."""
    from deltoctl.sim.serve import ServeOptions, serve_until_stopped

    opts = options(ctx)
    prof = opts.load_profile(profile)
    faults = {name: value for name, value in given.items() if value not in (None, False, [])}
    if env and opts.json:
        raise InvalidInput("--env or --json, not both")
    serve_until_stopped(prof, ServeOptions(host=host, port=port, **faults), opts.hardware,
                        opts.json, say, lambda m: emit_error(m, None, USAGE, opts.json),
                        env=env, private=private, note=warn)


def _parameter(option: "SimOption") -> inspect.Parameter:
    """A family's declared option as a typer option of `sim serve`: given or not (None,
    False, no joints), converted and checked by its declaration when the profile is served."""
    shown = option.default if option.default not in (None, (), False) else None
    if isinstance(shown, tuple):
        shown = ",".join(format(x, "g") for x in shown)
    elif isinstance(shown, int) and option.kind == "int" and option.high == 0xFF:
        shown = f"{shown:#04x}"
    info: dict[str, Any] = {
        "help": option.help + (f" Default: {shown}." if shown is not None else ""),
        "metavar": option.metavar or ("JOINT" if option.kind == "joints" else None),
        "show_default": False}
    if option.kind == "joints":
        info["autocompletion"] = complete_joints  # of PROFILE or --profile
    kind: Any = {"flag": bool, "joints": list[str] | None}.get(option.kind, str | None)
    default: Any = False if option.kind == "flag" else None
    return inspect.Parameter(option.name, inspect.Parameter.KEYWORD_ONLY, default=default,
                             annotation=Annotated[kind, typer.Option(option.flag, **info)])


def _command() -> Any:
    """`sim serve` with the options the families declare (each once: a name several
    families share, such as --missing, is one option)."""
    from deltoctl import registry
    from deltoctl.cmdline import GLOBAL_OPTIONS

    fixed = [p for p in inspect.signature(serve).parameters.values()
             if p.kind != inspect.Parameter.VAR_KEYWORD]  # ctx, PROFILE, --host, --port …
    declared = [_parameter(o) for o in registry.sim_options().values()
                if o.flag not in GLOBAL_OPTIONS]

    def command(**kwargs: Any) -> None:
        serve(**kwargs)

    command.__doc__ = serve.__doc__
    cast(Any, command).__signature__ = inspect.Signature(fixed + declared)  # what typer reads
    return command


def register(root: typer.Typer) -> None:
    app.command("serve")(_command())  # built now: the families installed are the options
    root.add_typer(app, name="sim")
