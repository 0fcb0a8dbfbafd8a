"""``deltoctl sim serve PROFILE``: a simulated device in its own process."""

import contextlib
import inspect
from typing import TYPE_CHECKING, Annotated, Any, cast

import typer

from deltoctl.cli.context import options

if TYPE_CHECKING:
    from deltoctl.registry import SimOption

app = typer.Typer(help="Simulated devices that speak the real protocol.", no_args_is_help=True)


def _complete_profile(incomplete: str) -> list[str]:
    from deltoctl.cli.profile_cmd import _complete_profile as names

    return names(incomplete)


def _complete_joint(ctx: typer.Context, incomplete: str) -> list[str]:
    """Joints of the PROFILE argument (or --profile), for the faults that name one."""
    from deltoctl.cli.profile_cmd import complete_joints

    return complete_joints(ctx, incomplete)


def serve(ctx: typer.Context, profile: str | None, host: str, port: int,
          **given: Any) -> None:
    """Serve every block's simulated device until Ctrl-C or SIGTERM, printing one target per
    bus (BUS=URL, ready for --target).

    Each family's emulator serves its blocks behind a real link, with the faults and settings
    the family declares (below). --hardware serves some blocks only; --json prints one line."""
    import gc
    import json
    import signal
    import sys
    import threading

    from deltoctl.sim.serve import ServeOptions, serve_profile

    opts = options(ctx)
    prof = opts.load_profile(profile)
    faults = {name: value for name, value in given.items() if value not in (None, False, [])}
    serve_options = ServeOptions(host=host, port=port, **faults)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    gc.disable()  # a served device answers within microseconds; no collector pauses
    with contextlib.ExitStack() as stack:
        info = serve_profile(stack, prof, serve_options, opts.hardware)
        if opts.json:
            typer.echo(json.dumps(info))
        else:
            typer.echo("\n".join(f"--target {bus}={url}" for bus, url in info["buses"].items()))
        sys.stdout.flush()
        with contextlib.suppress(KeyboardInterrupt):
            stop.wait()


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
        info["autocompletion"] = _complete_joint
    kind: Any = {"flag": bool, "joints": list[str] | None}.get(option.kind, str | None)
    default: Any = False if option.kind == "flag" else None
    return inspect.Parameter(option.name, inspect.Parameter.KEYWORD_ONLY, default=default,
                             annotation=Annotated[kind, typer.Option(option.flag, **info)])


def _command() -> Any:
    """`sim serve` with the options the families declare (each once: a name several
    families share, such as --missing, is one option)."""
    from deltoctl import registry
    from deltoctl.cmdline import GLOBAL_OPTIONS

    fixed = [
        inspect.Parameter("ctx", inspect.Parameter.POSITIONAL_OR_KEYWORD,
                          annotation=typer.Context),
        inspect.Parameter("profile", inspect.Parameter.POSITIONAL_OR_KEYWORD, default=None,
                          annotation=Annotated[str | None, typer.Argument(
                              metavar="[PROFILE]", autocompletion=_complete_profile,
                              help="Catalog name or file; default: --profile.")]),
        inspect.Parameter("host", inspect.Parameter.KEYWORD_ONLY, default="127.0.0.1",
                          annotation=Annotated[str, typer.Option(
                              help="Address to listen on.")]),
        inspect.Parameter("port", inspect.Parameter.KEYWORD_ONLY, default=0,
                          annotation=Annotated[int, typer.Option(
                              help="Port to listen on (0: any free one).")]),
    ]
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
