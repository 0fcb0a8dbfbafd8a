"""Completions of a command line being typed: the catalog's profiles, and the names in the
profile it names (joints, sensors, GPIOs, blocks, registers)."""

from typing import TYPE_CHECKING, Any

import typer

if TYPE_CHECKING:
    from collections.abc import Callable, Iterable

    from deltoctl.profile.model import Profile


def complete_profile(incomplete: str) -> list[str]:
    from deltoctl.profile.catalog import catalog_names

    return [n for n in catalog_names() if n.startswith(incomplete)]


def _completion_profile(ctx: typer.Context) -> "Profile | None":
    """The profile named on the command line being completed (its own or --profile), or
    None."""
    from deltoctl.profile.catalog import completion_profile

    root_params = ctx.find_root().params or {}
    spec = ctx.params.get("profile") or root_params.get("profile")
    return completion_profile(spec, bool(root_params.get("xacro")))


def _completer(names: "Callable[[Profile], Iterable[str]]") -> Any:
    """A completion of the names ``names`` finds in the profile on the command line."""
    def complete(ctx: typer.Context, incomplete: str) -> list[str]:
        prof = _completion_profile(ctx)
        return [] if prof is None else [n for n in names(prof) if n.startswith(incomplete)]

    return complete


# joint, sensor and GPIO names; the <ros2_control> blocks' (for --hardware); joints only
complete_part = _completer(lambda prof: [c.name for _, c in prof.components()])
complete_blocks = _completer(lambda prof: [hw.name for hw in prof.hardware])
complete_joints = _completer(lambda prof: [j.name for j in prof.joints()])
complete_gpio = _completer(lambda prof: [n for hw in prof.hardware for c in hw.gpios
                                         for n in c.interface_names("command")])


def _target_names(prof: "Profile") -> list[str]:
    from deltoctl.app.robot import target_names

    return target_names(prof)


complete_target = _completer(_target_names)  # joints, their groups and all


def complete_register_items(ctx: typer.Context, incomplete: str) -> list[str]:
    """Register item names of the profile's families that have registers (return_delay_time)."""
    from deltoctl import registry

    def names(prof: "Profile") -> "Iterable[str]":
        families = {registry.of_block(prof.family_of(hw), hw.plugin) for hw in prof.hardware}
        return dict.fromkeys(n for f in families if f is not None for n in f.register_names())

    return _completer(names)(ctx, incomplete.lower())
