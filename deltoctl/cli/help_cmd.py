"""``deltoctl help [TOPIC | examples [--copy DIR] | schema VERB | VERB …]``."""

from pathlib import Path
from typing import Annotated

import typer

from deltoctl import verbs
from deltoctl.cli.context import TEACH, options
from deltoctl.cli.output import emit_json, info, stdout_is_terminal, table
from deltoctl.errors import EXIT_CODES, InvalidInput
from deltoctl.verb_help import DESCRIPTIONS


def register(holder: typer.Typer) -> None:
    holder.command("help", help=DESCRIPTIONS["help"])(help_cmd)


def _topics() -> list[str]:
    from deltoctl.topics_lookup import topic_names

    return ["exit-codes", "examples", "schema", *topic_names()]


def help_cmd(
    ctx: typer.Context,
    topic: Annotated[list[str] | None, typer.Argument(
        metavar="[TOPIC | schema VERB... | VERB...]", autocompletion=lambda incomplete: [
            t for t in (*_topics(), *verbs.modules()) if t.startswith(incomplete)],
        help="A topic (exit-codes, examples, targets, trust-model, security, "
             "shell-completion, global-options, diagnostics, pytest), schema VERB (its --json "
             "document's JSON Schema), or a verb (e.g. register get).")] = None,
    copy: Annotated[Path | None, typer.Option(
        "--copy", metavar="DIR", help="With examples: copy the shipped examples into DIR.")] = None,
    force: Annotated[bool, typer.Option(
        "--force", help="With examples --copy: overwrite examples already in DIR.")] = False,
) -> None:
    words = list(topic or [])
    if (copy is not None or force) and words != ["examples"]:
        raise InvalidInput("--copy and --force go with `deltoctl help examples`")
    if words == ["exit-codes"]:
        _exit_codes(ctx)
    elif words == ["examples"]:
        _examples(ctx, copy, force)
    elif words[:1] == ["schema"]:
        from deltoctl.schemas_lookup import schema_text

        typer.echo(schema_text(" ".join(words[1:])), nl=False)
    elif len(words) == 1 and words[0] in _topics():
        _topic(ctx, words[0])
    else:
        _verb_help(ctx, words)


def _exit_codes(ctx: typer.Context) -> None:
    if options(ctx).json:
        emit_json([{"code": c, "meaning": m} for c, m in EXIT_CODES])
    else:
        table(None, ["code", "meaning"], EXIT_CODES)


def _topic(ctx: typer.Context, name: str) -> None:
    from deltoctl.topics_lookup import topic_text

    text = topic_text(name)
    if options(ctx).json:
        emit_json({"topic": name, "text": text})
    elif stdout_is_terminal():  # drawn by rich; as written when piped
        from rich.console import Console
        from rich.markdown import Markdown

        Console().print(Markdown(text))
    else:
        typer.echo(text, nl=False)


def _examples(ctx: typer.Context, copy: Path | None, force: bool) -> None:
    from deltoctl.topics_lookup import copy_examples, examples, examples_dir

    listed = examples()
    written = [str(p) for p in copy_examples(copy, force)] if copy is not None else []
    for path in written:
        info(f"wrote {path}")
    if options(ctx).json:
        emit_json({"examples": [{"file": f, "what": w} for f, w in listed],
                   "directory": str(examples_dir()), "copied": written})
    elif copy is None:
        table(None, ["file", "what"], listed)
        info(f"in {examples_dir()}; `deltoctl help examples --copy DIR` copies them out")


def _verb_help(ctx: typer.Context, words: list[str]) -> None:
    command, cctx = ctx.find_root().command, ctx.find_root()
    cctx.meta[TEACH] = True  # the verbs loaded from here on show the global options
    for word in words:
        sub = command.get_command(cctx, word) if hasattr(command, "get_command") else None
        if sub is None:
            from deltoctl.suggest import did_you_mean

            names = getattr(command, "list_commands", lambda _: [])(cctx)
            near = did_you_mean(word, names) or did_you_mean(word, _topics())
            raise InvalidInput(f"no help topic {' '.join(words)!r}" + near)
        cctx = sub.make_context(word, [], parent=cctx, resilient_parsing=True)
        command = sub
    text = command.get_help(cctx)  # rich prints it itself and returns ""
    if text:
        typer.echo(text)
