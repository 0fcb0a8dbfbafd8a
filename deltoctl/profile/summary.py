"""What deltoctl shows of a profile, as data (the JSON documents): its summary (``profile
list``), the document of ``profile show`` and of one of its parts, what a conversion wrote
(``profile import|export --json``) and a profile's entry of ``profile validate``."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from deltoctl.errors import OK, WARNINGS, DeltoctlError, InvalidInput

if TYPE_CHECKING:
    from pathlib import Path

    from deltoctl.profile.model import Component, Profile


def summary(profile: Profile) -> dict[str, Any]:
    """A catalog line: name, family, model, status, description, counts and source."""
    return {
        "name": profile.name,
        "family": profile.family or ",".join(
            sorted({profile.family_of(h) or "?" for h in profile.hardware})),
        "model": profile.model,
        "status": profile.status,
        "description": profile.description,
        **profile.counts(),
        "source": profile.source,
    }


def soft_limits(profile: Profile) -> dict[str, dict[str, Any]]:
    """{block: {joint: soft limits}} for the joints that have them."""
    data: dict[str, dict[str, Any]] = {}
    for hw in profile.hardware:
        for joint in hw.joints:
            if joint.soft_limits is not None:
                data.setdefault(hw.name, {})[joint.name] = dict(vars(joint.soft_limits))
    return data


def show_data(profile: Profile) -> dict[str, Any]:
    """The whole profile: its summary, interfaces, blocks, soft limits and warnings."""
    from deltoctl.profile.exporter import profile_data

    return {**summary(profile), "state_interfaces": profile.state_interfaces(),
            "command_interfaces": profile.command_interfaces(),
            "profile": profile_data(profile), "soft_limits": soft_limits(profile),
            "warnings": [str(w) for w in profile.warnings]}


def part(profile: Profile, name: str) -> Component:
    """The joint, sensor or GPIO ``name``; InvalidInput (with the nearest names) if none."""
    comp = profile.component(name)
    if comp is None:
        from deltoctl.suggest import did_you_mean

        names = [c.name for _, c in profile.components()]
        raise InvalidInput(f"{profile.name} has no joint, sensor or GPIO named {name!r}"
                           + did_you_mean(name, names))
    return comp


def part_data(comp: Component) -> dict[str, Any]:
    """One part: its kind, its profile entry, and a joint's soft limits."""
    from deltoctl.profile.exporter import component_data

    data = {"kind": comp.kind, **component_data(comp)}
    soft = comp.soft_limits if comp.kind == "joint" else None
    if soft is not None:
        data["soft_limits"] = dict(vars(soft))
    return data


def written(profile: Profile, fmt: str, text: str, output: Path | None) -> dict[str, Any]:
    """What a conversion wrote: to ``output`` (resolved), or the text itself in ``content``
    when no file was named."""
    c = profile.counts()
    return {"profile": profile.name, "source": profile.source, "format": fmt,
            "output": None if output is None else str(output.resolve()),
            "bytes": len(text.encode("utf-8")),
            "blocks": [hw.name for hw in profile.hardware],
            "joints": c["joints"], "sensors": c["sensors"], "gpios": c["gpios"],
            "warnings": [str(w) for w in profile.warnings],
            **({"content": text} if output is None else {})}


def validation(spec: str, load: Callable[[str], Profile],
               strict: bool = False) -> tuple[dict[str, Any], int]:
    """One profile checked (``profile validate``): its entry of the document, and its exit
    code (0; 3 with warnings; the error's when it is invalid). ``strict``: warnings are
    errors."""
    from deltoctl.profile.validate import validate
    from deltoctl.transport.serial_port import stable_hint

    try:
        prof = load(spec)
        if strict:
            validate(prof, strict=True)
    except DeltoctlError as exc:
        return {"profile": spec, "ok": False, "error": exc.message}, exc.exit_code
    notes = [str(w) for w in prof.warnings]
    stable = [h for h in map(stable_hint, prof.buses.values()) if h]  # advice, no warning
    return ({"profile": spec, "ok": True, **prof.counts(), "warnings": notes, "notes": stable},
            WARNINGS if notes else OK)
