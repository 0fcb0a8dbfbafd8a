"""Objects of a node's dictionary by name or ``index:subindex``, as register and config items.

``0x6041``, ``6041:00``, ``0x6099:1``, ``Statusword`` and ``Homing speeds.Speed during search
for switch`` all name objects; a config item is ``0x6081:00 Profile velocity``.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

from deltoctl.errors import InvalidInput

# written only with the --allow naming them: they move the drive's zero or its limits
GUARDED = {0x607D: "limits", 0x607C: "homing", 0x6098: "homing"}
# commands: never compared or restored (their value is the last command, not a setting)
COMMANDS = {0x6040, 0x607A, 0x60FF, 0x1010, 0x1011}


def variables(od: Any) -> Iterator[Any]:
    """Every variable of a dictionary, records' and arrays' members included, in order."""
    from canopen.objectdictionary import ODVariable

    for index in sorted(od.indices):
        obj = od.indices[index]
        if isinstance(obj, ODVariable):
            yield obj
        else:
            yield from (obj.subindices[s] for s in sorted(obj.subindices))


def item_name(var: Any) -> str:
    parent = getattr(var, "parent", None)  # a record or an array; the dictionary for a VAR
    name = f"{parent.name}.{var.name}" if hasattr(parent, "subindices") else var.name
    return f"0x{var.index:04X}:{var.subindex:02X} {name}"


def find(od: Any, text: str) -> Any:
    """The variable an item names; InvalidInput naming the nearest when there is none."""
    key = text.strip().split(" ", 1)[0]
    index, sub = _address(key)
    if index is not None:
        obj = od.indices.get(index)
        if obj is not None and hasattr(obj, "subindices"):
            obj = obj.subindices.get(sub or 0)
        if obj is None:
            raise InvalidInput(f"no object {index:#06x}:{sub or 0:02x} in the node's EDS")
        return obj
    wanted = text.strip().lower()
    names = {}
    for var in variables(od):
        full = item_name(var).split(" ", 1)[1]
        names[full.lower()] = var
        names.setdefault(var.name.lower(), var)
    if wanted in names:
        return names[wanted]
    from deltoctl.suggest import did_you_mean

    raise InvalidInput(f"no object {text!r} in the node's EDS"
                       + did_you_mean(text, [item_name(v).split(" ", 1)[1]
                                             for v in variables(od)]))


def _address(key: str) -> tuple[int | None, int | None]:
    """``0x6041``, ``6041``, ``6041:00``, ``0x6099:1`` → (index, sub); else (None, None)."""
    head, _, tail = key.partition(":")
    try:
        index = int(head, 16)
        sub = int(tail, 16) if tail else None
    except ValueError:
        return None, None
    if not (len(head.removeprefix("0x").removeprefix("0X")) == 4 and 0 <= (sub or 0) <= 255):
        return None, None
    return index, sub


def _generic() -> Any:
    from deltoctl_canopen import eds
    from deltoctl_canopen.nodes import GENERIC_EDS

    return eds.load(GENERIC_EDS, 1)


def item_names() -> list[str]:
    """The register items of the generic drive (shell completion)."""
    return [item_name(v).split(" ", 1)[1] for v in variables(_generic())]


def config_rules() -> dict[str, tuple[int | None, int | None, str | None]]:
    """Each writable item's range (its EDS limits, else its data type's) and permission."""
    rules = {}
    for var in variables(_generic()):
        if var.writable:
            low, high = value_range(var)
            rules[item_name(var)] = (low, high, GUARDED.get(var.index))
    return rules


def value_range(var: Any) -> tuple[int | None, int | None]:
    from canopen.objectdictionary import datatypes

    if var.data_type not in datatypes.INTEGER_TYPES:
        return None, None
    bits = len(var)
    signed = var.data_type in datatypes.SIGNED_TYPES
    low, high = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
    return (var.min if var.min is not None else low), (var.max if var.max is not None else high)
