""""Did you mean …?" for every name a person types: verbs, profiles, joints, GPIOs, blocks,
interfaces, register items.

Names are compared without case, '-' and '_' (``dg5f`` is ``dg-5f-…``), and a name that
starts with what was typed ranks first: a technician types the start of a name far more
often than a near miss of a whole one. difflib is imported by typer already, so this costs
nothing at start-up.
"""

from __future__ import annotations

from collections.abc import Iterable
from difflib import SequenceMatcher

CUTOFF = 0.6  # below this similarity a name is not worth offering
WINDOW = 0.05  # names this much less similar than the best one are left out


def _plain(name: str) -> str:
    return name.lower().replace("-", "").replace("_", "").replace(" ", "")


def _score(typed: str, name: str) -> tuple[float, float]:
    """(rank, whole-name similarity): the rank counts a match of the name's start too."""
    whole = SequenceMatcher(None, typed, name).ratio()
    start = SequenceMatcher(None, typed, name[:len(typed)]).ratio() if len(name) > len(typed) \
        else 0.0
    return max(whole, start), whole


def close_matches(typed: str, names: Iterable[str], n: int = 4) -> list[str]:
    """Up to ``n`` names nearest ``typed``, best first; [] when none is close."""
    key = _plain(typed)
    if not key:
        return []
    scored = []
    for name in dict.fromkeys(names):
        rank, whole = _score(key, _plain(name))
        if rank >= CUTOFF and name != typed:
            scored.append((-rank, -whole, name))
    scored.sort()
    best = -scored[0][0] if scored else 0.0
    return [name for rank, _, name in scored[:n] if -rank >= best - WINDOW]


def did_you_mean(typed: str, names: Iterable[str], n: int = 4) -> str:
    """`` (did you mean a, b?)`` to append to a message, or ''."""
    close = close_matches(typed, names, n)
    return f" (did you mean {', '.join(close)}?)" if close else ""

