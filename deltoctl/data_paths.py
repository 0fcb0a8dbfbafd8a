"""Where the shipped data directories are (inside the wheel, or at the source tree's root),
and where deltoctl keeps its caches."""

from __future__ import annotations

from pathlib import Path

_PACKAGE = Path(__file__).resolve().parent


def data_dir(name: str) -> Path:
    """``profiles``, ``urdf``, ``completions`` or ``examples``."""
    installed = _PACKAGE / "_data" / name
    if installed.is_dir():
        return installed
    return _PACKAGE.parent / name


def cache_file(name: str) -> Path:
    """A cache of this version of deltoctl: $XDG_CACHE_HOME/deltoctl/NAME-VERSION.json
    (~/.cache/… by default)."""
    import os

    from deltoctl.version import __version__

    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "deltoctl" / f"{name}-{__version__}.json"


def user_data_dir(*parts: str) -> Path:
    """What deltoctl keeps for this user across versions (calibrations):
    $XDG_DATA_HOME/deltoctl/PARTS (~/.local/share/… by default)."""
    import os

    base = os.environ.get("XDG_DATA_HOME") or os.path.join(os.path.expanduser("~"), ".local",
                                                            "share")
    return Path(base, "deltoctl", *parts)
