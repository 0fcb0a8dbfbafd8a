"""``deltoctl completion SHELL``: the shell completion script, and ``deltoctl completion man
--out DIR`` the manual pages (both shipped in completions/)."""

from pathlib import Path
from typing import Annotated

import typer

from deltoctl.errors import EXIT_CODES, InvalidInput

SHELLS = ("bash", "zsh", "fish")
SCRIPT_FILES = {"bash": "deltoctl.bash", "zsh": "_deltoctl", "fish": "deltoctl.fish"}


def completion_script(shell: str) -> str:
    from typer._completion_shared import get_completion_script

    script = get_completion_script(prog_name="deltoctl", complete_var="_DELTOCTL_COMPLETE",
                                   shell=shell)
    return script.rstrip("\n") + "\n"


def register(app: typer.Typer) -> None:
    @app.command("completion")
    def completion(
        shell: Annotated[str, typer.Argument(
            help="bash, zsh or fish; or man: the manual pages, written to --out DIR.",
            autocompletion=lambda incomplete: [s for s in (*SHELLS, "man")
                                               if s.startswith(incomplete)])],
        out: Annotated[Path | None, typer.Option(
            "--out", metavar="DIR", help="Where the manual pages go (with man).")] = None,
    ) -> None:
        """Print the completion script for a shell (`deltoctl help shell-completion`), or write
        the manual pages (deltoctl.1, deltoctl-VERB.1) to a directory."""
        if shell == "man":
            write_manpages(out)
            return
        if shell not in SHELLS:
            raise InvalidInput(f"unknown shell {shell!r} (expected one of: "
                               f"{', '.join(SHELLS)}, or man)")
        typer.echo(completion_script(shell), nl=False)


def write_manpages(out: Path | None) -> None:
    """Every manual page into ``out``, one line each said on stderr."""
    from deltoctl.cli.output import info

    if out is None or not out.is_dir():
        raise InvalidInput("completion man needs --out DIR, an existing directory")
    for name, text in manual_pages().items():
        try:
            (out / name).write_text(text, encoding="utf-8")
        except OSError as exc:
            raise InvalidInput(f"cannot write {out / name}: {exc.strerror}") from None
        info(f"wrote {out / name}")


def manual_pages() -> dict[str, str]:
    """deltoctl's manual pages, rendered from its command tree: file name → roff text."""
    from typer.main import get_command

    from deltoctl.cli.main import app
    from deltoctl.render.manpages import pages

    return pages(get_command(app), EXIT_CODES)
