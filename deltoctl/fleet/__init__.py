"""deltoctl over Zenoh: an agent on the robot's computer serves every verb, and any computer
runs them remotely (``--robot``) or on many robots at once (``fleet``).

Key expressions, all under ``deltoctl/<robot>/``:

- ``agent/<profile>`` — liveliness token: the robot's agent is there.
- ``info`` — queryable: profile, identity, state, whether motion is allowed (JSON); with the
  ``profile_yaml`` parameter (``info?profile_yaml``), the resolved profile's YAML too, which a
  remote ``record`` writes into the file it makes on the caller's computer.
- ``state`` — publication: the state each time it changes (``idle``, ``busy``, ``moving``).
- ``run`` — queryable: runs one verb; the query's payload is ``{"id", "argv"}``, the replies
  carry the verb's stdout, its stderr and finally its exit code.
- ``alive/<id>`` — publications: the caller's heartbeat while verb ``<id>`` runs.
- ``caller/<id>`` — liveliness token of that caller.
- ``cancel/<id>`` — publication: interrupt verb ``<id>`` (the caller's Ctrl-C).
- ``frames/<id>`` — publications: the NDJSON frames of a remote ``stream --json``. (A remote
  ``record`` reads the stream's frames from the run's replies instead: those are not dropped.)

zenoh is imported only by the modules that talk over it, never at the CLI's start-up.
"""

from __future__ import annotations

import re
from types import ModuleType

from deltoctl import verbs
from deltoctl.errors import InvalidInput

ROOT = "deltoctl"
# command paths ("jog", "gpio set") by their effect in deltoctl.verbs; one the table does not
# declare is in both (fail-closed). MOTION: one at a time per robot, the deadman matters most
MOTION = verbs.Effects(verbs.MOVES)
# what moves or switches something on the robot: it needs an authenticated caller
ACTUATING = verbs.Effects(verbs.MOVES, verbs.ACTUATES)
# the agent's own verbs, and a benchmark that would load the robot's computer while it moves
NOT_REMOTE = frozenset(name for name, verb in verbs.TABLE.items() if not verb.remote)
# the first word of the command line the agent's verb process runs to set a robot's blocks
# safe (a caller's command line starts with the robot's links, never with it)
SET_SAFE = "deltoctl.set-safe"
MAX_VERBS = 8  # verbs running at once on one robot's agent; more are refused (exit 5)
HEARTBEAT = 0.05  # s between a caller's heartbeats
DEADLINE = 0.2  # s without a heartbeat before the agent interrupts the verb
INSTALL_HINT = "pip install 'deltoctl[fleet]'"

# reply tags: the first byte of each reply to a run query
OUT, ERR, EXIT = b"o", b"e", b"x"

_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,62}")


def check_robot(name: str) -> str:
    """A robot name is one key-expression chunk: letters, digits, ``_ . -``."""
    if not _NAME.fullmatch(name):
        raise InvalidInput(f"robot name {name!r}: use letters, digits, '_', '.' and '-' "
                           "(up to 63, no '/', '*' or '$')")
    return name


def key(robot: str, *parts: str) -> str:
    return "/".join((ROOT, robot, *parts))


def zenoh_module() -> ModuleType:
    """``import zenoh``, or one clear message saying how to install it."""
    try:
        import zenoh
    except ImportError:
        raise InvalidInput(f"Zenoh is not installed: {INSTALL_HINT} (--robot, agent and "
                           "fleet talk over it)") from None
    return zenoh
