"""Configuration snapshots: every block's configuration in one YAML document, compared with
the live devices or another snapshot, and written back where it differs.

Each block reports its configuration through the driver contract (``config_read``: part →
item → entry) and writes it back through ``config_write``, which knows the order its device
requires. A snapshot is untrusted input, loaded as carefully as a profile: a bounded safe YAML
load, then every block, part and item name and every value checked against what the live
block reports (an integer within its item's range, and within the range its family
documents) before anything is compared or written; safety settings are written only when
the caller names them (``allow``).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

from deltoctl.errors import DeviceError, InvalidInput, ProfileError, Refused

if TYPE_CHECKING:
    from deltoctl.core.system import System

FORMAT = 1  # the snapshot format's version
MAX_SNAPSHOT_BYTES = 16 << 20  # as a profile: refused before it is read
MAX_TEXT = 1024  # characters of a name or a text value
# the keys of an item a snapshot file keeps (the others describe the live device's moment)
FILE_KEYS = ("value", "unit", "access", "area", "address", "meaning", "state")
ENTRY_KEYS = frozenset(FILE_KEYS) | {"min", "max", "note", "fixed", "needs", "opt_in"}
TOP_KEYS = frozenset({"deltoctl_config", "profile", "deltoctl", "taken", "blocks"})
BLOCK_KEYS = frozenset({"family", "target", "parts"})
PROFILE_NOTE = "set from the profile at each start: change the profile"

Key = tuple[str, str, str]  # block, part, item


class Value(NamedTuple):
    """One item's value, with what a comparison needs to know about it."""

    value: Any
    unit: str | None = None
    state: bool = False  # a reading or a command: kept, never compared
    line: int | None = None  # where a snapshot file holds it


class Snapshot(NamedTuple):
    source: str
    profile: str | None
    families: dict[str, str]  # block → family
    values: dict[Key, Value]
    lines: dict[tuple[str, ...], int]  # (block,) and (block, part) → line


def read_live(system: System) -> tuple[dict[str, dict[str, Any]], list[str]]:
    """``{block: {"family", "target", "parts"}}`` of every block that reports its
    configuration, and the names of those that cannot."""
    live = {m.name: {"family": m.family.name, "target": m.url or None,
                     "parts": m.driver.config_read()} for m in system.able("config")}
    return live, [m.name for m in system if not m.can("config")]


def live_values(live: dict[str, dict[str, Any]]) -> dict[Key, Value]:
    return {(block, part, item): Value(entry.get("value"), entry.get("unit"),
                                       bool(entry.get("state")))
            for block, b in live.items() for part, items in b["parts"].items()
            for item, entry in items.items()}


def live_entry(live: dict[str, dict[str, Any]], key: Key) -> dict[str, Any]:
    block, part, item = key
    return dict(live[block]["parts"][part][item])


def document(profile: str, live: dict[str, dict[str, Any]], taken: str) -> dict[str, Any]:
    """The snapshot as written: profile, deltoctl's version, time, and per block its family,
    target and each part's items (without what only describes the device's moment)."""
    from deltoctl.version import __version__

    def kept(entry: dict[str, Any]) -> dict[str, Any]:
        return {k: entry[k] for k in FILE_KEYS if k in entry and (k != "state" or entry[k])}

    return {"deltoctl_config": FORMAT, "profile": profile, "deltoctl": __version__,
            "taken": taken,
            "blocks": {name: {"family": b["family"], "target": b["target"],
                              "parts": {part: {item: kept(e) for item, e in items.items()}
                                        for part, items in b["parts"].items()}}
                       for name, b in live.items()}}


def default_name(profile: str, live: dict[str, dict[str, Any]], stamp: str) -> str:
    """``config-<profile>[-<address>]-<time>.yaml``: the address when one target holds
    every block (a device's host and port, a bus's device node)."""
    import re
    from urllib.parse import urlsplit

    targets = {b["target"] for b in live.values() if b["target"]}
    where = ""
    if len(targets) == 1:
        url = urlsplit(next(iter(targets)))
        where = url.netloc or url.path.rsplit("/", 1)[-1]
        where = "-" + re.sub(r"[^A-Za-z0-9.]+", "_", where).strip("_")
    return f"config-{profile}{where if where != '-' else ''}-{stamp}.yaml"


