"""``deltoctl ports``: the serial adapters, CAN interfaces and I2C adapters of this computer,
read from sysfs and udev's links (deltoctl.transport.adapters); nothing is opened."""

from __future__ import annotations

import typer

from deltoctl.cli.context import options
from deltoctl.cli.output import emit_json, say


def register(app: typer.Typer) -> None:
    app.command("ports")(ports)


def ports(ctx: typer.Context) -> None:
    """List the adapters a robot hangs on: serial, CAN and I2C.

    Each serial adapter with its stable path (/dev/serial/by-id/…) or usb:VID:PID:SERIAL
    target, USB IDs, driver, FTDI latency timer, the rates its driver refuses, access and who
    holds it; each CAN interface with its state, bit rate and error counters; each I2C
    adapter by name. Nothing is opened or sent."""
    from deltoctl.render.ports import ports_lines
    from deltoctl.transport.adapters import inventory

    found = inventory()
    if options(ctx).json:
        emit_json(found)
        return
    for line in ports_lines(found):
        say(line)
