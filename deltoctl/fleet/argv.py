"""What a remote command line asks for, judged on the robot: the verb it runs, and nothing
that would choose another profile or device, serve the robot's data elsewhere, or name a file
outside the agent's directory. It is parsed with the CLI's own grammar (deltoctl.cmdline):
global options may stand after the verb, and are judged where the CLI would take them."""

from __future__ import annotations

import os
import re

from deltoctl.cmdline import hoist_global_options, needs_value
from deltoctl.errors import InvalidInput
from deltoctl.fleet import NOT_REMOTE

# options the agent sets itself (the robot's profile and links), that name a local file, or
# that would serve the robot's data beyond the agent's own transport
FORBIDDEN = ("--profile", "--target", "--sim", "--arg", "--package-path", "--xacro",
             "--log-file", "--robot", "--zenoh-config", "--foxglove", "--foxglove-host",
             "--foxglove-port")
_SHORT_FORBIDDEN = re.compile(r"-[yqv]*[pt]")  # -p, -t, -yp …: a cluster naming them
GROUPS = frozenset({"gpio", "register", "config", "profile", "sim", "bench", "calibrate",
                    "fleet"})


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


def check_argv(argv: object, workdir: str = ".") -> str:
    """The verb (``jog``, ``gpio set``) of a remote command line, after checking it; raises
    InvalidInput for what the agent does not run."""
    if not isinstance(argv, list) or not all(isinstance(a, str) for a in argv) or not argv:
        raise InvalidInput("the request carries no command line")
    args = hoist_global_options(argv)
    for arg in args:
        name = arg.split("=", 1)[0]
        if name in FORBIDDEN or _SHORT_FORBIDDEN.match(arg):
            raise InvalidInput(f"{name} is not taken remotely: the agent runs the robot's "
                               "own profile and links, and serves its data only over Zenoh")
        if any(_outside(v, workdir) for v in _values(arg)):
            raise InvalidInput(f"{arg!r}: a remote verb names files in the agent's directory "
                               "only (no absolute path, '~' or '..')")
    i = 0
    while i < len(args) and args[i].startswith("-"):  # the global options, hoisted
        if args[i] == "--":
            raise InvalidInput("'--' before the verb")
        i += 2 if needs_value(args[i]) else 1
    words = [a for a in args[i:i + 2] if not a.startswith("-")]
    if not words:
        raise InvalidInput("no verb given")
    if words[0] in NOT_REMOTE:
        raise InvalidInput(f"'{words[0]}' runs on this computer, not remotely")
    return " ".join(words) if words[0] in GROUPS and len(words) == 2 else words[0]