def dump_yaml(doc: dict[str, Any]) -> str:
    import yaml

    dumper = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
    # leaf mappings in flow style: one line per item
    return str(yaml.dump(doc, Dumper=dumper, sort_keys=False, allow_unicode=True,
                         default_flow_style=None, width=100))


def load_snapshot(path: Path) -> Snapshot:
    """A snapshot file, bounded and safely loaded, its shape and value types checked (names
    and ranges are checked against the live blocks by ``check_against``)."""
    from deltoctl.profile.yaml_loader import load_data, read_text

    source = str(path)
    # the profile's bounded read and safe loader (depth and node bounds)
    data = load_data(read_text(path, "YAML", MAX_SNAPSHOT_BYTES, "snapshot"), source)
    return _parse(data, source)


def _line(container: Any, key: Any = None) -> int | None:
    lines = getattr(container, "lines", None)
    if key is not None and isinstance(lines, dict) and key in lines:
        return int(lines[key])
    return getattr(container, "line", None) or None


def _mapping(value: Any, what: str, source: str, line: int | None) -> dict:
    if not isinstance(value, dict):
        raise ProfileError(f"{what} must be a mapping", source, line)
    for key in value:
        if not isinstance(key, str) or not key or len(key) > MAX_TEXT:
            raise ProfileError(f"{what}: {key!r} is not a name", source, _line(value, key))
    return value


def _parse(data: Any, source: str) -> Snapshot:
    top = _mapping(data, "a snapshot", source, 1)
    unknown = sorted(set(top) - TOP_KEYS)
    if unknown:
        raise ProfileError(f"unknown key {unknown[0]!r} (a snapshot holds: "
                           f"{', '.join(sorted(TOP_KEYS))})", source, _line(top, unknown[0]))
    if top.get("deltoctl_config") != FORMAT:
        raise ProfileError(f"not a deltoctl configuration snapshot of format {FORMAT} "
                           "(deltoctl_config: 1)", source, _line(top, "deltoctl_config") or 1)
    profile = top.get("profile")
    if profile is not None and (not isinstance(profile, str) or len(profile) > MAX_TEXT):
        raise ProfileError("profile must be a name", source, _line(top, "profile"))
    blocks = _mapping(top.get("blocks"), "blocks", source, _line(top, "blocks"))
    families: dict[str, str] = {}
    values: dict[Key, Value] = {}
    lines: dict[tuple[str, ...], int] = {}
    for name, block in blocks.items():
        where = _line(blocks, name)
        lines[(name,)] = where or 0
        block = _mapping(block, f"block {name}", source, where)
        extra = sorted(set(block) - BLOCK_KEYS)
        if extra:
            raise ProfileError(f"block {name}: unknown key {extra[0]!r} (a block holds: "
                               "family, target, parts)", source, _line(block, extra[0]))
        family = block.get("family")
        if not isinstance(family, str):
            raise ProfileError(f"block {name}: family must be a name", source, where)
        families[name] = family
        parts = _mapping(block.get("parts"), f"block {name}: parts", source, where)
        for part, items in parts.items():
            lines[(name, part)] = _line(parts, part) or 0
            items = _mapping(items, f"{name}/{part}", source, _line(parts, part))
            for item, entry in items.items():
                key = (name, part, item)
                values[key] = _value(entry, key, source, _line(items, item))
    return Snapshot(source, profile, families, values, lines)


def _scalar_problem(value: Any) -> str | None:
    """Why ``value`` cannot be a configuration value (None when it can)."""
    if value is None or isinstance(value, (bool, int)):
        return None
    if isinstance(value, float):
        return None if math.isfinite(value) else "not a finite number"
    if isinstance(value, str):
        return None if len(value) <= MAX_TEXT else f"text longer than {MAX_TEXT} characters"
    return f"a {type(value).__name__} is not a configuration value"


