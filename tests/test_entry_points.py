"""The entry points of installed packages (families, transports, catalog profiles): read
through importlib.metadata once, then from the cache until a package is installed or
removed — without importlib.metadata's imports at every start-up."""

from __future__ import annotations

import json
import os
import subprocess
import sys

from tests.conftest import REPO

PROBE = ("import json, sys; from deltoctl.entry_points import declared; "
         "print(json.dumps([declared('deltoctl.profiles'), 'importlib.metadata' in sys.modules]))")


def _install(site, name: str) -> None:
    dist = site / f"{name}-1.0.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text(f"[deltoctl.profiles]\n{name} = {name}:profiles\n")


def test_installed_entry_points_are_read_once_and_again_when_packages_change(tmp_path):
    site = tmp_path / "site"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), str(REPO)]),
           "XDG_CACHE_HOME": str(tmp_path / "cache")}

    def probe(*more: str) -> tuple[list, bool]:
        path = os.pathsep.join([*more, env["PYTHONPATH"]])
        out = subprocess.run([sys.executable, "-c", PROBE], env={**env, "PYTHONPATH": path},
                             capture_output=True, text=True, timeout=60, check=True)
        found, scanned = json.loads(out.stdout)  # the profiles of the packages here only
        return [tuple(ep) for ep in found if ep[0].startswith("robots_")], scanned

    _install(site, "robots_a")
    assert probe() == ([("robots_a", "robots_a:profiles")], True)  # read, and cached
    assert probe() == ([("robots_a", "robots_a:profiles")], False)  # from the cache
    other = tmp_path / "other"
    other.mkdir()
    assert probe(str(other))[1] is True  # another sys.path: read for it too,
    assert probe()[1] is False  # each kept beside the other
    assert probe(str(other))[1] is False
    _install(site, "robots_b")
    assert sorted(probe()[0]) == [("robots_a", "robots_a:profiles"),
                                  ("robots_b", "robots_b:profiles")]
    import shutil

    shutil.rmtree(site / "robots_a-1.0.dist-info")
    assert probe() == ([("robots_b", "robots_b:profiles")], True)
    cache = tmp_path / "cache" / "deltoctl"
    shutil.rmtree(cache)
    cache.write_text("")  # a cache that cannot be written: the entry points are still read
    _install(site, "robots_c")
    assert sorted(probe()[0]) == [("robots_b", "robots_b:profiles"),
                                  ("robots_c", "robots_c:profiles")]
