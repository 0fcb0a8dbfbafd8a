"""The entry points installed packages declare to deltoctl — families, transports, catalog
profiles — read without importing importlib.metadata when nothing was installed since the last
read.

importlib.metadata reads every installed distribution's metadata and imports the email
package to do it: about 25 ms that every verb and every ``profile list`` of a bring-up script
would pay. The groups are cached (best effort, like the catalog's summaries) under a key of
the directories on ``sys.path`` and their modification times: installing, upgrading or
removing a package adds or removes entries in its directory, which changes its time.
"""

from __future__ import annotations

import os
import sys

FAMILIES = "deltoctl.families"  # a family's descriptor: "module:FAMILY"
TRANSPORTS = "deltoctl.transports"  # a URL scheme's transport: "module:attr"
PROFILES = "deltoctl.profiles"  # a package's folder of catalog profiles: "package:folder"
GROUPS = (FAMILIES, TRANSPORTS, PROFILES)
KEYS_KEPT = 8  # sys.paths whose entry points the cache holds
_read: tuple[list[list[object]], dict[str, list[list[str]]]] | None = None


def declared(group: str) -> list[tuple[str, str]]:
    """(name, value) of each entry point of ``group``, in importlib.metadata's order."""
    global _read
    key = _key()
    if _read is None or _read[0] != key:
        _read = key, _cached(key)
    return [(name, value) for name, value in _read[1].get(group, [])]


def _key() -> list[list[object]]:
    """Each directory (or zip file) on sys.path with its modification time."""
    key: list[list[object]] = []
    for entry in sys.path:
        try:
            key.append([entry, os.stat(entry or ".").st_mtime_ns])
        except OSError:
            continue
    return key


def _cached(key: list[list[object]]) -> dict[str, list[list[str]]]:
    """The groups from the cache when it holds ``key``; else read, and cached beside the
    keys of the last few ways deltoctl was started (a console script, ``python -m``, a test
    run: each has its own sys.path)."""
    import json

    from deltoctl.data_paths import cache_file

    path = cache_file("entry-points")
    name = json.dumps(key)
    try:
        cache = json.loads(path.read_text())
        if isinstance(cache.get(name), dict):
            return dict(cache[name])
    except (OSError, ValueError, AttributeError):
        cache = {}
    groups = _scan()
    kept = [k for k in cache if k != name][-(KEYS_KEPT - 1):]
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({**{k: cache[k] for k in kept}, name: groups}))
    except OSError:
        pass
    return groups


def _scan() -> dict[str, list[list[str]]]:
    """deltoctl's groups of every installed package's entry points."""
    import importlib.metadata

    return {group: [[ep.name, ep.value] for ep in importlib.metadata.entry_points(group=group)]
            for group in GROUPS}

