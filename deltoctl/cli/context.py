"""The global options every verb shares, and the profile they select."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import typer

from deltoctl.errors import InvalidInput

if TYPE_CHECKING:
    from deltoctl.profile.model import Profile


@dataclass
class Options:
    profile: str | None = None
    target: list[str] = field(default_factory=list)
    sim: bool = False
    json: bool = False
    yes: bool = False
    verbose: int = 0
    quiet: bool = False
    xacro_args: dict[str, str] = field(default_factory=dict)
    package_paths: dict[str, str] = field(default_factory=dict)

    def load_profile(self, spec: str | None = None) -> Profile:
        from deltoctl.profile.catalog import load_profile

        spec = spec or self.profile
        if not spec:
            raise InvalidInput("no profile given: pass --profile NAME|PATH (or set "
                               "DELTOCTL_PROFILE); 'deltoctl profile list' shows the catalog")
        return load_profile(spec, self.xacro_args, self.package_paths)


def options(ctx: typer.Context) -> Options:
    root = ctx.find_root()
    if not isinstance(root.obj, Options):
        root.obj = Options()
    return root.obj


def parse_pairs(items: list[str], sep: str, what: str, example: str) -> dict[str, str]:
    pairs: dict[str, str] = {}
    for item in items:
        key, found, value = item.partition(sep)
        if not found or not key:
            raise InvalidInput(f"{what} {item!r} is not of the form {example}")
        pairs[key] = value
    return pairs
