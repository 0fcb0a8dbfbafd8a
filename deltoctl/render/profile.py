"""Profiles for people: the catalog's table, a profile's heading and its parts' table with
their limits, one part's limits and interfaces (``profile list`` and ``profile show``).

A table is ``(columns, rows)``."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from deltoctl.profile.model import Component, Profile

Table = tuple[list[str], list[list[Any]]]


def catalog_table(summaries: list[dict[str, Any]]) -> Table:
    """The catalog, one profile a row (deltoctl.profile.summary.summary)."""
    columns = ["name", "family", "model", "joints", "sensors", "gpios", "status"]
    return columns, [[s[c] for c in columns] for s in summaries]


def range_text(lower: float | None, upper: float | None) -> str:
    low = "-inf" if lower is None else f"{lower:.4g}"
    high = "inf" if upper is None else f"{upper:.4g}"
    return f"[{low}, {high}]"


def limits_text(joint: Component) -> str:
    """The hard position limits, and the soft ones (a <safety_controller>) beside them."""
    lim, soft = joint.limits, joint.soft_limits
    parts = []
    if lim is not None and (lim.lower is not None or lim.upper is not None):
        unit = "m" if joint.joint_type == "prismatic" else "rad"
        parts.append(f"{range_text(lim.lower, lim.upper)} {unit}")
    if soft is not None:
        parts.append(f"soft {range_text(soft.lower, soft.upper)}")
    return ", ".join(parts)


def heading(profile: Profile) -> list[str]:
    """The profile's name and description, then its buses (a port named in plug-in order with
    what names its adapter instead)."""
    from deltoctl.transport.serial_port import stable_hint

    discontinued = " (discontinued)" if profile.status == "discontinued" else ""
    lines = [f"{profile.name}: {profile.description}{discontinued}"]
    for bus, url in profile.buses.items():
        hint = stable_hint(url)
        lines += [f"  bus {bus}: {url}"] + ([f"    note: {hint}"] if hint else [])
    return lines


def parts_table(profile: Profile) -> Table:
    """Every joint, sensor and GPIO: its block, address, interfaces and limits."""
    from deltoctl.profile.validate import part_address

    rows = []
    for hw, comp in profile.components():
        address = part_address(profile, hw, comp)
        rows.append([
            hw.name, comp.kind, comp.name,
            "" if address is None else str(address),
            ", ".join(i.name for i in comp.command_interfaces),
            ", ".join(i.name for i in comp.state_interfaces),
            limits_text(comp) if comp.kind == "joint" else "",
        ])
    return ["block", "kind", "name", "address", "commands", "states", "limits"], rows


def part_heading(comp: Component) -> list[str]:
    """One part's kind, name and limits (a joint's soft limits on a line of their own)."""
    hard = comp.limits
    hard_text = "" if hard is None else range_text(hard.lower, hard.upper)
    lines = [f"{comp.kind} {comp.name}" + (f"  limits {hard_text}" if hard_text else "")]
    soft = comp.soft_limits if comp.kind == "joint" else None
    if soft is not None:
        lines.append(f"  soft limits {range_text(soft.lower, soft.upper)} "
                     f"(k_position {soft.k_position:g}, k_velocity {soft.k_velocity:g})")
    return lines


def interfaces_table(comp: Component) -> Table:
    """One part's command, then state interfaces."""
    rows = [["command", i.name, i.min, i.max, i.initial_value, i.data_type]
            for i in comp.command_interfaces]
    rows += [["state", i.name, i.min, i.max, i.initial_value, i.data_type]
             for i in comp.state_interfaces]
    return ["direction", "interface", "min", "max", "initial", "type"], rows
