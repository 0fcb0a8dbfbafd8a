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


def one_letter_off(typed: str, name: str) -> bool:
    """Whether ``typed`` is ``name`` with one letter left out, added, changed, or swapped with
    its neighbour (``positon``, ``postion``, ``velocty``)."""
    if typed == name or abs(len(typed) - len(name)) > 1:
        return False
    start = next((i for i, (a, b) in enumerate(zip(typed, name)) if a != b),
                 min(len(typed), len(name)))
    rest_t, rest_n = typed[start:], name[start:]
    return (rest_t[1:] == rest_n[1:] or rest_t == rest_n[1:] or rest_t[1:] == rest_n
            or (len(rest_t) > 1 and rest_t[:2] == rest_n[1::-1] and rest_t[2:] == rest_n[2:]))
