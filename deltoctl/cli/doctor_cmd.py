"""``deltoctl doctor [-p PROFILE]``: what stops a bring-up, found before any byte is sent
(deltoctl.app.doctor). Exit 0 only when every check passes: 2 when the profile or a target is
invalid, 4 when a device cannot be reached or opened."""

from __future__ import annotations

from typing import Annotated

import typer

from deltoctl.app.doctor import diagnose, exit_code, install_udev_rule, udev_rule_text
from deltoctl.cli.context import options
from deltoctl.cli.output import emit_json, info, say
from deltoctl.render.doctor import doctor_lines
from deltoctl.verb_help import DESCRIPTIONS


def register(app: typer.Typer) -> None:
    app.command("doctor", help=DESCRIPTIONS["doctor"])(doctor)


def doctor(
    ctx: typer.Context,
    timeout: Annotated[float, typer.Option(
        "--timeout", help="Seconds to wait for each target to accept a connection.")] = 1.0,
    udev_rule: Annotated[bool, typer.Option(
        "--udev-rule", help="Print a udev rule for the serial adapters (the profile's buses, "
                            "or all): a named /dev link each and a 1 ms latency timer.")] = False,
    write_udev_rule: Annotated[bool, typer.Option(
        "--write-udev-rule", help="Install that rule (root), then udevadm reload and "
                                  "trigger.")] = False,
) -> None:
    opts = options(ctx)
    if udev_rule or write_udev_rule:
        text = udev_rule_text(opts.profile, opts.load_profile, opts.target, opts.hardware)
        for line in install_udev_rule(text) if write_udev_rule else [text.rstrip("\n")]:
            (info if write_udev_rule else say)(line)
        return
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

