"""Profile validation: ros2_control's component_parser rules plus deltoctl's own.

Every problem is a ProfileError naming ``file:line``; the first one found is raised. Unsafe
numbers (a limit, a jog step, a cap, a rate that is not finite or not in its range) are errors
whatever ros2_control says. What ros2_control's parser accepts but deltoctl doubts (a joint with
no interface, a data type no handle can have) is an error in deltoctl's own YAML form and a
warning, kept on ``profile.warnings``, in a URDF; ``strict`` turns warnings into errors.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from pathlib import Path
from urllib.parse import urlsplit

from deltoctl import registry
from deltoctl.errors import ProfileError
from deltoctl.profile.model import (
    DATA_TYPES,
    HARDWARE_TYPES,
    JOINT_TYPES,
    Component,
    Hardware,
    Interface,
    Profile,
    ProfileWarning,
    parse_bool,
    parse_int_array,
    parse_number,
    parse_rw_rate,
    parse_thread_priority,
)

URDF_SUFFIXES = (".urdf", ".xacro", ".xml")
Fail = Callable[[str, "int | None"], ProfileError]
Doubt = Callable[[str, "int | None"], None]  # a warning: ros2_control accepts it, deltoctl doubts


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


# -- a block's attributes, as ros2_control reads them --------------------------------------------

def block_attribute_problems(attributes: dict[str, str]) -> tuple[list[str], list[str]]:
    """(errors, warnings) of a block's ``rw_rate``, ``is_async`` and ``thread_priority``.
    ros2_control reads ``thread_priority`` only on an ``is_async`` block."""
    errors: list[str] = []
    warnings: list[str] = []
    if "rw_rate" in attributes:
        try:
            _, ignored = parse_rw_rate(attributes["rw_rate"])
            if ignored:
                warnings.append(f"rw_rate {attributes['rw_rate']!r}: ros2_control reads only "
                                "its leading whole number")
        except ValueError as exc:
            errors.append(str(exc))
    is_async = False
    if "is_async" in attributes:
        try:
            is_async = parse_bool(attributes["is_async"])
        except ValueError as exc:
            errors.append(f"is_async: {exc}")
    if is_async and "thread_priority" in attributes:
        try:
            parse_thread_priority(attributes["thread_priority"])
        except ValueError as exc:
            errors.append(str(exc))
    return errors, warnings


def async_property_problems(props: dict[str, str]) -> list[str]:
    """What is wrong with the attributes of a block's ``<properties><async …/>``."""
    readers = {"thread_priority": parse_thread_priority, "affinity": parse_int_array,
               "print_warnings": parse_bool}
    problems = []
    for key, read in readers.items():
        if key in props:
            try:
                read(props[key])
            except ValueError as exc:
                problems.append(f"{key}: {exc}")
    return problems


# -- the whole profile ---------------------------------------------------------------------------