def _value(entry: Any, key: Key, source: str, line: int | None) -> Value:
    """An item as a snapshot holds it: ``{value, unit, …}`` or the bare value."""
    where = "/".join(key)
    if isinstance(entry, dict):
        extra = sorted(k for k in entry if k not in ENTRY_KEYS)
        if extra:
            raise ProfileError(f"{where}: unknown key {extra[0]!r} (an item holds: "
                               f"{', '.join(FILE_KEYS)})", source, _line(entry, extra[0]))
        if "value" not in entry:
            raise ProfileError(f"{where}: no value", source, line)
        value, unit = entry["value"], entry.get("unit")
        if unit is not None and not isinstance(unit, str):
            raise ProfileError(f"{where}: unit must be text", source, _line(entry, "unit"))
        state = entry.get("state", False) is True
        line = _line(entry, "value") or line
    else:
        value, unit, state = entry, None, False
    problem = _scalar_problem(value)
    if problem:
        raise ProfileError(f"{where}: {problem}", source, line)
    return Value(value, unit, state, line)


def check_against(snap: Snapshot, live: dict[str, dict[str, Any]], profile: Any) -> list[str]:
    """Every name of the snapshot known and every value one its item takes, for the blocks
    driven now (a bad snapshot is exit 2, naming the item); returns notes on the parts that
    cannot be compared (they do not answer). Blocks not driven (--hardware, or left out with
    a warning of the System's) are passed over."""
    from deltoctl.suggest import did_you_mean

    blocks = {hw.name: hw for hw in profile.hardware}
    for block, family in snap.families.items():
        line = snap.lines.get((block,))
        if block not in blocks:
            raise ProfileError(f"block {block!r}: {profile.name} has no such block"
                               f"{did_you_mean(block, blocks)}", snap.source, line)
        if block in live and family != live[block]["family"]:
            raise ProfileError(f"block {block}: a {family} block in the snapshot, a "
                               f"{live[block]['family']} block in {profile.name}",
                               snap.source, line)
    silent: set[tuple[str, str]] = set()
    for key, v in snap.values.items():
        block, part, item = key
        if block not in live:
            continue
        parts = live[block]["parts"]
        if part not in parts:
            known = [c.name for c in blocks[block].components()]
            if part not in known:
                raise ProfileError(f"{block}: no part {part!r}"
                                   f"{did_you_mean(part, [*parts, *known])}", snap.source,
                                   snap.lines.get((block, part)))
            silent.add((block, part))
            continue
        entry = parts[part].get(item)
        if entry is None:
            raise ProfileError(f"{block}/{part}: no item {item!r}"
                               f"{did_you_mean(item, parts[part])}", snap.source, v.line)
        problem = value_problem(v.value, entry)
        if problem:
            raise ProfileError(f"{block}/{part}/{item}: {problem}", snap.source, v.line)
    return [f"{block}/{part}: in the snapshot, not compared (it does not answer)"
            for block, part in sorted(silent)]


def _kind(value: Any) -> str:
    if value is None:
        return "nothing"
    if isinstance(value, bool):
        return "true or false"
    if isinstance(value, int):
        return "an integer"
    if isinstance(value, float):
        return "a number"
    return "text"


def value_problem(value: Any, entry: dict[str, Any]) -> str | None:
    """Why a snapshot's value is not one the live item takes: its kind (an integer item, a
    number, text, a flag) and an integer's range (from the item's size and sign)."""
    live = entry.get("value")
    kind, want = _kind(value), _kind(live)
    number = want == "a number" and kind == "an integer"
    if kind != want and not number and "nothing" not in (kind, want):
        return f"{value!r} is {kind}; the item holds {want}"
    low, high = entry.get("min"), entry.get("max")
    if kind == "an integer" and low is not None and high is not None and \
            not low <= value <= high:
        return f"{value} is outside the item's range {low}..{high}"
    if kind == "nothing" and entry.get("access") == "RW" and want != "nothing":
        return "no value"
    return None


def same(a: Any, b: Any) -> bool:
    if isinstance(a, float) or isinstance(b, float):
        if isinstance(a, (int, float)) and isinstance(b, (int, float)) and \
                not isinstance(a, bool) and not isinstance(b, bool):
            return math.isclose(a, b, rel_tol=1e-6, abs_tol=1e-9)
        return False
    return type(a) is type(b) and a == b


def show(value: Any) -> str:
    """A value as a person reads it."""
    if value is None:
        return "—"
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def _compared(a: Value | None, b: Value | None, both_ways: bool) -> bool:
    """Whether an item held as ``a`` and ``b`` counts as a difference."""
    if (a and a.state) or (b and b.state):  # a reading or a command
        return False
    if a is None or b is None:
        return both_ways
    return not same(a.value, b.value)


