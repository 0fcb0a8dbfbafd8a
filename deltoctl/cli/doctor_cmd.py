"""``deltoctl doctor [-p PROFILE]``: what stops a bring-up, found before any byte is sent
(deltoctl.app.doctor). Exit 0 only when every check passes: 2 when the profile or a target is
invalid, 4 when a device cannot be reached or opened."""

from __future__ import annotations

from typing import Annotated

import typer

from deltoctl.app.doctor import diagnose, exit_code
from deltoctl.cli.context import options
from deltoctl.cli.output import emit_json, say
from deltoctl.render.doctor import doctor_lines


def register(app: typer.Typer) -> None:
    app.command("doctor")(doctor)


def doctor(
    ctx: typer.Context,
    timeout: Annotated[float, typer.Option(
        "--timeout", help="Seconds to wait for each target to accept a connection.")] = 1.0,
) -> None:
    """Check the set-up before a bring-up: profile, ports, buses, routes, targets.

    One line per check with the fix to type; exit 0 only when all pass. Without -p: the
    -t URLs, or what each transport finds on this host (its ports and buses)."""
    opts = options(ctx)
    result = diagnose(opts.profile, opts.load_profile, opts.target, opts.hardware, opts.sim,
                      timeout)
    if opts.json:
        emit_json(result)
    else:
        for line in doctor_lines(result["checks"]):
            say(line)
    code = exit_code(result["checks"])
    if code:
        raise typer.Exit(code)