def validate(profile: Profile, strict: bool = False) -> Profile:
    src = profile.source
    from_urdf = (src or "").lower().endswith(URDF_SUFFIXES)
    warnings: list[ProfileWarning] = list(profile.warnings)

    def fail(message: str, line: int | None) -> ProfileError:
        return ProfileError(message, src, line)

    def doubt(message: str, line: int | None) -> None:
        """ros2_control's parser accepts it: a warning in a URDF, an error in YAML."""
        if not from_urdf:
            raise fail(message, line)
        warnings.append(ProfileWarning(message, src, line))

    _check_profile(profile, fail)
    interfaces: dict[tuple[str, str], str] = {}
    seen_blocks: set[str] = set()
    addresses: dict[tuple[str, int], str] = {}
    for hw in profile.hardware:
        if hw.name in seen_blocks:
            raise fail(f"duplicate ros2_control block name {hw.name!r} (ros2_control's resource "
                       "manager refuses two hardware components of the same name)", hw.line)
        seen_blocks.add(hw.name)
        _check_block(profile, hw, fail, doubt)
        seen_parts: dict[str, Component] = {}
        for comp in hw.components():
            where = comp.line or hw.line
            if comp.name in seen_parts:
                raise fail(f"duplicate name {comp.name!r} in {hw.name!r} (a "
                           f"{seen_parts[comp.name].kind} has it already)", where)
            seen_parts[comp.name] = comp
            if comp.kind == "joint":
                _check_joint(hw, comp, fail, doubt)
            _check_interfaces(hw, comp, interfaces, fail, doubt)
            warnings += _near_standard(comp, src, where)
            if comp.kind == "joint":
                _check_limits(comp, where, fail)
            _check_params(comp.params, f"{comp.kind} {comp.name!r}", where, fail, travel=True)
            if not math.isfinite(comp.offset):
                raise fail(f"deltoctl.offset of {comp.name!r} must be a finite number", where)
            _check_address(profile, hw, comp, addresses, fail)
    _check_safety(profile, fail)
    profile.warnings = _unique(warnings)
    if strict and profile.warnings:
        first = profile.warnings[0]
        raise ProfileError(f"{first.message} (an error under --strict)", first.source, first.line)
    return profile


def _unique(warnings: list[ProfileWarning]) -> list[ProfileWarning]:
    """Each message once (the URDF loader and validation may both notice a thing)."""
    unique: dict[str, ProfileWarning] = {}
    for warning in warnings:
        unique.setdefault(warning.message, warning)
    return list(unique.values())


def _check_profile(profile: Profile, fail: Fail) -> None:
    if profile.status not in ("current", "discontinued"):
        raise fail(f"status must be 'current' or 'discontinued', got {profile.status!r}", None)
    known = registry.families()
    if profile.family is not None and profile.family not in known:
        raise fail(f"unknown driver family {profile.family!r} "
                   f"(known: {', '.join(known)}){registry.install_hint(profile.family)}", None)
    schemes = {s for f in known.values() for s in f.schemes}
    for bus, url in profile.buses.items():
        try:
            scheme = urlsplit(url).scheme
        except ValueError:  # tcp://[::1 (no closing bracket): no URL at all
            scheme = ""
        if scheme not in schemes:
            raise fail(f"bus {bus!r}: {url!r} is not a target URL "
                       "(expected tcp://HOST:PORT, serial:///dev/PORT or i2c:///dev/i2c-N)"
                       + registry.install_hint(scheme=scheme), None)


def _check_block(profile: Profile, hw: Hardware, fail: Fail, doubt: Doubt) -> None:
    if hw.type not in HARDWARE_TYPES:
        raise fail(f"ros2_control block {hw.name!r}: type must be one of "
                   f"{', '.join(HARDWARE_TYPES)}, got {hw.type!r}", hw.line)
    if not hw.plugin and not (profile.source or "").lower().endswith(URDF_SUFFIXES):
        # a URDF may leave out <hardware> (its loader warns); the YAML form needs a plugin
        raise fail(f"missing <plugin> in the <hardware> of {hw.name!r}", hw.line)
    errors, doubts = block_attribute_problems(hw.attributes)
    if errors:
        raise fail(f"ros2_control block {hw.name!r}: {errors[0]}", hw.line)
    for message in doubts:
        doubt(f"<ros2_control name={hw.name!r}>: {message}", hw.line)
    problems = async_property_problems(hw.async_properties)
    if problems:
        raise fail(f"ros2_control block {hw.name!r}, <async>: {problems[0]}", hw.line)
    known = registry.families()
    family_name = profile.family_of(hw)
    if family_name is not None and family_name not in known:
        raise fail(f"unknown driver family {family_name!r} in {hw.name!r} "
                   f"(known: {', '.join(known)})"
                   + registry.install_hint(family_name, hw.plugin), hw.line)
    if hw.bus is not None and hw.bus not in profile.buses:
        raise fail(f"{hw.name!r} names unknown bus {hw.bus!r} "
                   f"(the profile's buses: {', '.join(profile.buses) or 'none'})", hw.line)
    _check_params(hw.params, f"block {hw.name!r}", hw.line, fail)
    for transmission in hw.transmissions:
        for end in transmission.joints + transmission.actuators:
            where = transmission.line or hw.line
            if not math.isfinite(end.mechanical_reduction) or end.mechanical_reduction == 0:
                raise fail(f"transmission {transmission.name!r}: mechanical_reduction of "
                           f"{end.name!r} must be a finite non-zero number", where)
            if not math.isfinite(end.offset):
                raise fail(f"transmission {transmission.name!r}: offset of {end.name!r} must "
                           "be a finite number", where)


