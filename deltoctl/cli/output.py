"""Rendering: data on stdout (JSON for scripts, tables for people), diagnostics on stderr.

rich is imported only when a person is looking at a terminal; scripts that pipe the output get
plain aligned text and pay no import cost for it.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import typer

from deltoctl.cli.context import DOCUMENT  # root ctx.meta key: the document, until the verb exits

if TYPE_CHECKING:
    from rich.progress import Progress


def stdout_is_terminal() -> bool:
    return sys.stdout.isatty()


WARNINGS = "deltoctl.warnings"  # root ctx.meta key: the warnings said so far
# verbs that report each block of the robot: ``blocks`` beside the envelope's keys, their
# other data in ``result``
BLOCK_VERBS = ("connect", "identify", "detect", "home", "jog", "calibrate ft", "calibrate imu")
# verbs that read no profile (a file, the fleet, this computer): their envelope's is null
NO_PROFILE = ("info", "plot", "help", "completion", "bench", "fleet", "ports")


def emit_json(data: Any, err: bool = False, profile: str | None = None) -> None:
    """The verb's JSON document (on stderr with ``err``: a stream's, whose stdout holds its
    frames). Inside a command it is written when the verb exits, in its envelope
    (``envelope``), which then knows the warnings and the exit code. ``profile`` names the
    profile the verb ran on when the command line does not (a remote robot's)."""
    root = _root()
    if root is None:
        write_json(data, err)
        return
    root.meta[DOCUMENT] = (_verb(), data, err, profile)


def write_json(data: Any, err: bool = False) -> None:
    import json

    if err:
        typer.echo(json.dumps(data, separators=(",", ":"), default=_jsonable), err=True)
    else:
        typer.echo(json.dumps(data, indent=2, default=_jsonable))


def envelope(verb: str, data: Any, warnings: list[str], exit_code: int,
             profile: str | None) -> dict[str, Any]:
    """Every verb's JSON in one shape, these keys and no others: ``verb``, ``profile``, the
    data — ``blocks`` for the robot's blocks, ``result`` for the rest (a verb that reports
    each block has both when it says more than its blocks: home's ``settled``) —,
    ``warnings`` and ``exit_code``."""
    named = data.get("profile") if isinstance(data, dict) else None
    profile = named if isinstance(named, str) else profile
    if verb in BLOCK_VERBS and isinstance(data, dict) and isinstance(data.get("blocks"), list):
        rest = {k: v for k, v in data.items() if k not in ("profile", "blocks")}
        body = {"blocks": data["blocks"], **({"result": rest} if rest else {})}
    else:
        body = {"result": data}
    return {"verb": verb, "profile": profile, **body, "warnings": list(warnings),
            "exit_code": exit_code}


def flush_document(ctx: Any, exit_code: int) -> None:
    """Write the verb's pending document in its envelope, with the exit code it ends with."""
    meta = ctx.find_root().meta
    pending = meta.pop(DOCUMENT, None)
    if pending is None:
        return
    verb, data, err, profile = pending
    if profile is None and verb.split(" ")[0] not in NO_PROFILE:
        profile = getattr(ctx.find_root().obj, "profile", None)
    write_json(envelope(verb, data, meta.get(WARNINGS, []), exit_code, profile), err)


def _root() -> Any:
    from typer._click.globals import get_current_context

    ctx = get_current_context(silent=True)
    return None if ctx is None else ctx.find_root()


def _verb() -> str:
    """The command path of the verb running (``gpio get``)."""
    from typer._click.globals import get_current_context

    ctx = get_current_context(silent=True)
    return "" if ctx is None else ctx.command_path.partition(" ")[2]


def emit_json_line(data: Any) -> None:
    import json

    sys.stdout.write(json.dumps(data, separators=(",", ":"), default=_jsonable) + "\n")
    sys.stdout.flush()


def _jsonable(value: Any) -> Any:
    if hasattr(value, "__fspath__"):
        return str(value)
    if isinstance(value, (set, tuple)):
        return list(value)
    raise TypeError(f"cannot write {type(value).__name__} as JSON")


def emit_error(message: str, hint: str | None, exit_code: int, as_json: bool) -> None:
    """An error on stderr: one line (and its hint) for people; with --json one object,
    ``{"error": {"message", "hint", "exit_code"}}``, so stdout holds data only."""
    if as_json:
        import json

        error = {"message": message, "hint": hint, "exit_code": exit_code}
        typer.echo(json.dumps({"error": error}), err=True)
        return
    typer.echo(f"deltoctl: error: {message}", err=True)
    if hint:
        typer.echo(f"  hint: {hint}", err=True)


def say(message: str) -> None:
    """A line of a verb's result for people, on stdout, whatever -q says (scripts ask for
    --json instead)."""
    typer.echo(message)


def info(message: str) -> None:
    """A diagnostic line for people, on stderr; -q hides it, unless it is a warning."""
    if message.startswith("warning") or not _quiet():
        typer.echo(message, err=True)


def warn(message: str) -> None:
    """A warning on stderr, shown even with -q (it explains an exit code of 3); the verb's
    JSON document lists it too."""
    typer.echo(f"warning: {message}", err=True)
    root = _root()
    if root is not None:
        root.meta.setdefault(WARNINGS, []).append(message)


def _quiet() -> bool:
    from typer._click.globals import get_current_context

    ctx = get_current_context(silent=True)
    return ctx is not None and bool(getattr(ctx.find_root().obj, "quiet", False))


def progress(opts: Any, transient: bool = True, elapsed: bool = False) -> Progress | None:
    """A started rich Progress on stderr while a person watches; None for scripts (--json, -q,
    stderr not a terminal). stdout stays for the verb's result. ``elapsed``: the time so far
    instead of the time left."""
    if opts.json or opts.quiet or not sys.stderr.isatty():
        return None
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    columns = ((TextColumn("{task.description}"), BarColumn(), TimeElapsedColumn()) if elapsed
               else Progress.get_default_columns())
    bar = Progress(*columns, console=Console(stderr=True), transient=transient)
    bar.start()
    return bar


def advancing(bar: Progress | None, label: str) -> Callable[[float], None] | None:
    """A task named ``label`` on ``bar`` and what moves it to a fraction done; None without
    a bar."""
    if bar is None:
        return None
    task = bar.add_task(label, total=1.0)
    return lambda fraction: bar.update(task, completed=fraction)


def show(parts: Sequence[str | tuple]) -> None:
    """Lines and tables of a result for people, in their order."""
    for part in parts:
        if isinstance(part, str):
            say(part)
        else:
            table(*part)


def table(title: str | None, columns: Sequence[str], rows: Sequence[Sequence[Any]]) -> None:
    """A table of a verb's result on stdout (deltoctl.render.table)."""
    from deltoctl.render.table import cells, plain_lines, print_rich

    text = cells(rows)
    if stdout_is_terminal():
        print_rich(title, columns, text)
    else:
        typer.echo("\n".join(plain_lines(title, columns, text)))
