"""``deltoctl sim serve PROFILE``: a simulated device in its own process."""

import inspect
from typing import TYPE_CHECKING, Annotated, Any, cast

import typer

from deltoctl.cli.completions import complete_joints, complete_profile
from deltoctl.cli.context import options
from deltoctl.cli.output import emit_error, say, warn
from deltoctl.errors import USAGE, InvalidInput
from deltoctl.verb_help import DESCRIPTIONS

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
    info: dict[str, Any] = {
        "help": option.described(),
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

    cast(Any, command).__signature__ = inspect.Signature(fixed + declared)  # what typer reads
    return command


def register(root: typer.Typer) -> None:
    # built now: the families installed are the options
    app.command("serve", help=DESCRIPTIONS["sim serve"])(_command())
    root.add_typer(app, name="sim")
