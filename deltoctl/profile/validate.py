"""Profile validation: ros2_control's component_parser rules plus deltoctl's own.

Every problem is a ProfileError naming ``file:line``; the first one found is raised.
"""

from __future__ import annotations

from urllib.parse import urlsplit

from deltoctl.errors import ProfileError
from deltoctl import registry
from deltoctl.profile.model import (
    DATA_TYPES,
    HARDWARE_TYPES,
    JOINT_TYPES,
    Component,
    Hardware,
    Profile,
)


def part_address(profile: Profile, hw: Hardware, comp: Component) -> int | None:
    """The address of a part: given explicitly, carried by a plugin param, or its position."""
    if comp.address is not None:
        return comp.address
    family = registry.get(profile.family_of(hw))
    if family and family.address_param and family.address_param in comp.params:
        raw = comp.params[family.address_param]
        try:
            return int(str(raw), 0)
        except ValueError:
            raise ProfileError(
                f"{family.address_param} of {comp.name!r} must be a number, got {raw!r}",
                profile.source, comp.line,
            ) from None
    if family and family.address_by_position and comp.kind == "joint":
        return hw.joints.index(comp) + 1
    return None


def validate(profile: Profile) -> Profile:
    src = profile.source

    def fail(message: str, line: int | None) -> ProfileError:
        return ProfileError(message, src, line)

    if profile.status not in ("current", "discontinued"):
        raise fail(f"status must be 'current' or 'discontinued', got {profile.status!r}", None)
    known = registry.families()
    if profile.family is not None and profile.family not in known:
        raise fail(f"unknown driver family {profile.family!r} "
                   f"(known: {', '.join(known)})", None)
    schemes = {s for f in known.values() for s in f.schemes}
    for bus, url in profile.buses.items():
        scheme = urlsplit(url).scheme
        if scheme not in schemes:
            raise fail(f"bus {bus!r}: {url!r} is not a target URL "
                       "(expected tcp://HOST:PORT, serial:///dev/PORT or i2c:///dev/i2c-N)", None)

    seen_blocks: set[str] = set()
    seen_parts: dict[str, Component] = {}
    addresses: dict[tuple[str, int], str] = {}
    for hw in profile.hardware:
        if hw.name in seen_blocks:
            raise fail(f"duplicate ros2_control block name {hw.name!r}", hw.line)
        seen_blocks.add(hw.name)
        if hw.type not in HARDWARE_TYPES:
            raise fail(f"ros2_control block {hw.name!r}: type must be one of "
                       f"{', '.join(HARDWARE_TYPES)}, got {hw.type!r}", hw.line)
        if not hw.plugin:
            raise fail(f"missing <plugin> in the <hardware> of {hw.name!r}", hw.line)
        family_name = profile.family_of(hw)
        if family_name is not None and family_name not in known:
            raise fail(f"unknown driver family {family_name!r} in {hw.name!r} "
                       f"(known: {', '.join(known)})", hw.line)
        family = known.get(family_name or "")
        if hw.bus is not None and hw.bus not in profile.buses:
            raise fail(f"{hw.name!r} names unknown bus {hw.bus!r} "
                       f"(the profile's buses: {', '.join(profile.buses) or 'none'})", hw.line)

        for comp in hw.components():
            where = comp.line or hw.line
            if comp.name in seen_parts:
                raise fail(f"duplicate name {comp.name!r} (a {seen_parts[comp.name].kind} "
                           "has it already)", where)
            seen_parts[comp.name] = comp
            if comp.kind == "joint":
                _check_joint(comp, fail)
            for which in ("command", "state"):
                names: set[str] = set()
                for itf in getattr(comp, f"{which}_interfaces"):
                    line = itf.line or where
                    if not itf.name:
                        raise fail(f"an interface of {comp.name!r} has no name", line)
                    if itf.name in names:
                        raise fail(f"duplicate {which} interface {comp.name}/{itf.name}", line)
                    names.add(itf.name)
                    if itf.min is not None and itf.max is not None and itf.min > itf.max:
                        raise fail(f"{comp.name}/{itf.name}: min {itf.min} is greater "
                                   f"than max {itf.max}", line)
                    if itf.data_type is not None and itf.data_type not in DATA_TYPES:
                        raise fail(f"{comp.name}/{itf.name}: unknown data_type "
                                   f"{itf.data_type!r} (expected one of "
                                   f"{', '.join(DATA_TYPES)})", line)
                    if itf.size is not None and itf.size < 1:
                        raise fail(f"{comp.name}/{itf.name}: size must be at least 1", line)
            bus = profile.bus_of(hw, comp)
            if comp.bus is not None and comp.bus not in profile.buses:
                raise fail(f"{comp.name!r} names unknown bus {comp.bus!r} "
                           f"(the profile's buses: {', '.join(profile.buses) or 'none'})", where)
            address = part_address(profile, hw, comp)
            if address is None:
                continue
            if family and family.address_range:
                low, high = family.address_range
                if not low <= address <= high:
                    show = family.show_address
                    raise fail(f"{family.address_kind} of {comp.name!r} must be within "
                               f"{show(low)}..{show(high)}, got {show(address)}", where)
            key = (bus or hw.name, address)
            if key in addresses:
                raise fail(f"{comp.name!r} has the same address {address} as "
                           f"{addresses[key]!r} on bus {key[0]!r}", where)
            addresses[key] = comp.name

    joints = {j.name: j for j in profile.joints()}
    for name, value in profile.safety.home_pose.items():
        if name not in joints:
            raise fail(f"safety.home_pose names unknown joint {name!r}", None)
        limits = joints[name].limits
        if limits and not limits.contains(value):
            raise fail(f"safety.home_pose of {name!r} ({value:g}) is outside its limits "
                       f"[{limits.lower:g}, {limits.upper:g}]", None)
    for name in profile.safety.homing_order:
        if name not in joints:
            raise fail(f"safety.homing_order names unknown joint {name!r}", None)
    return profile


def _check_joint(joint: Component, fail) -> None:  # type: ignore[no-untyped-def]
    where = joint.line
    if joint.joint_type not in JOINT_TYPES:
        raise fail(f"joint {joint.name!r}: type must be one of {', '.join(JOINT_TYPES)}, "
                   f"got {joint.joint_type!r}", where)
    if joint.joint_type == "fixed" and (joint.command_interfaces or joint.state_interfaces):
        raise fail(f"joint {joint.name!r} is fixed in the URDF and cannot have interfaces", where)
    if not joint.command_interfaces and not joint.state_interfaces:
        raise fail(f"joint {joint.name!r} has no command or state interface", where)
    if joint.mimic is not None and joint.command_interfaces:
        raise fail(f"joint {joint.name!r} mimics {joint.mimic.joint!r} and so cannot have "
                   "command interfaces", where)
    lim = joint.limits
    if lim and lim.lower is not None and lim.upper is not None and lim.lower > lim.upper:
        raise fail(f"joint {joint.name!r}: lower limit {lim.lower:g} is greater than upper "
                   f"limit {lim.upper:g}", where)
    for key in ("velocity", "effort"):
        value = getattr(lim, key, None) if lim else None
        if value is not None and value < 0:
            raise fail(f"joint {joint.name!r}: {key} limit must not be negative", where)
