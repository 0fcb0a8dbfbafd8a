"""What a remote command line asks for, judged on the robot: the command it runs, found by the
CLI's own parse of it (the parse that will run it) and looked up in the verb table
(deltoctl.verbs), and nothing that would choose another profile or device, serve the robot's
data elsewhere, or name a file outside the agent's directory. Global options may stand after the
verb (deltoctl.cmdline), and are judged where the CLI would take them.

A run request is bounded before it is read: its size, the number and length of its arguments;
the whole command line the agent hands its zygote fits in one message (forks.MESSAGE)."""

from __future__ import annotations

import json
import os
import re
from typing import Any

from deltoctl import verbs
from deltoctl.cmdline import hoist_global_options
from deltoctl.errors import InvalidInput
from deltoctl.fleet.forks import MESSAGE

REQUEST = MESSAGE  # bytes: the largest run request, and command line, the agent takes
MAX_ARGS = 1024  # arguments in a command line
MAX_ARG = 4096  # bytes in one argument

# options the agent sets itself (the robot's profile and links), that name a local file, or
# that would serve the robot's data beyond the agent's own transport
FORBIDDEN = ("--profile", "--target", "--sim", "--sim-fresh", "--sim-option", "--arg",
             "--package-path", "--xacro", "--log-file", "--robot", "--zenoh-config", "--foxglove",
             "--foxglove-host", "--foxglove-port")
# options that write outside the agent's directory (the shell's start-up files, the host's
# udev rules)
WRITES_OUTSIDE = ("--install-completion", "--show-completion", "--write-udev-rule")
_SHORT_FORBIDDEN = re.compile(r"-[yqv]*[pt]")  # -p, -t, -yp …: a cluster naming them


def read_request(payload: bytes) -> dict[str, Any]:
    """A run request's JSON object, its size bounded before it is parsed."""
    if len(payload) > REQUEST:
        raise InvalidInput(f"a run request of {len(payload)} bytes: the agent takes up to "
                           f"{REQUEST // 1024} KiB")
    try:
        request = json.loads(payload) if payload else None
    except (ValueError, RecursionError):  # not JSON, not UTF-8, nested too deep
        request = None
    if not isinstance(request, dict):
        raise InvalidInput("a run request is a JSON object {id, argv}")
    return request


def fits(links: list[str], argv: list[str]) -> None:
    """Refuses a command line that, with the agent's links, would not fit in one message to
    its zygote."""
    size = len(json.dumps([*links, *argv]).encode())
    if size > REQUEST:
        raise InvalidInput(f"the command line is {size} bytes with the robot's links: the "
                           f"agent runs command lines of up to {REQUEST // 1024} KiB")


def _bounded(argv: object) -> list[str]:
    """The command line of a request: a list of strings, bounded, no NUL byte."""
    if not isinstance(argv, list) or not argv:
        raise InvalidInput("the request carries no command line")
    if not all(isinstance(a, str) for a in argv):
        raise InvalidInput("a command line is a list of strings")
    if len(argv) > MAX_ARGS:
        raise InvalidInput(f"{len(argv)} arguments: a remote command line has up to {MAX_ARGS}")
    for arg in argv:
        if "\0" in arg:
            raise InvalidInput("an argument holds a NUL byte")
        try:
            size = len(arg.encode())
        except UnicodeEncodeError:
            raise InvalidInput("an argument is not valid Unicode text") from None
        if size > MAX_ARG:
            raise InvalidInput(f"an argument of {size} bytes: each takes up to {MAX_ARG}")
    return argv


def _values(arg: str) -> list[str]:
    """What in one argument may name a file: the argument, the value of ``--opt=VALUE``, and
    the value attached to a short option (``-oFILE``)."""
    values = [arg]
    if arg.startswith("--") and "=" in arg:
        values.append(arg.split("=", 1)[1])
    elif arg.startswith("-") and not arg.startswith("--") and len(arg) > 2:
        values.append(arg[2:])
    return values


def _outside(value: str, workdir: str) -> bool:
    """Whether ``value``, read as a path from ``workdir``, leads out of it (symlinks too)."""
    if value.startswith("~"):
        return True
    base = os.path.realpath(workdir)
    path = os.path.realpath(os.path.join(base, value))
    return os.path.commonpath([base, path]) != base


def _check_option(arg: str, workdir: str) -> None:
    name = arg.split("=", 1)[0]
    if name in FORBIDDEN or _SHORT_FORBIDDEN.match(arg):
        raise InvalidInput(f"{name} is not taken remotely: the agent runs the robot's "
                           "own profile and links, and serves its data only over Zenoh")
    if name in WRITES_OUTSIDE:
        raise InvalidInput(f"{name} is not taken remotely: it writes outside the agent's "
                           "directory")
    if any(_outside(v, workdir) for v in _values(arg)):
        raise InvalidInput(f"{arg!r}: a remote verb names files in the agent's directory "
                           "only (no absolute path, '~' or '..')")


def check_argv(argv: object, workdir: str = ".",
               links: list[str] | None = None) -> verbs.Command:
    """The command (``jog``, ``gpio set``) of a remote command line and the options it gives
    (its effect: ``report --yes`` moves), after checking it, as the CLI will resolve it with
    the agent's ``links`` before it; raises InvalidInput for what the agent does not run. A
    command it cannot resolve is verbs.UNRESOLVED (it counts as moving)."""
    args = _bounded(argv)
    for arg in hoist_global_options(args):
        _check_option(arg, workdir)
    path = verbs.resolve([*(links or []), *args])
    if not path:
        raise InvalidInput("no verb given")
    if not verbs.remote(path):
        raise InvalidInput(f"'{path.split()[0]}' runs on this computer, not remotely")
    return path
