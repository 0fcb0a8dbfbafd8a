"""What the robot's blocks are, for people: connect's round trips and lifecycles, identify's
tables of what each device says it is, detect's checks against the profile."""

from __future__ import annotations

from typing import Any

# a table as the CLI prints it: its title (or none), its columns, its rows
Table = tuple[str | None, list[str], list[list[Any]]]


def label(key: Any) -> str:
    """A field's key as words: ``configured_model`` → ``configured model``."""
    return str(key).replace("_", " ")


def word(value: Any) -> Any:
    """A value as people read it: a yes/no for a flag, the value otherwise."""
    return ("yes" if value else "no") if isinstance(value, bool) else value


def identity_tables(ident: dict[str, Any], title: str | None = None) -> list[Table]:
    """Plain fields in one table; each list of parts (joints, servos) in a table of its own,
    one row per part; nested groups recursively."""
    tables: list[Table] = []
    flat = [[label(k), word(v)] for k, v in ident.items() if not isinstance(v, dict)]
    if flat:
        tables.append((title, ["field", "value"], flat))
    for key, value in ident.items():
        if not isinstance(value, dict):
            continue
        name = f"{title} {label(key)}" if title else label(key)
        rows = list(value.values())
        if rows and all(isinstance(r, dict) and not any(isinstance(x, dict) for x in r.values())
                        for r in rows):
            columns = list(dict.fromkeys(c for r in rows for c in r))
            tables.append((name, ["name", *map(label, columns)],
                           [[part, *(word(r.get(c, "")) for c in columns)]
                            for part, r in value.items()]))
        elif rows and not any(isinstance(r, dict) for r in rows):
            tables.append((name, ["field", "value"],
                           [[label(k), word(v)] for k, v in value.items()]))
        else:
            tables.extend(identity_tables(value, name))
    return tables


def connect_lines(result: dict[str, Any], simulated: list[str | None]) -> list[str]:
    """Each block's round trips and lifecycle; ``simulated``: why each block is simulated
    (None: a device), in the order of the result's blocks."""
    lines = []
    for b, why in zip(result["blocks"], simulated):
        rtt = b["rtt_ms"]
        where = b["target"] or "the in-process mock"
        if why:
            where = f"its simulator at {where} ({why})"
        lines.append(f"{b['name']}: connected to {where}: round trip median "
                     f"{rtt['median']} ms (min {rtt['min']}, max {rtt['max']}, "
                     f"n={b['round_trips']})")
        lines.append(f"{b['name']}: lifecycle " + " → ".join(b["lifecycle"]))
    return lines


def identify_tables(result: dict[str, Any]) -> list[Table]:
    """Each block's identity (with its family and target) as its tables."""
    return [t for b in result["blocks"] for t in identity_tables(
        {"family": b["family"], "target": b["target"], **b["identity"]}, b["name"])]


def detect_parts(result: dict[str, Any]) -> list[str | Table]:
    """Each block's summary, its grid when it has one, and its checks as a table."""
    parts: list[str | Table] = []
    for b in result["blocks"]:
        parts.append(b["summary"])
        if "grid" in b["details"]:
            parts.append(b["details"]["grid"])
        if b["checks"]:
            parts.append((b["name"], ["check", "profile", "device", "match"],
                          [[c["what"], c["profile"], c["device"], "yes" if c["match"] else "NO"]
                           for c in b["checks"]]))
    return parts
