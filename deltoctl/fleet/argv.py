"""What a remote command line asks for, judged on the robot: the verb it runs, and nothing
that would choose another profile or device, or name a file outside the agent's directory."""

from __future__ import annotations

import re

from deltoctl.errors import InvalidInput
from deltoctl.fleet import NOT_REMOTE

# options the agent sets itself (the robot's profile and links) or that name a local file
FORBIDDEN = ("--profile", "--target", "--sim", "--arg", "--package-path", "--xacro",
             "--log-file", "--robot", "--zenoh-config")
_SHORT_FORBIDDEN = re.compile(r"-[yqv]*[pt]")  # -p, -t, -yp …: a cluster naming them
GROUPS = frozenset({"gpio", "register", "config", "profile", "sim", "bench", "calibrate",
                    "fleet"})


def check_argv(argv: object) -> str:
    """The verb (``jog``, ``gpio set``) of a remote command line, after checking it; raises
    InvalidInput for what the agent does not run."""
    if not isinstance(argv, list) or not all(isinstance(a, str) for a in argv) or not argv:
        raise InvalidInput("the request carries no command line")
    words: list[str] = []
    skip = False
    for arg in argv:
        if skip:
            skip = False
            continue
        name = arg.split("=", 1)[0]
        if name in FORBIDDEN or _SHORT_FORBIDDEN.match(arg):
            raise InvalidInput(f"{name} is not taken remotely: the agent runs "
                               "the robot's own profile and links")
        if arg.startswith(("/", "~")) or ".." in arg.split("/"):
            raise InvalidInput(f"{arg!r}: a remote verb names files in the "
                               "agent's directory only (no absolute path, '~' or '..')")
        if not words and arg == "--":
            raise InvalidInput("'--' before the verb")
        if not words and arg == "--hardware":
            skip = True
        elif not arg.startswith("-") and len(words) < 2:
            words.append(arg)
    if not words:
        raise InvalidInput("no verb given")
    verb = words[0] if words[0] not in GROUPS or len(words) < 2 else " ".join(words)
    if words[0] in NOT_REMOTE:
        raise InvalidInput(f"'{words[0]}' runs on this computer, not remotely")
    return verb
