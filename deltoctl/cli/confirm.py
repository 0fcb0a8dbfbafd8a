"""Asking before a command acts on the robot, by one rule derived from the verb table
(``deltoctl.verbs``): a command whose effect, with the options its command line gives, is to
actuate or to move asks on a terminal and needs ``--yes`` without one; a command that reads
never asks. Each verb says what it is about to do; none decides whether to ask."""

from __future__ import annotations

import sys
from typing import Any

from deltoctl import verbs
from deltoctl.cli.context import options
from deltoctl.errors import Refused

_QUESTION = {verbs.MOVES: "Move?", verbs.ACTUATES: "Go on?"}


def running(ctx: Any) -> verbs.Command:
    """The command a context runs (``gpio set``) and the options its command line gives,
    the global ones too."""
    from deltoctl.cli.main import given_options

    chain = []
    while ctx is not None:
        chain.append(ctx)
        ctx = ctx.parent
    chain.reverse()
    path = " ".join(c.info_name for c in chain[1:])
    return verbs.Command(path, {o for c in chain for o in given_options(c)})


def confirm(ctx: Any, what: str) -> None:
    """Go on when the command only reads, when --yes was given, or when the user says yes at
    ``WHAT. Move?`` on a terminal; otherwise Refused (exit 5) naming --yes. Ctrl-C at the
    question interrupts (exit 130)."""
    effect = verbs.effect(running(ctx))
    if effect == verbs.READS or options(ctx).yes:
        return
    if not on_terminal():
        raise Refused(f"needs confirmation, and no terminal to ask on (pass --yes): {what}",
                      "pass --yes (-y) to go ahead without asking")
    if not asked(f"{what}. {_QUESTION.get(effect, _QUESTION[verbs.MOVES])}"):
        raise Refused("not confirmed; nothing was done",
                      "answer y to go ahead, or pass --yes (-y) to go ahead without asking")


def on_terminal() -> bool:
    """Whether there is a person to ask: standard input is a terminal."""
    return sys.stdin.isatty()


def asked(question: str) -> bool:
    """Whether the user answers y (or yes) to ``question`` on the terminal; anything else,
    an empty line or the end of input is no. Ctrl-C raises KeyboardInterrupt."""
    sys.stderr.write(f"{question} [y/N]: ")
    sys.stderr.flush()
    return sys.stdin.readline().strip().lower() in ("y", "yes")