def differences(snap: dict[Key, Value], other: dict[Key, Value],
                both_ways: bool) -> list[dict[str, Any]]:
    """The items whose values differ (readings and commands left out); ``both_ways``: items
    only one side holds count too (two files), else only items both hold (the snapshot's
    names are checked against the live ones first, see ``check_against``)."""
    keys = list(snap) + ([k for k in other if k not in snap] if both_ways else [])
    rows = []
    for key in keys:
        a, b = snap.get(key), other.get(key)
        if not _compared(a, b, both_ways):
            continue
        held = a or b
        row = {"block": key[0], "part": key[1], "item": key[2],
               "unit": held.unit if held else None,
               "snapshot": a.value if a else None, "other": b.value if b else None}
        if both_ways:
            row["absent"] = None if a and b else ("snapshot" if b else "other")
        rows.append(row)
    return rows


Rule = tuple[int | None, int | None, str | None]  # documented range, and its --allow


def restore_rules(live: dict[str, dict[str, Any]]) -> dict[str, dict[str, Rule]]:
    """Per block, what its family declares of each item: the documented range and the
    permission a safety setting needs (``Family.config_rules``)."""
    from deltoctl import registry

    tables: dict[str, dict[str, Rule]] = {}
    for name in {b["family"] for b in live.values()}:
        family = registry.get(name)
        tables[name] = family.config_rule_table() if family else {}
    return {block: tables[b["family"]] for block, b in live.items()}


def check_ranges(snap: Snapshot, rows: list[dict[str, Any]],
                 rules: dict[str, dict[str, Rule]],
                 live: dict[str, dict[str, Any]] | None = None) -> None:
    """A value to restore outside its item's documented range (not only its size's) is a bad
    snapshot: exit 2, naming the item, the value and the range, before anything is written.
    A live entry's own ``low``/``high`` (its device model's range) narrow the family's."""
    for row in rows:
        low, high, _ = rules[row["block"]].get(row["item"], (None, None, None))
        if live is not None:
            entry = live_entry(live, (row["block"], row["part"], row["item"]))
            low, high = entry.get("low", low), entry.get("high", high)
        value = row["snapshot"]
        if not isinstance(value, int) or isinstance(value, bool):
            continue
        if (low is not None and value < low) or (high is not None and value > high):
            key = (row["block"], row["part"], row["item"])
            raise ProfileError(f"{'/'.join(key)}: {value} is outside the item's documented "
                               f"range {_bound(low)}..{_bound(high)}", snap.source,
                               snap.values[key].line)


def _bound(value: int | None) -> str:
    return "" if value is None else str(value)


def permission(text: str) -> str:
    """An --allow value as the rules spell it: "Max Position Limit" → max-position-limit."""
    return "-".join(text.strip().lower().replace("_", " ").split())


def permission_names() -> list[str]:
    """What --allow may name: every permission, then every family's safety settings."""
    from deltoctl import registry

    declared = {rule[2] for f in registry.families().values()
                for rule in f.config_rule_table().values() if rule[2]}
    return [*registry.permissions(), *sorted(declared)]


def plan(rows: list[dict[str, Any]], live: dict[str, dict[str, Any]],
         allow: frozenset[str], rules: dict[str, dict[str, Rule]] | None = None) -> None:
    """Each differing item's fate: write, or why not (read-only, skipped, refused). A safety
    setting a family declares needs its --allow, as do the permissions a driver names in an
    entry's ``needs`` (declared by its family: ``Family.permissions``)."""
    for row in rows:
        entry = live_entry(live, (row["block"], row["part"], row["item"]))
        guard = ((rules or {}).get(row["block"], {}).get(row["item"]) or (None,) * 3)[2]
        needs = [n for n in (entry.get("needs"), guard) if n]
        missing, opt_in = [n for n in needs if n not in allow], entry.get("opt_in")
        if needs:
            row["needs"] = needs
        if entry.get("access") == "profile":
            row["status"], row["note"] = "read-only", PROFILE_NOTE
        elif entry.get("access") != "RW":
            row["status"] = "read-only"
            row["note"] = entry.get("note") or "the device has no write"
        elif entry.get("fixed"):
            row["status"], row["note"] = "skipped", f"not restored: {entry['fixed']}"
        elif opt_in and opt_in not in allow:
            row["status"], row["note"] = "skipped", f"written only when asked: --allow {opt_in}"
        elif missing:
            row["status"] = "refused"
            row["note"] = "needs " + " and ".join(f"--allow {n}" for n in missing)
        else:
            row["status"] = "write"
            row["note"] = "with " + " and ".join(f"--allow {n}" for n in needs) if needs else ""


