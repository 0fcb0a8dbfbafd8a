"""Which parts of an emulated servo bus are on the wire: the ``connect`` and ``disconnect``
control lines of ``sim serve`` (and of ``--sim``), so that a box of factory-new servos, all at
one ID, can be set up as a technician does it — the controller plugged to one servo alone, then
the next (LeRobot's setup-motors asks for each motor "only" in the same way).

``connect JOINT…`` leaves those parts alone on the wire (every other one unplugged);
``connect all`` plugs every part back; ``disconnect JOINT…`` (or ``all``) unplugs those. A
servo keeps its ID, rate and memory while it is unplugged. A factory-new bus starts with every
part connected, so their replies collide until one is chosen."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from deltoctl.core.emulator_contract import ServeContext
from deltoctl.errors import InvalidInput

CONNECT_USAGE = ("connect JOINT...|all: only these servos on the wire (a factory-new bus: "
                 "one at a time, as the setup asks)")
DISCONNECT_USAGE = "disconnect JOINT...|all: these servos unplugged from the wire"


class Wiring:
    """The parts of one family's emulated buses by joint name (each an emulated servo with a
    ``connected`` flag); ``known`` every joint of the profile, so a name of another family's
    part is not an error (each family answers the same line for its own parts)."""

    def __init__(self, parts: Mapping[str, Any], known: Sequence[str]) -> None:
        self.parts, self.known = dict(parts), set(known)

    def _names(self, words: list[str], verb: str) -> set[str] | None:
        """The joints named (None: ``all``); a name the profile lacks is InvalidInput."""
        if not words:
            raise InvalidInput(f"which joints? ({verb} JOINT... or {verb} all)")
        if words == ["all"]:
            return None
        unknown = [w for w in words if w not in self.known]
        if unknown:
            raise InvalidInput(f"no joint {', '.join(map(repr, unknown))} in the profile "
                               f"(joints: {', '.join(sorted(self.known))})")
        return set(words)

    def connect(self, words: list[str]) -> str:
        names = self._names(words, "connect")
        if names is not None and not names & self.parts.keys():
            return ""  # another family's parts: this bus stays as it is
        for name, part in self.parts.items():
            part.connected = names is None or name in names
        return self._state()

    def disconnect(self, words: list[str]) -> str:
        names = self._names(words, "disconnect")
        for name, part in self.parts.items():
            if names is None or name in names:
                part.connected = False
        return self._state()

    def _state(self) -> str:
        on = [n for n, p in self.parts.items() if p.connected]
        return f"on the wire: {', '.join(on) or 'nothing'}"


def add_controls(ctx: ServeContext, parts: Mapping[str, Any]) -> Wiring:
    """Answer ``connect`` and ``disconnect`` for these parts (joint name → servo)."""
    known = [j.name for hw in ctx.profile.hardware for j in hw.joints]
    wiring = Wiring(parts, known)
    ctx.control("connect", CONNECT_USAGE, wiring.connect)
    ctx.control("disconnect", DISCONNECT_USAGE, wiring.disconnect)
    return wiring
