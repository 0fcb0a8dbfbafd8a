"""The built-in profile catalog, and resolving ``--profile NAME|PATH`` to a loaded profile."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from deltoctl import entry_points
from deltoctl.data_paths import cache_file as data_cache_file
from deltoctl.data_paths import data_dir
from deltoctl.errors import DeltoctlError, InvalidInput, ProfileError
from deltoctl.profile.files import MAX_PROFILE_BYTES, check_profile_file

if TYPE_CHECKING:
    from deltoctl.profile.model import Profile

YAML_SUFFIXES = (".yaml", ".yml")
URDF_SUFFIXES = (".urdf", ".xacro", ".xml")
PROFILES_GROUP = entry_points.PROFILES


def catalog_dir() -> Path:
    return data_dir("profiles")


def _plugin_dirs() -> list[Path]:
    """The profile folders installed packages name in the ``deltoctl.profiles`` entry-point
    group (``name = "package:folder"``), found without importing the packages."""
    import importlib.util

    found = []
    for _, value in entry_points.declared(PROFILES_GROUP):
        package, _, folder = value.partition(":")
        try:
            spec = importlib.util.find_spec(package)
        except (ImportError, ValueError):
            continue
        for location in (spec.submodule_search_locations or []) if spec else []:
            found.append(Path(location) / folder)
    return found


def catalog_files(plugins: bool = True) -> dict[str, Path]:
    """Every catalog profile by name: deltoctl's own, then those of installed packages (a
    package's profile never replaces one of deltoctl's)."""
    files: dict[str, Path] = {}
    for directory in [catalog_dir(), *(_plugin_dirs() if plugins else ())]:
        if directory.is_dir():
            for path in sorted(directory.glob("*.yaml")):
                files.setdefault(path.stem, path)
    return files


def catalog_names(plugins: bool = True) -> list[str]:
    """The catalog's names; ``plugins`` False: deltoctl's own only."""
    return sorted(catalog_files(plugins))


def resolve(spec: str) -> Path:
    """A catalog name or a file path → the file to load."""
    path = Path(spec).expanduser()
    if path.suffix.lower() in YAML_SUFFIXES + URDF_SUFFIXES or "/" in spec or path.exists():
        if not path.is_file():
            problem = "is not a regular file" if path.exists() else "does not exist"
            raise InvalidInput(f"profile file {spec!r} {problem}")
        return path
    candidate = catalog_dir() / f"{spec}.yaml"
    if candidate.is_file():
        return candidate
    installed = catalog_files().get(spec)
    if installed is not None:
        return installed
    from deltoctl.suggest import close_matches

    close = close_matches(spec, catalog_names())
    hint = f" Did you mean {', '.join(close)}?" if close else ""
    raise InvalidInput(f"no profile named {spec!r}.{hint} "
                       "Run 'deltoctl profile list' to see the catalog, or give a file path.")


def merge_interface_limits(profile: Profile) -> Profile:
    """Command interface min/max tighten the joint limits, as ros2_control merges them (a YAML
    profile's too; idempotent on what the URDF loader merged already)."""
    from deltoctl.profile.model import merge_interface_limits as merge

    for joint in profile.joints():
        joint.limits = merge(joint.limits, joint)
    return profile


def runs_xacro(path: Path, xacro: bool = False) -> bool:
    """Whether loading ``path`` runs xacro: a ``.xacro`` file, or ``--xacro`` on a URDF."""
    return path.suffix.lower() in URDF_SUFFIXES and (path.name.endswith(".xacro") or xacro)


def load_profile(
    spec: str | Path,
    xacro_args: Mapping[str, str] | None = None,
    packages: Mapping[str, str] | None = None,
    xacro: bool = False,
    expand: bool = True,
) -> Profile:
    """Load and validate a profile from a catalog name or a YAML/URDF/xacro path; xacro runs
    on a ``.xacro`` file, or on another URDF file when ``xacro`` is true — unless ``expand``
    is false (shell completion), which refuses such a file instead of evaluating anything."""
    from deltoctl.profile.validate import validate

    path = spec if isinstance(spec, Path) else resolve(spec)
    suffix = path.suffix.lower()
    if suffix not in YAML_SUFFIXES + URDF_SUFFIXES:
        raise ProfileError(
            "unknown profile format (expected .yaml/.yml, or .urdf/.xacro/.xml)", str(path))
    if not expand and runs_xacro(path, xacro):
        raise ProfileError("not expanded here: xacro runs only in a verb", str(path))
    check_profile_file(path)
    if suffix in YAML_SUFFIXES:
        from deltoctl.profile.yaml_loader import load_yaml_profile

        profile = load_yaml_profile(path)
    else:
        from deltoctl.profile.urdf_loader import load_urdf_profile

        profile = load_urdf_profile(path, xacro_args, packages, xacro=xacro)
    return validate(merge_interface_limits(profile))


def completion_profile(spec: str | None, xacro: bool) -> Profile | None:
    """The profile ``spec`` names for a command line being completed, or None.

    Completion runs while a command line is typed, on a file nobody chose to load yet: it
    reads YAML and plain URDF only, and never runs xacro (a ``.xacro`` file, or ``--xacro``
    on the line, completes nothing)."""
    if not spec:
        return None
    try:
        return load_profile(spec, xacro=xacro, expand=False)
    except DeltoctlError:
        return None


def profile_from_text(text: str, source: str) -> Profile:
    """A YAML profile handed over as text (a recording's metadata, a robot's agent), loaded
    as a profile file is: the size limit, the bounded YAML loader, validation."""
    from deltoctl.profile.validate import validate
    from deltoctl.profile.yaml_loader import load_data, profile_from_data

    if len(text.encode()) > MAX_PROFILE_BYTES:
        raise ProfileError(f"larger than {MAX_PROFILE_BYTES >> 20} MiB, the limit for a "
                           "profile", source)
    data = load_data(text, source)
    if data is None:
        raise ProfileError("empty (expected a YAML profile)", source)
    return validate(merge_interface_limits(profile_from_data(data, source)))


def catalog_summaries(summarize: Callable[[Profile], dict[str, Any]]) -> list[dict[str, Any]]:
    """``summarize(profile)`` for every catalog profile, cached by file size and mtime.

    A bring-up script runs ``profile list`` often and the catalog rarely changes: a hit
    costs a stat per file and no YAML parsing. The cache is best effort; any problem with
    it just means the profiles are loaded.
    """
    import json

    cache_file = data_cache_file("catalog")
    try:
        cache = json.loads(cache_file.read_text())
    except (OSError, ValueError):
        cache = {}
    summaries = []
    fresh: dict[str, dict[str, Any]] = {}
    for path in catalog_files().values():
        stat = path.stat()
        key = f"{path}:{stat.st_size}:{stat.st_mtime_ns}"
        summary = cache.get(key)
        if summary is None:
            summary = summarize(load_profile(path))
        fresh[key] = summary
        summaries.append(summary)
    if fresh != cache:
        try:
            cache_file.parent.mkdir(parents=True, exist_ok=True)
            cache_file.write_text(json.dumps(fresh))
        except OSError:
            pass
    return summaries