def write_changes(system: System, rows: list[dict[str, Any]], allow: frozenset[str]) -> None:
    """Each block's changes through its driver, then each item verified by its read back."""
    by_block: dict[str, dict[str, dict[str, Any]]] = {}
    for row in rows:
        if row["status"] == "write":
            by_block.setdefault(row["block"], {}).setdefault(row["part"], {})[row["item"]] = \
                row["snapshot"]
    members = {m.name: m for m in system}
    for block, changes in by_block.items():
        mine = [r for r in rows if r["block"] == block and r["status"] == "write"]
        try:
            read_back = members[block].driver.config_write(changes, allow)
        except (DeviceError, Refused, InvalidInput) as exc:
            for row in mine:
                row["status"] = "refused" if isinstance(exc, Refused) else "failed"
                row["note"] = exc.message
            continue
        for row in mine:
            after = read_back.get(row["part"], {}).get(row["item"], ...)
            if after is ...:
                row["status"] = "written"
                continue
            row["after"] = after
            if same(after, row["snapshot"]):
                row["status"] = "verified"
            else:
                row["status"], row["note"] = "failed", f"reads back {show(after)}"


def refusal(refused: list[dict[str, Any]], allow: frozenset[str]) -> Refused:
    """Why a restore is refused before anything is written or anyone is asked: what, and
    the way on."""
    from deltoctl import registry

    declared = registry.permissions()  # why each is asked for, and the way on
    needs = sorted({n for r in refused for n in r["needs"] if n not in allow})
    parts = sorted({f"{r['block']}/{r['part']}" for r in refused})
    why = " ".join(declared[n].why for n in needs if n in declared).strip()
    safety = [n for n in needs if n not in declared or not declared[n].why]
    if safety:
        why = (why + " " if why else "") + (f"{', '.join(safety)}: safety setting(s), "
                                            "written only when named")
    return Refused(f"nothing written: {len(refused)} item(s) of {', '.join(parts)} are "
                  f"written only with {' and '.join(f'--allow {n}' for n in needs)}"
                  + (f" ({why})" if why else ""),
                  hint="; ".join(_way_on(declared.get(n), n) for n in needs))


def _way_on(permission: Any, name: str) -> str:
    if permission is not None and permission.hint:
        return str(permission.hint)
    return f"check the snapshot's value, then pass --allow {name}"


def description(writes: list[dict[str, Any]]) -> str:
    """What a restore will write, for the caller's confirmation."""
    from deltoctl import registry

    parts = sorted({f"{r['block']}/{r['part']}" for r in writes})
    shown = ", ".join(parts[:6]) + (f" and {len(parts) - 6} more" if len(parts) > 6 else "")
    what = f"restore {len(writes)} value(s) to {shown}"
    declared = registry.permissions()  # what each permission given does
    for need in sorted({n for r in writes for n in r.get("needs", ())}):
        names = sorted({r["part"] for r in writes if need in r.get("needs", ())})
        given = declared[need].given if need in declared else ""
        what += f"; {', '.join(names)}: {given or '--allow ' + need}"
    return what


def snapshot(system: System) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
    """The snapshot document of every block that reports its configuration, and the live
    configuration it was made of; a block that cannot report is a warning of the System."""
    from datetime import datetime, timezone

    live, unable = read_live(system)
    if not live:
        raise InvalidInput(f"no block of {system.profile.name} reports its configuration")
    if unable:
        system.notes.append(f"{', '.join(unable)}: cannot report its configuration")
    taken = datetime.now(timezone.utc).isoformat(timespec="seconds")
    return document(system.profile.name, live, taken), live


