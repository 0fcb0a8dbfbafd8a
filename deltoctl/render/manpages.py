"""Manual pages rendered from the CLI's command tree: ``deltoctl.1`` (the global options, the
verbs, the exit codes) and ``deltoctl-VERB.1`` per verb (its synopsis, description, options and
sub-commands, the verb table's effects and examples). ``deltoctl completion man --out DIR``
writes them; the package ships them beside the completion scripts. The tree comes in built (click's
commands, read through their attributes): nothing here parses a command line.
"""

from __future__ import annotations

import re
from typing import Any

from deltoctl import verbs

SECTION = "1"


def pages(root: Any, exit_codes: tuple[tuple[int, str], ...]) -> dict[str, str]:
    """file name → roff text, for deltoctl (``root``: its click group) and each verb."""
    ctx = _context(root, "deltoctl")
    commands = {name: root.get_command(ctx, name) for name in root.list_commands(ctx)}
    out = {f"deltoctl.{SECTION}": _root_page(root, ctx, commands, exit_codes)}
    for name, command in commands.items():
        out[f"deltoctl-{name}.{SECTION}"] = _verb_page(name, command, ctx, exit_codes)
    return out


def _context(command: Any, name: str, parent: Any = None) -> Any:
    """A context of ``command`` to render its usage and metavars with (its class's own)."""
    return command.context_class(command, info_name=name, parent=parent)


def _root_page(root: Any, ctx: Any, commands: dict[str, Any],
               exit_codes: tuple[tuple[int, str], ...]) -> str:
    lines = _header("deltoctl", _first_line(root.help))
    lines += [".SH SYNOPSIS", ".B deltoctl", r"[\fIGLOBAL OPTIONS\fR] \fIVERB\fR [\fIARGS\fR]..."]
    lines += [".SH DESCRIPTION", _text(root.help or ""),
              ".PP", "Global options may stand before or after the verb."]
    lines += [".SH GLOBAL OPTIONS", *_options(root, ctx)]
    lines += [".SH VERBS"]
    for name, command in commands.items():
        lines += [".TP", rf"\fB{name}\fR(1)", _text(_first_line(command.help))]
    lines += _examples({"": verbs.TABLE["identify"].example})
    lines += _exit_status(exit_codes)
    lines += [".SH SEE ALSO", ", ".join(rf"\fBdeltoctl\-{n}\fR({SECTION})" for n in commands)]
    return "\n".join(lines) + "\n"


def _verb_page(name: str, command: Any, parent: Any,
               exit_codes: tuple[tuple[int, str], ...]) -> str:
    ctx = _context(command, name, parent)
    lines = _header(f"deltoctl-{name}", _first_line(command.help))
    lines += [".SH SYNOPSIS", *_synopsis(f"deltoctl {name}", command, ctx)]
    lines += [".SH DESCRIPTION", _text(command.help or "")]
    own = _options(command, ctx)
    if own:
        lines += [".SH OPTIONS", *own]
    subs = getattr(command, "commands", {})
    if subs:
        lines += [".SH COMMANDS"]
        for sub_name, sub in subs.items():
            sub_ctx = _context(sub, sub_name, ctx)
            lines += [".SS " + _escape(f"{name} {sub_name}"), *_synopsis(
                f"deltoctl {name} {sub_name}", sub, sub_ctx), ".PP", _text(sub.help or "")]
            options = _options(sub, sub_ctx)
            if options:
                lines += [".PP", "Options:", *options]
    paths = [path for path, _ in verbs.walk() if path == name or path.startswith(name + " ")]
    lines += [".SH EFFECT ON THE ROBOT"]
    for path in paths:
        lines += [".TP", rf"\fB{_escape(path)}\fR", _escape(verbs.describe(path))]
    entries = {path: v.example for path in paths if (v := verbs.lookup(path)) and v.example}
    lines += _examples(entries)
    lines += _exit_status(exit_codes)
    lines += [".SH SEE ALSO", rf"\fBdeltoctl\fR({SECTION})"]
    return "\n".join(lines) + "\n"


def _header(name: str, summary: str) -> list[str]:
    return [f'.TH "{name.upper()}" "{SECTION}" "" "deltoctl" "deltoctl manual"',
            ".SH NAME", _escape(name) + r" \- " + _escape(summary)]


def _synopsis(path: str, command: Any, ctx: Any) -> list[str]:
    pieces = " ".join(command.collect_usage_pieces(ctx))
    return [".B " + _escape(path), _escape(pieces)]


def _options(command: Any, ctx: Any) -> list[str]:
    """Each option (and argument) of a command: ``.TP``, its spellings and value, its help."""
    lines: list[str] = []
    for param in command.params:
        if getattr(param, "hidden", False) or param.name in ("help",):
            continue
        if param.param_type_name == "argument":
            lines += [".TP", rf"\fI{_escape(param.make_metavar(ctx))}\fR",
                      _text(getattr(param, "help", None) or "")]
            continue
        spellings = ", ".join(_escape(o) for o in [*param.opts, *param.secondary_opts])
        value = "" if param.is_flag or param.count else \
            rf" \fI{_escape(param.make_metavar(ctx))}\fR"
        lines += [".TP", rf"\fB{spellings}\fR{value}", _text(param.help or "")]
    return lines


def _examples(entries: dict[str, str]) -> list[str]:
    if not entries:
        return []
    lines = [".SH EXAMPLES"]
    for example in entries.values():
        lines += [".PP", ".nf", _escape(example), ".fi"]
    return lines


def _exit_status(exit_codes: tuple[tuple[int, str], ...]) -> list[str]:
    lines = [".SH EXIT STATUS"]
    for code, meaning in exit_codes:
        lines += [".TP", rf"\fB{code}\fR", _escape(meaning)]
    return lines


def summary(text: str | None) -> str:
    """A help in one line: the first sentence of its first paragraph, up to a colon, a
    semicolon or a bracket (``What a recording holds``)."""
    import re

    first = " ".join((text or "").split("\n\n")[0].split())
    return re.split(r"\. |: |; | \(", first, maxsplit=1)[0].rstrip(".")


def _first_line(text: str | None) -> str:
    return (text or "").strip().split("\n\n")[0].replace("\n", " ").replace("\\[", "[")


def _text(text: str) -> str:
    """A help text as roff paragraphs (typer's markup escapes and backticks removed)."""
    text = text.replace("\\[", "[").replace("`", "")
    paragraphs = [" ".join(p.split()) for p in text.strip().split("\n\n") if p.strip()]
    return "\n.PP\n".join(_escape(p) for p in paragraphs)


def _escape(text: str) -> str:
    """Plain text safe in roff: backslashes, hyphens, and a leading dot or quote."""
    text = text.replace("\\", r"\e").replace("-", r"\-")
    return re.sub(r"^([.'])", r"\\&\1", text, flags=re.MULTILINE)
