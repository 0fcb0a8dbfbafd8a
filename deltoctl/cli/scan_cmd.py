"""``deltoctl scan PORT|URL``: what answers on a serial link, no profile (deltoctl.app.scan)."""

from __future__ import annotations

from typing import Annotated

import typer

from deltoctl.cli.context import options
from deltoctl.cli.output import emit_json, show, warn
from deltoctl.errors import WARNINGS


def register(app: typer.Typer) -> None:
    app.command("scan")(scan)


def scan(ctx: typer.Context, link: Annotated[str, typer.Argument(
             help="A serial port, a serial:// / usb: target, or a link URL "
                  "an installed family scans (its scheme).")],
         wait: Annotated[float, typer.Option("--wait", min=0.001, max=1.0,
                                             help="Seconds to wait for a reply.")] = 0.01,
         every: Annotated[bool, typer.Option(
             "--all", help="Every rate and protocol, not up to the first that answers.")] = False,
         ) -> None:
    """Find the servos on a link at any baud rate and protocol the installed families speak.

    Broadcasts at the common rates first, then per-ID sweeps; a table of what answers (ID,
    model, firmware, baud, protocol) and the bus time the scan took. A link of another kind
    (a CAN bus) is scanned by its family: its nodes, and its parts that have no ID yet."""
    from deltoctl.app.scan import scan as run
    from deltoctl.render.scan import collision_lines, scan_parts

    result = run(link, wait, every)
    emit_json(result) if options(ctx).json else show(scan_parts(result))
    for line in collision_lines(result):
        warn(line)
    if collision_lines(result):
        raise typer.Exit(WARNINGS)
