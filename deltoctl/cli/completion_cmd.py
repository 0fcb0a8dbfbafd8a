"""``deltoctl completion SHELL``: the shell completion script (also shipped in completions/)."""

from typing import Annotated

import typer

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
            help="bash, zsh or fish.",
            autocompletion=lambda incomplete: [s for s in SHELLS if s.startswith(incomplete)])],
    ) -> None:
        """Print the completion script for a shell (see README: Shell completion)."""
        from deltoctl.errors import InvalidInput

        if shell not in SHELLS:
            raise InvalidInput(f"unknown shell {shell!r} (expected one of: {', '.join(SHELLS)})")
        typer.echo(completion_script(shell), nl=False)
