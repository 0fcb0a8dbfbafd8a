"""``deltoctl ports``: the serial adapters, CAN interfaces and I2C adapters of this computer,
read from sysfs and udev's links (deltoctl.transport.adapters); nothing is opened."""

from __future__ import annotations

import typer

from deltoctl.cli.context import options
from deltoctl.cli.output import emit_json, say
from deltoctl.verb_help import DESCRIPTIONS


def register(app: typer.Typer) -> None:
    app.command("ports", help=DESCRIPTIONS["ports"])(ports)


def ports(ctx: typer.Context) -> None:
    from deltoctl.render.ports import ports_lines
    from deltoctl.transport.adapters import inventory

    found = inventory()
    if options(ctx).json:
        emit_json(found)
        return
    for line in ports_lines(found):
        say(line)
