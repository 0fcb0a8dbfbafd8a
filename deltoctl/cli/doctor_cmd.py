"""``deltoctl doctor [-p PROFILE]``: what stops a bring-up, found before any byte is sent
(deltoctl.app.doctor). Exit 0 only when every check passes: 2 when the profile or a target is
invalid, 4 when a device cannot be reached or opened."""

from __future__ import annotations

from typing import Annotated

import typer

from deltoctl.app.doctor import diagnose, exit_code
from deltoctl.cli.context import Options, options
from deltoctl.cli.output import emit_json, info, say
from deltoctl.render.doctor import doctor_lines


def register(app: typer.Typer) -> None:
    app.command("doctor")(doctor)


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
    """Check the set-up before a bring-up: profile, ports, buses, routes, targets.

    One line per check with the fix to type; exit 0 only when all pass. Without -p: the
    -t URLs, or what each transport finds on this host (its ports and buses)."""
    opts = options(ctx)
    if udev_rule or write_udev_rule:
        _udev(opts, write_udev_rule)
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


def _udev(opts: Options, write: bool) -> None:
    """Print, or install, the udev rule of the profile's serial adapters (all, without -p)."""
    from deltoctl.app.doctor import rule_adapters, write_udev_rule
    from deltoctl.errors import Unreachable
    from deltoctl.transport.adapters import udev_rule

    chosen = rule_adapters(opts.profile, opts.load_profile, opts.target, opts.hardware)
    if not chosen:
        raise Unreachable("no USB serial adapter to name", hint="plug it in; deltoctl ports "
                                                                "lists the adapters")
    text = udev_rule(chosen)
    if not write:
        say(text.rstrip("\n"))
        return
    for line in write_udev_rule(text):
        info(line)
