"""Asking before a command acts on the robot, by one rule derived from the verb table
(deltoctl.verbs): a command that actuates or moves, with the options its command line gives,
asks on a terminal and needs --yes without one; a command that reads never asks. Each verb
says what it is about to do; none decides whether to ask."""

import sys
from typing import Any

from deltoctl import verbs
from deltoctl.cli.context import given_options, options
from deltoctl.errors import Refused

_QUESTION = {verbs.MOVES: "Move?", verbs.ACTUATES: "Go on?"}
_NOT_CONFIRMED = "not confirmed; nothing was done"


def confirm(ctx: Any, what: str) -> None:
    """Go on when the command reads, with --yes, or on a yes at ``WHAT. Move?``; else Refused
    (exit 5) naming --yes. Ctrl-C at the question raises KeyboardInterrupt (exit 130)."""
    chain = []
    while ctx is not None:
        chain.append(ctx)
        ctx = ctx.parent
    command = verbs.Command(" ".join(c.info_name for c in reversed(chain[:-1])),
                            {o for c in chain for o in given_options(c)})
    effect = verbs.effect(command)
    if effect == verbs.READS or options(chain[0]).yes:
        return
    if not on_terminal():
        raise Refused(f"needs confirmation, and no terminal to ask on (pass --yes): {what}",
                      "pass --yes (-y) to go ahead without asking")
    if not asked(f"{what}. {_QUESTION.get(effect, 'Move?')}"):
        raise Refused(_NOT_CONFIRMED, "answer y, or pass --yes (-y) to go ahead without asking")


def confirmed_remotely(opts: Any, what: str) -> bool:
    """For a command another computer runs: True on a yes at ``WHAT. Go on?`` (the command
    line then carries --yes); False without asking with --yes or without a terminal (the robot
    refuses as a local run would); a no is Refused here."""
    if opts.yes or not on_terminal():
        return False
    if not asked(f"{what}. Go on?"):
        raise Refused(_NOT_CONFIRMED)
    return True


def on_terminal() -> bool:
    return sys.stdin.isatty()


def asked(question: str) -> bool:
    """Whether the answer to ``question`` on the terminal is y or yes."""
    sys.stderr.write(f"{question} [y/N]: ")
    sys.stderr.flush()
    return sys.stdin.readline().strip().lower() in ("y", "yes")