def _check_joint(hw: Hardware, joint: Component, fail: Fail, doubt: Doubt) -> None:
    where = joint.line or hw.line
    if joint.joint_type not in JOINT_TYPES:
        raise fail(f"joint {joint.name!r}: type must be one of {', '.join(JOINT_TYPES)}, "
                   f"got {joint.joint_type!r}", where)
    if joint.joint_type == "fixed":
        raise fail(f"joint {joint.name!r} is fixed in the URDF (type 'fixed'): fixed joints do "
                   "not make sense in ros2_control", where)
    if not joint.command_interfaces and not joint.state_interfaces:
        doubt(f"joint {joint.name!r} has no command or state interface", where)
    if joint.mimic is not None:
        if joint.command_interfaces:
            raise fail(f"joint {joint.name!r} mimics {joint.mimic.joint!r} and so cannot have "
                       "command interfaces", where)
        if all(j.name != joint.mimic.joint for j in hw.joints):
            raise fail(f"mimic joint {joint.mimic.joint!r} (mimicked by {joint.name!r}) not "
                       f"found in <ros2_control name={hw.name!r}> tag", where)
        for key in ("multiplier", "offset"):
            if not math.isfinite(getattr(joint.mimic, key)):
                raise fail(f"joint {joint.name!r}: mimic {key} must be a finite number", where)


def _check_limits(joint: Component, where: int | None, fail: Fail) -> None:
    lim = joint.limits
    if lim is not None:
        for key in ("lower", "upper"):
            value = getattr(lim, key)
            if value is not None and not math.isfinite(value):
                raise fail(f"joint {joint.name!r}: {key} limit must be a finite number, got "
                           f"{value}", where)
        if lim.lower is not None and lim.upper is not None and lim.lower > lim.upper:
            raise fail(f"joint {joint.name!r}: lower limit {lim.lower:g} is greater than upper "
                       f"limit {lim.upper:g}", where)
        for key in ("velocity", "effort", "acceleration", "deceleration", "jerk"):
            value = getattr(lim, key)
            if value is not None and not (math.isfinite(value) and value >= 0):
                raise fail(f"joint {joint.name!r}: {key} limit must be a finite number, not "
                           f"negative, got {value}", where)
    soft = joint.soft_limits
    if soft is not None:
        for key in ("lower", "upper", "k_position", "k_velocity"):
            value = getattr(soft, key)
            if not math.isfinite(value) or (key.startswith("k_") and value < 0):
                raise fail(f"joint {joint.name!r}: soft limit {key} must be a finite number"
                           f"{', not negative' if key.startswith('k_') else ''}, got {value}",
                           where)
        if soft.lower > soft.upper:
            raise fail(f"joint {joint.name!r}: soft limits [{soft.lower:g}, {soft.upper:g}] "
                       "leave no room (inside the hard limits, the soft lower limit is above "
                       "the soft upper one)", where)