def write_snapshot(doc: dict[str, Any], live: dict[str, dict[str, Any]],
                   output: str | None = None) -> Path:
    """Write a snapshot document to ``output`` (a directory: the default name in it;
    nothing: the default name here); returns the file written."""
    from datetime import datetime, timezone

    path = Path(output or ".")
    if output is None or path.is_dir():
        stamp = datetime.fromisoformat(doc["taken"]).astimezone(timezone.utc)
        path = path / default_name(doc["profile"], live, stamp.strftime("%Y%m%dT%H%M%SZ"))
    try:
        path.write_text(dump_yaml(doc), encoding="utf-8")
    except OSError as exc:
        raise InvalidInput(f"cannot write {path}: {exc.strerror}") from None
    return path


def snapshot_profile(snap: Snapshot, named: str | None) -> str | None:
    """The catalog profile a snapshot is compared with or restored under when none is
    ``named`` (-p) and the snapshot names one; None: the named (or default) profile."""
    if named or not snap.profile:
        return None
    return profile_of(snap)


def profile_of(snap: Snapshot) -> str:
    """The catalog profile a snapshot names — never a path from a file that may come from
    anywhere."""
    from deltoctl.profile.catalog import catalog_names

    if not snap.profile or snap.profile not in catalog_names():
        raise InvalidInput(f"{snap.source} was taken of {snap.profile!r}, which is not in the "
                           "catalog: name its profile with -p")
    return snap.profile


def compare_files(snap: Snapshot, other: Snapshot) -> tuple[list[dict[str, Any]], list[str]]:
    """The items that differ between two snapshots (``other`` in each row), and notes."""
    rows = differences(snap.values, other.values, both_ways=True)
    notes = [f"{block}: a {snap.families[block]} block in {snap.source}, a "
             f"{other.families[block]} block in {other.source}"
             for block in sorted(set(snap.families) & set(other.families))
             if snap.families[block] != other.families[block]]
    return rows, notes


def compare_live(system: System, snap: Snapshot) -> tuple[list[dict[str, Any]], list[str]]:
    """The items that differ between a snapshot and the live devices (``live`` in each row),
    after checking every name and value of the snapshot; and the notes (warnings)."""
    live, unable = read_live(system)
    notes = check_against(snap, live, system.profile)
    notes += [f"{', '.join(unable)}: cannot report its configuration"] if unable else []
    notes += [f"{b}: not in the snapshot" for b in live if b not in snap.families]
    rows = differences(snap.values, live_values(live), both_ways=False)
    for row in rows:
        row["live"] = row.pop("other")
    return rows, notes


def plan_restore(system: System, snap: Snapshot,
                 allow: frozenset[str]) -> tuple[list[dict[str, Any]], list[str]]:
    """What a restore would do to each differing item (``status``: write, read-only,
    skipped, refused), every value checked against its documented range first (a value
    outside is ``ProfileError``, exit 2); nothing is written."""
    live, unable = read_live(system)
    notes = check_against(snap, live, system.profile)
    notes += [f"{', '.join(unable)}: cannot report its configuration"] if unable else []
    rows = differences(snap.values, live_values(live), both_ways=False)
    for row in rows:
        row["live"] = row.pop("other")
    rules = restore_rules(live)
    check_ranges(snap, rows, rules, live)
    plan(rows, live, allow, rules)
    return rows, notes


def status_counts(rows: list[dict[str, Any]]) -> dict[str, int]:
    """How many items a restore has of each status, in the order they first come."""
    counts: dict[str, int] = {}
    for row in rows:
        counts[row["status"]] = counts.get(row["status"], 0) + 1
    return counts


def restore_outcome(rows: list[dict[str, Any]]) -> str | None:
    """A restore's worst outcome: some item refused (``Refused``, exit 5) or not verified
    (``DeviceError``, exit 1) is raised; items that differ still are a warning, returned."""
    statuses = {r["status"] for r in rows}
    bad = [f"{r['block']}/{r['part']}/{r['item']}" for r in rows if r["status"] == "failed"]
    if "refused" in statuses:
        raise Refused("some items were refused (see the table)")
    if bad:
        raise DeviceError(f"not verified: {', '.join(bad)}")
    left = [r for r in rows if r["status"] in ("read-only", "skipped")]
    if left:
        return (f"{len(left)} item(s) differ still: read-only, or not restored unasked (see "
                "the table)")
    return None
