"""Rendering: data on stdout (JSON for scripts, tables for people), diagnostics on stderr.

rich is imported only when a person is looking at a terminal; scripts that pipe the output get
plain aligned text and pay no import cost for it.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import typer

from deltoctl.cli.context import DOCUMENT  # root ctx.meta key: the document, until the verb exits

if TYPE_CHECKING:
    from rich.progress import Progress


def stdout_is_terminal() -> bool:
    return sys.stdout.isatty()


WARNINGS = "deltoctl.warnings"  # root ctx.meta key: the warnings said so far
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
    from deltoctl.render.envelope import dumps

    typer.echo(dumps(data, compact=err), err=err)


def flush_document(ctx: Any, exit_code: int) -> None:
    """Write the verb's pending document in its envelope, with the exit code it ends with."""
    meta = ctx.find_root().meta
    pending = meta.pop(DOCUMENT, None)
    if pending is None:
        return
    from deltoctl.render.envelope import envelope

    verb, data, err, profile = pending
    if profile is None and verb.split(" ")[0] not in NO_PROFILE:
        profile = getattr(ctx.find_root().obj, "profile", None)
    write_json(envelope(verb, data, meta.get(WARNINGS, []), exit_code, profile), err)


def _context() -> Any:
    """The context of the command running, or None outside one."""
    from typer._click.globals import get_current_context

    return get_current_context(silent=True)


def _root() -> Any:
    return None if _context() is None else _context().find_root()


def _verb() -> str:
    """The command path of the verb running (``gpio get``)."""
    return "" if _context() is None else _context().command_path.partition(" ")[2]


def emit_json_line(data: Any) -> None:
    from deltoctl.render.envelope import dumps

    sys.stdout.write(dumps(data, compact=True) + "\n")
    sys.stdout.flush()


def emit_error(message: str, hint: str | None, exit_code: int, as_json: bool,
               **more: str) -> None:
    """An error on stderr (deltoctl.render.envelope.error_text), so stdout holds data only."""
    from deltoctl.render.envelope import error_text

    typer.echo(error_text(message, hint, exit_code, as_json, **more), err=True)


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
    return _root() is not None and bool(getattr(_root().obj, "quiet", False))


def progress(opts: Any, transient: bool = True, elapsed: bool = False) -> Progress | None:
    """A started rich Progress on stderr while a person watches; None for scripts (--json, -q,
    stderr not a terminal). stdout stays for the verb's result. ``elapsed``: the time so far
    instead of the time left."""
    if opts.json or opts.quiet or not sys.stderr.isatty():
        return None
    from deltoctl.render.progress import started_bar

    return started_bar(transient, elapsed)


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