def _check_interfaces(hw: Hardware, comp: Component, seen: dict[tuple[str, str], str],
                      fail: Fail, doubt: Doubt) -> None:
    where = comp.line or hw.line
    for which in ("command", "state"):
        names: set[str] = set()
        for itf in getattr(comp, f"{which}_interfaces"):
            line = itf.line or where
            if not itf.name:
                raise fail(f"an interface of {comp.name!r} has no name", line)
            if itf.name in names:
                raise fail(f"duplicate {which} interface {comp.name}/{itf.name}", line)
            names.add(itf.name)
            full = f"{comp.name}/{itf.name}"
            other = seen.get((which, full))
            if other is not None:
                raise fail(f"{which} interface {full!r} is declared by both {other!r} and "
                           f"{hw.name!r} (ros2_control routes an interface by its name to one "
                           "hardware component)", line)
            seen[(which, full)] = hw.name
            _check_interface(comp, itf, line, fail, doubt)


# ros2_control's standard interface names (hardware_interface_type_values.hpp)
STANDARD_INTERFACES = ("position", "velocity", "acceleration", "effort", "torque", "force",
                       "current", "temperature")


def _near_standard(comp: Component, src: str | None,
                   where: int | None) -> list[ProfileWarning]:
    """A warning for each interface name one letter off a standard one (``positon``): a
    controller that claims ``position`` would never find it."""
    found = []
    for itf in [*comp.command_interfaces, *comp.state_interfaces]:
        near = [n for n in STANDARD_INTERFACES if one_letter_off(itf.name, n)]
        if near:
            found.append(ProfileWarning(
                f"{comp.name}/{itf.name}: did you mean {comp.name}/{near[0]}? ({itf.name!r} is "
                "one letter off a standard interface name of ros2_control)",
                src, itf.line or where))
    return found


def one_letter_off(typed: str, name: str) -> bool:
    """Whether ``typed`` is ``name`` with one letter left out, added, changed, or swapped with
    its neighbour (``positon``, ``postion``, ``velocty``)."""
    if typed == name or abs(len(typed) - len(name)) > 1:
        return False
    start = next((i for i, (a, b) in enumerate(zip(typed, name)) if a != b),
                 min(len(typed), len(name)))
    rest_t, rest_n = typed[start:], name[start:]
    return (rest_t[1:] == rest_n[1:] or rest_t == rest_n[1:] or rest_t[1:] == rest_n
            or (len(rest_t) > 1 and rest_t[:2] == rest_n[1::-1] and rest_t[2:] == rest_n[2:]))


def _check_interface(comp: Component, itf: Interface, line: int | None, fail: Fail,
                     doubt: Doubt) -> None:
    what = f"{comp.name}/{itf.name}"
    for key in ("min", "max"):
        value = getattr(itf, key)
        if value is not None and not math.isfinite(value):
            raise fail(f"{what}: {key} must be a finite number, got {value}", line)
    if itf.min is not None and itf.max is not None and itf.min > itf.max:
        raise fail(f"{what}: min {itf.min} is greater than max {itf.max}", line)
    if itf.data_type is not None and itf.data_type not in DATA_TYPES:
        doubt(f"{what}: unknown data_type {itf.data_type!r} (expected one of "
              f"{', '.join(DATA_TYPES)}; ros2_control cannot make a handle of another type)", line)
    if itf.size is not None and itf.size < 1:
        raise fail(f"{what}: size must be at least 1", line)
    _check_params(itf.params, f"interface {what}", line, fail)


# Params whose numbers bound motion or timing: finite, and the first kind not negative. A
# joint's own min/max params (the Bioscara's travel) count; an interface's are its limits,
# read (or, unreadable, skipped with a warning) as ros2_control does.
_NOT_NEGATIVE = re.compile(r".*_rate|.*_current|current|max_.*")
_FINITE = re.compile(r".*_velocity|.*_acceleration|.*_speed|velocity|acceleration|speed")
_TRAVEL = re.compile(r"min|max")
_FLAGS = frozenset({"detect_sweep"})  # true or false (a Dynamixel Protocol 1.0 block's sweep)


