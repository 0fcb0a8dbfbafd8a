"""Run xacro with no ROS installed: ``$(find pkg)`` resolves through package paths."""

from __future__ import annotations

import contextlib
import io
import os
import re
from collections.abc import Iterator, Mapping
from pathlib import Path

from deltoctl.errors import ProfileError

PACKAGE_PATH_ENV = "DELTOCTL_PACKAGE_PATH"


def package_paths(given: Mapping[str, str] | None = None) -> dict[str, Path]:
    """``PKG=DIR`` pairs from DELTOCTL_PACKAGE_PATH (``:``-separated), overridden by ``given``."""
    paths: dict[str, Path] = {}
    for item in os.environ.get(PACKAGE_PATH_ENV, "").split(os.pathsep):
        if "=" in item:
            pkg, _, directory = item.partition("=")
            paths[pkg.strip()] = Path(directory.strip()).expanduser()
    for pkg, directory in (given or {}).items():
        paths[pkg] = Path(directory).expanduser()
    return paths


@contextlib.contextmanager
def _find_packages_in(paths: dict[str, Path], missing: list[str]) -> Iterator[None]:
    from xacro import substitution_args

    def find(pkg: str) -> str:
        if pkg in paths:
            return str(paths[pkg].resolve())
        missing.append(pkg)
        raise LookupError(pkg)

    original = substitution_args._eval_find
    substitution_args._eval_find = find
    try:
        yield
    finally:
        substitution_args._eval_find = original


def run_xacro(path: Path, args: Mapping[str, str], packages: Mapping[str, str] | None) -> str:
    """Expand a xacro file; returns the URDF text. Errors name the file."""
    import xacro

    source = str(path)
    missing: list[str] = []
    try:
        with _find_packages_in(package_paths(packages), missing), \
                contextlib.redirect_stderr(io.StringIO()):
            doc = xacro.process_file(str(path), mappings=dict(args), verbosity=0)
    except Exception as exc:  # xacro raises many kinds; each becomes one clear line
        if missing:
            pkg = missing[0]
            raise ProfileError(
                f"$(find {pkg}): package {pkg!r} is unknown; pass --package-path {pkg}=DIR "
                f"or add {pkg}=DIR to {PACKAGE_PATH_ENV}", source) from None
        where = ""
        stack = [f for f in (getattr(xacro, "filestack", None) or []) if f]
        if stack and stack[-1] != source:
            where = f" (in {stack[-1]})"
        message = str(exc).strip() or type(exc).__name__
        undefined = re.match(r"Undefined substitution argument (\S+)", message)
        if undefined:
            name = undefined.group(1)
            message = f"xacro argument {name!r} has no value: pass --arg {name}:=VALUE"
        raise ProfileError(f"xacro failed{where}: {message}", source) from None
    return doc.toxml()


def included_files() -> list[str]:
    import xacro

    return [str(f) for f in getattr(xacro, "all_includes", [])]