def _check_params(params: dict[str, str], owner: str, line: int | None, fail: Fail,
                  travel: bool = False) -> None:
    for name, value in params.items():
        if name in _FLAGS:
            try:
                parse_bool(str(value))
            except ValueError:
                raise fail(f"param {name!r} of {owner} is true or false, got {value!r}",
                           line) from None
        not_negative = _NOT_NEGATIVE.fullmatch(name) is not None
        finite = _FINITE.fullmatch(name) or (travel and _TRAVEL.fullmatch(name))
        if not (not_negative or finite) or not str(value).strip():
            continue
        number = parse_number(str(value))
        if number is None:
            raise fail(f"param {name!r} of {owner} must be a finite number, got {value!r}", line)
        if not_negative and number < 0:
            raise fail(f"param {name!r} of {owner} must not be negative, got {value!r}", line)


def _check_address(profile: Profile, hw: Hardware, comp: Component,
                   addresses: dict[tuple[str, int], str], fail: Fail) -> None:
    where = comp.line or hw.line
    if comp.bus is not None and comp.bus not in profile.buses:
        raise fail(f"{comp.name!r} names unknown bus {comp.bus!r} "
                   f"(the profile's buses: {', '.join(profile.buses) or 'none'})", where)
    address = part_address(profile, hw, comp)
    if address is None:
        return
    family = registry.families().get(profile.family_of(hw) or "")
    if family and family.address_range:
        low, high = family.address_range
        if not low <= address <= high:
            show = family.show_address
            raise fail(f"{family.address_kind} of {comp.name!r} must be within "
                       f"{show(low)}..{show(high)}, got {show(address)}", where)
    key = (profile.bus_of(hw, comp) or hw.name, address)
    if key in addresses:
        raise fail(f"{comp.name!r} has the same address {address} as "
                   f"{addresses[key]!r} on bus {key[0]!r}", where)
    addresses[key] = comp.name


# -- safety settings -----------------------------------------------------------------------------

# field: (must be positive (else: not negative), what it means)
_SAFETY_NUMBERS = {
    "max_jog_step": (True, "the largest single jog"),
    "current_cap": (True, "the current bound of a move, mA"),
    "home_tolerance": (False, "how close homing must get"),
    "home_timeout": (True, "how long homing may take, s"),
}


def _check_safety(profile: Profile, fail: Fail) -> None:
    safety = profile.safety
    for key, (positive, meaning) in _SAFETY_NUMBERS.items():
        value = getattr(safety, key)
        if value is None:
            continue
        bad = not math.isfinite(value) or (value <= 0 if positive else value < 0)
        if bad:
            rule = "a finite number above 0" if positive else "a finite number, not negative"
            raise fail(f"safety.{key} ({meaning}) must be {rule}, got {value}",
                       _line_of(profile, key))
    joints = {j.name: j for j in profile.joints()}
    for name, value in safety.home_pose.items():
        line = _line_of(profile, "home_pose")
        if name not in joints:
            raise fail(f"safety.home_pose names unknown joint {name!r}", line)
        if not math.isfinite(value):
            raise fail(f"safety.home_pose of {name!r} must be a finite number, got {value}", line)
        joint = joints[name]
        for kind, bounds in (("limits", joint.limits), ("soft limits", joint.soft_limits)):
            if bounds is not None and not bounds.contains(value):
                raise fail(f"safety.home_pose of {name!r} ({value:g}) is outside its {kind} "
                           f"[{_bound(bounds.lower)}, {_bound(bounds.upper)}]", line)
    for name in safety.homing_order:
        if name not in joints:
            raise fail(f"safety.homing_order names unknown joint {name!r}",
                       _line_of(profile, "homing_order"))


def _bound(value: float | None) -> str:
    return "none" if value is None else f"{value:g}"


def _line_of(profile: Profile, key: str) -> int | None:
    """The line of the file that sets ``key`` (the model keeps no line for safety settings)."""
    if not profile.source:
        return None
    try:
        lines = Path(profile.source).read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError):
        return None
    pattern = re.compile(rf"(^|[\s{{,.\"']){re.escape(key)}\b")
    return next((n for n, text in enumerate(lines, 1) if pattern.search(text)), None)
