"""Load a YAML profile into the model, naming ``file:line`` for every problem.

A profile is untrusted: only plain YAML types are built (a safe loader), and before anything
is built a pass over the parser's events bounds the nesting depth and the number of nodes with
every alias expanded, so an alias bomb or a deeply nested file is refused at once.
"""

from __future__ import annotations

import contextlib
import stat
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml

from deltoctl.errors import ProfileError
from deltoctl.profile.model import (
    Component,
    Hardware,
    Interface,
    Limits,
    Mimic,
    Profile,
    Safety,
    SoftLimits,
    Transmission,
    TransmissionEnd,
    clamp_soft_limits,
    fill_transmission,
    merge_interface_limits,
)
from deltoctl.units import (
    format_number,
    joint_dimension,
    mismatch,
    parse_quantity,
    parse_unit,
)


def param_text(value: Any) -> str:
    """ros2_control keeps every param as text; numbers get their shortest exact form."""
    if isinstance(value, (bool, int, float)):
        return format_number(value)
    return str(value)

if TYPE_CHECKING:  # one class to type against; libyaml's loader behaves the same
    from yaml import SafeLoader as _BaseLoader
else:
    _BaseLoader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)

MAX_YAML_DEPTH = 64
MAX_YAML_NODES = 100_000  # counting each alias as the nodes it stands for


class LineDict(dict):
    """A mapping that remembers the line of itself and of each key."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.line = 0
        self.lines: dict[Any, int] = {}


class LineList(list):
    """A list that remembers the line of itself and of each item."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.line = 0
        self.lines: list[int] = []


class _Loader(_BaseLoader):
    pass


def _construct_mapping(loader: _Loader, node: yaml.MappingNode) -> LineDict:
    result = LineDict()
    result.line = node.start_mark.line + 1
    loader.flatten_mapping(node)
    for key_node, value_node in node.value:
        key = loader.construct_object(key_node, deep=True)
        line = key_node.start_mark.line + 1
        if isinstance(key, (dict, list, set)):
            kind = "mapping" if isinstance(key, dict) else type(key).__name__.lower()
            kind = "list" if isinstance(key, list) else kind
            raise ProfileError(f"a mapping key must be a single value, not a {kind}",
                               loader.name, line)
        if key in result:
            raise ProfileError(f"duplicate key {key!r}", loader.name, line)
        result[key] = loader.construct_object(value_node, deep=True)
        result.lines[key] = line
    return result


def _construct_sequence(loader: _Loader, node: yaml.SequenceNode) -> LineList:
    result = LineList(loader.construct_object(child, deep=True) for child in node.value)
    result.line = node.start_mark.line + 1
    result.lines = [child.start_mark.line + 1 for child in node.value]
    return result


_Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)
_Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_SEQUENCE_TAG, _construct_sequence)


class _Bounds:
    """Counts the nodes of a document as the parser's events go by, aliases expanded."""

    def __init__(self, source: str) -> None:
        self.source = source
        self.nodes = 0
        self.sizes: dict[str, int] = {}  # anchor -> expanded nodes, once its node is complete
        self.open: list[tuple[str | None, int]] = []  # collections being read: anchor, nodes

    def add(self, count: int, line: int) -> None:
        self.nodes += count
        if self.nodes > MAX_YAML_NODES:
            raise ProfileError(f"more than {MAX_YAML_NODES} YAML nodes with aliases expanded "
                               "(an alias bomb?)", self.source, line)
        if self.open:
            anchor, size = self.open[-1]
            self.open[-1] = (anchor, size + count)

    def event(self, event: yaml.Event) -> None:
        line = event.start_mark.line + 1 if event.start_mark else 0
        if isinstance(event, yaml.AliasEvent):
            if event.anchor not in self.sizes:
                if any(anchor == event.anchor for anchor, _ in self.open):
                    raise ProfileError(f"alias *{event.anchor} refers to itself", self.source,
                                       line)
                return  # an undefined alias: the composer reports it
            self.add(self.sizes[event.anchor], line)
        elif isinstance(event, yaml.ScalarEvent):
            self.add(1, line)
            if event.anchor:
                self.sizes[event.anchor] = 1
        elif isinstance(event, yaml.CollectionStartEvent):
            if len(self.open) >= MAX_YAML_DEPTH:
                raise ProfileError(f"YAML nested deeper than {MAX_YAML_DEPTH} levels",
                                   self.source, line)
            self.add(1, line)
            self.open.append((event.anchor, 1))
        elif isinstance(event, yaml.CollectionEndEvent):
            anchor, size = self.open.pop()
            if anchor:
                self.sizes[anchor] = size
            if self.open:
                parent, total = self.open[-1]
                self.open[-1] = (parent, total + size - 1)  # its start was counted already


def _yaml_error(exc: Exception, source: str) -> ProfileError:
    if isinstance(exc, yaml.MarkedYAMLError):
        mark = exc.problem_mark or exc.context_mark
        line = mark.line + 1 if mark else None
        return ProfileError(f"not valid YAML: {exc.problem or exc}", source, line)
    # e.g. a timestamp with a day 2001-02-30, or an integer of 5000 digits
    message = " ".join(str(exc).split()) or type(exc).__name__
    return ProfileError(f"not valid YAML: {message}", source)


def check_yaml_bounds(text: str, source: str) -> None:
    """Refuse a document nested too deeply or too large with its aliases expanded.

    Runs over the parser's events only, stopping at the first excess: the C composer
    recurses without a limit and the node graph of an alias bomb is small until expanded.
    """
    bounds = _Bounds(source)
    try:
        for event in yaml.parse(text, Loader=_BaseLoader):
            bounds.event(event)
    except yaml.YAMLError as exc:
        if "nesting depth" in str(exc):  # newer PyYAML scans far ahead in flow style
            raise ProfileError(f"YAML nested deeper than {MAX_YAML_DEPTH} levels",
                               source) from None
        raise _yaml_error(exc, source) from None


def load_data(text: str, source: str, loader_class: type | None = None) -> Any:
    """One YAML document, bounded, built with ``loader_class`` (default: the line-keeping one)."""
    check_yaml_bounds(text, source)
    loader = (loader_class or _Loader)(text)
    loader.name = source
    try:
        return loader.get_single_data()
    except ProfileError:
        raise
    except (yaml.YAMLError, ArithmeticError, LookupError, TypeError, ValueError,
            RecursionError) as exc:
        raise _yaml_error(exc, source) from None
    finally:
        loader.dispose()


def parse_yaml(text: str, source: str) -> Any:
    return load_data(text, source)


def read_text(path: Path, what: str, limit: int | None = None, kind: str = "profile") -> str:
    """The text of a ``kind`` of file (a profile, a snapshot …), refusing one larger than
    ``limit`` (MAX_PROFILE_BYTES by default) or not a regular file, before reading it."""
    from deltoctl.profile.files import MAX_PROFILE_BYTES

    limit = MAX_PROFILE_BYTES if limit is None else limit
    source = str(path)
    try:
        if not stat.S_ISREG(path.stat().st_mode):  # a FIFO or a device would block or not end
            raise ProfileError("not a regular file", source)
        with path.open("rb") as f:
            data = f.read(limit + 1)
    except OSError as exc:
        raise ProfileError(f"cannot read the {kind}: {exc.strerror}", source) from None
    if len(data) > limit:
        raise ProfileError(f"larger than {limit >> 20} MiB, the limit for a {kind}", source)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise ProfileError(f"not a text file (expected UTF-8 {what})", source) from None


class _Reader:
    """Checks keys and types of one YAML document, locating each complaint."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, message: str, line: int | None) -> ProfileError:
        return ProfileError(message, self.source, line)

    def mapping(self, value: Any, what: str, line: int | None, allowed: set[str]) -> LineDict:
        if not isinstance(value, LineDict):
            raise self.fail(f"{what} must be a mapping, got {type(value).__name__}", line)
        for key in value:
            if key not in allowed:
                expected = ", ".join(sorted(allowed))
                raise self.fail(f"unknown key {key!r} in {what} (expected one of: {expected})",
                                value.lines[key])
        return value

    def require(self, d: LineDict, key: str, what: str) -> Any:
        if key not in d or d[key] is None or d[key] == "":
            raise self.fail(f"{what} needs '{key}'", d.line)
        return d[key]

    def string(self, d: LineDict, key: str, what: str, required: bool = False) -> str | None:
        if required:
            self.require(d, key, what)
        value = d.get(key)
        if value is None:
            return None
        if not isinstance(value, (str, int, float)) or isinstance(value, bool):
            raise self.fail(f"'{key}' of {what} must be text", d.lines[key])
        return str(value)

    def number(self, d: LineDict, key: str, what: str) -> float | None:
        value = d.get(key)
        if value is None:
            return None
        try:
            return parse_quantity(value)
        except ValueError as exc:
            raise self.fail(f"'{key}' of {what}: {exc}", d.lines[key]) from None

    def integer(self, d: LineDict, key: str, what: str) -> int | None:
        value = d.get(key)
        if value is None:
            return None
        if isinstance(value, str):
            with contextlib.suppress(ValueError):
                value = int(value, 0)
        if not isinstance(value, int) or isinstance(value, bool):
            raise self.fail(f"'{key}' of {what} must be a whole number, got {value!r}",
                            d.lines[key])
        return value

    def boolean(self, d: LineDict, key: str, what: str, default: bool = False) -> bool:
        value = d.get(key, default)
        if not isinstance(value, bool):
            raise self.fail(f"'{key}' of {what} must be true or false, got {value!r}",
                            d.lines[key])
        return value

    def sequence(self, d: LineDict, key: str, what: str) -> LineList:
        value = d.get(key)
        if value is None:
            return LineList()
        if not isinstance(value, LineList):
            raise self.fail(f"'{key}' of {what} must be a list", d.lines[key])
        return value

    def scalars(self, d: LineDict, key: str, what: str) -> dict[str, Any]:
        value = d.get(key)
        if value is None:
            return {}
        if not isinstance(value, LineDict):
            raise self.fail(f"'{key}' of {what} must be a mapping of name: value", d.lines[key])
        for name, item in value.items():
            if isinstance(item, (dict, list)):
                raise self.fail(f"param {name!r} of {what} must be a single value",
                                value.lines[name])
        return {str(k): param_text(v) for k, v in value.items() if v is not None}


_INTERFACE_KEYS = {
    "name", "min", "max", "initial_value", "data_type", "size", "params", "enable_limits",
}
_COMPONENT_KEYS = {
    "name", "command_interfaces", "state_interfaces", "params", "bus", "address",
}
_KEYS = {
    "gpio": _COMPONENT_KEYS,
    "sensor": _COMPONENT_KEYS | {"enable_limits"},
    "joint": _COMPONENT_KEYS | {"type", "limits", "soft_limits", "enable_limits", "mimic",
                                "inverse", "offset"},
}
_LIMIT_KEYS = {"lower", "upper", "velocity", "effort", "acceleration", "deceleration", "jerk"}
_SOFT_LIMIT_KEYS = {"lower", "upper", "k_position", "k_velocity"}
_HARDWARE_KEYS = {
    "name", "type", "plugin", "params", "group", "family", "bus", "joints", "sensors", "gpios",
    "attributes", "async_properties", "transmissions",
}
_TRANSMISSION_KEYS = {"name", "type", "joints", "actuators", "params"}
_END_KEYS = {"name", "role", "mechanical_reduction", "offset", "read_only"}
_PROFILE_KEYS = {
    "name", "description", "family", "model", "status", "buses", "safety", "ros2_control",
    "report",
}
# the limits of `deltoctl report` a profile may set
REPORT_LIMITS = {
    "rtt_p50_ms", "rtt_p99_ms", "error_rate_perc", "loop_rate_ratio", "jitter_p99_ms",
    "homes", "home_repeatability", "following_error",
}
_SAFETY_KEYS = {
    "home_pose", "max_jog_step", "current_cap", "home_tolerance", "home_timeout",
    "homing_order",
}


def _interface(r: _Reader, item: Any, line: int, owner: str) -> Interface:
    if isinstance(item, str):
        return Interface(name=item, line=line)
    what = f"an interface of {owner}"
    d = r.mapping(item, what, line, _INTERFACE_KEYS)
    name = r.string(d, "name", what, required=True)
    initial = d.get("initial_value")
    return Interface(
        name=name or "",
        min=r.number(d, "min", f"{owner}/{name}"),
        max=r.number(d, "max", f"{owner}/{name}"),
        initial_value=None if initial is None else param_text(initial),
        data_type=r.string(d, "data_type", f"{owner}/{name}"),
        size=r.integer(d, "size", f"{owner}/{name}"),
        params=r.scalars(d, "params", f"{owner}/{name}"),
        enable_limits=r.boolean(d, "enable_limits", f"{owner}/{name}", default=True),
        line=d.line,
    )


def _component(r: _Reader, kind: str, item: Any, line: int) -> Component:
    what = f"a {kind}"
    d = r.mapping(item, what, line, _KEYS[kind])
    name = r.string(d, "name", what, required=True) or ""
    what = f"{kind} {name!r}"
    comp = Component(kind=kind, name=name, line=d.line)
    for key in ("command_interfaces", "state_interfaces"):
        items = r.sequence(d, key, what)
        setattr(comp, key, [_interface(r, i, ln, name) for i, ln in zip(items, items.lines)])
    comp.params = r.scalars(d, "params", what)
    comp.bus = r.string(d, "bus", what)
    comp.address = r.integer(d, "address", what)
    if kind != "gpio":
        comp.enable_limits = r.boolean(d, "enable_limits", what, default=True)
    if kind == "joint":
        comp.joint_type = r.string(d, "type", what) or "revolute"
        comp.inverse = r.boolean(d, "inverse", what)
        comp.offset = r.number(d, "offset", what) or 0.0
        if "limits" in d:
            ld = r.mapping(d["limits"], f"limits of {what}", d.lines["limits"], _LIMIT_KEYS)
            _limit_units(r, ld, comp, "limits")
            comp.limits = Limits(**{k: r.number(ld, k, what) for k in sorted(_LIMIT_KEYS)})
        if "soft_limits" in d:
            comp.soft_limits = _soft_limits(r, d, comp, what)
        if "mimic" in d:
            md = r.mapping(d["mimic"], f"mimic of {what}", d.lines["mimic"],
                           {"joint", "multiplier", "offset"})
            comp.mimic = Mimic(
                joint=r.string(md, "joint", f"mimic of {what}", required=True) or "",
                multiplier=r.number(md, "multiplier", what) or 1.0,
                offset=r.number(md, "offset", what) or 0.0,
            )
    return comp


def _soft_limits(r: _Reader, d: LineDict, joint: Component, what: str) -> SoftLimits:
    """A ``<safety_controller>``'s soft limits, clamped into the joint's limits as the URDF
    loader (and ros2_control) clamps them."""
    sd = r.mapping(d["soft_limits"], f"soft_limits of {what}", d.lines["soft_limits"],
                   _SOFT_LIMIT_KEYS)
    _limit_units(r, sd, joint, "soft_limits")
    soft = SoftLimits(**{k: r.number(sd, k, f"soft_limits of {what}") or 0.0
                         for k in sorted(_SOFT_LIMIT_KEYS)})
    return clamp_soft_limits(soft, merge_interface_limits(joint.limits, joint))


def _transmission(r: _Reader, hw: Hardware, item: Any, line: int) -> Transmission:
    what = f"a transmission of {hw.name!r}"
    d = r.mapping(item, what, line, _TRANSMISSION_KEYS)
    name = r.string(d, "name", what, required=True) or ""
    what = f"transmission {name!r}"
    transmission = Transmission(name=name, type=r.string(d, "type", what) or "",
                                params=r.scalars(d, "params", what), line=d.line)
    for key in ("joints", "actuators"):
        items = r.sequence(d, key, what)
        setattr(transmission, key, [_end(r, i, ln, what) for i, ln in zip(items, items.lines)])
    try:
        fill_transmission(hw, transmission)
    except ValueError as exc:
        raise r.fail(str(exc), d.line) from None
    return transmission


def _end(r: _Reader, item: Any, line: int, owner: str) -> TransmissionEnd:
    what = f"an end of {owner}"
    d = r.mapping(item, what, line, _END_KEYS)
    reduction = r.number(d, "mechanical_reduction", what)
    return TransmissionEnd(
        name=r.string(d, "name", what, required=True) or "",
        role=r.string(d, "role", what) or "",
        mechanical_reduction=1.0 if reduction is None else reduction,
        offset=r.number(d, "offset", what) or 0.0,
        read_only=r.boolean(d, "read_only", what),
    )


def _hardware(r: _Reader, item: Any, line: int) -> Hardware:
    d = r.mapping(item, "a ros2_control block", line, _HARDWARE_KEYS)
    name = r.string(d, "name", "a ros2_control block", required=True) or ""
    what = f"ros2_control block {name!r}"
    hw = Hardware(
        name=name,
        type=r.string(d, "type", what) or "system",
        plugin=r.string(d, "plugin", what) or "",
        params=r.scalars(d, "params", what),
        group=r.string(d, "group", what),
        family=r.string(d, "family", what),
        bus=r.string(d, "bus", what),
        attributes=r.scalars(d, "attributes", what),
        async_properties=r.scalars(d, "async_properties", what),
        line=d.line,
    )
    for key, kind in (("joints", "joint"), ("sensors", "sensor"), ("gpios", "gpio")):
        items = r.sequence(d, key, what)
        setattr(hw, key, [_component(r, kind, i, ln) for i, ln in zip(items, items.lines)])
    items = r.sequence(d, "transmissions", what)
    hw.transmissions = [_transmission(r, hw, i, ln) for i, ln in zip(items, items.lines)]
    return hw


def _safety(r: _Reader, d: LineDict) -> Safety:
    s = r.mapping(d["safety"], "safety", d.lines["safety"], _SAFETY_KEYS)
    pose = s.get("home_pose", LineDict())
    pose = r.mapping(pose, "safety.home_pose", s.lines.get("home_pose"), set(pose))
    order = r.sequence(s, "homing_order", "safety")
    return Safety(
        home_pose={str(k): r.number(pose, k, "safety.home_pose") or 0.0 for k in pose},
        max_jog_step=r.number(s, "max_jog_step", "safety"),
        current_cap=r.number(s, "current_cap", "safety"),
        home_tolerance=r.number(s, "home_tolerance", "safety"),
        home_timeout=r.number(s, "home_timeout", "safety"),
        homing_order=[str(j) for j in order],
    )


def profile_from_data(data: Any, source: str) -> Profile:
    r = _Reader(source)
    d = r.mapping(data, "the profile", 1, _PROFILE_KEYS)
    name = r.string(d, "name", "the profile", required=True) or ""
    profile = Profile(
        name=name,
        description=r.string(d, "description", "the profile") or "",
        family=r.string(d, "family", "the profile"),
        model=r.string(d, "model", "the profile"),
        status=r.string(d, "status", "the profile") or "current",
        source=source,
    )
    buses = r.scalars(d, "buses", "the profile")
    profile.buses = buses
    if "safety" in d:
        profile.safety = _safety(r, d)
    if "report" in d:
        limits = r.mapping(d["report"], "report", d.lines["report"], REPORT_LIMITS)
        profile.report = {str(k): r.number(limits, k, "report") or 0.0 for k in limits}
    blocks = r.sequence(d, "ros2_control", "the profile")
    if not blocks:
        raise r.fail("the profile needs at least one block under 'ros2_control'", d.line)
    profile.hardware = [_hardware(r, i, ln) for i, ln in zip(blocks, blocks.lines)]
    if "safety" in d:
        _check_safety_units(r, profile, d["safety"])
    return profile


def _check_safety_units(r: _Reader, profile: Profile, safety: LineDict) -> None:
    """A home pose in its joint's unit (no ``5mm`` on a revolute joint); ``max_jog_step``
    and ``home_tolerance`` in the unit of every joint they bound (a bare number is SI for
    each)."""
    joints = {j.name: j for j in profile.joints()}
    pose = safety.get("home_pose") or LineDict()
    for name, value in pose.items():
        if str(name) in joints:
            _fits(r, value, joints[str(name)], f"safety.home_pose of {name}", pose.lines[name])
    for key in ("max_jog_step", "home_tolerance"):
        if safety.get(key) is not None:
            for joint in joints.values():
                _fits(r, safety[key], joint, f"safety.{key}", safety.lines[key])


def _limit_units(r: _Reader, limits: LineDict, joint: Component, key: str) -> None:
    """A joint's (soft) limits in its unit: lower and upper its positions (no ``20deg`` on a
    prismatic joint, no ``/s``), velocity its speed."""
    for name, speed in (("lower", False), ("upper", False), ("velocity", True)):
        if limits.get(name) is not None:
            with contextlib.suppress(ValueError):  # not a quantity: r.number names it
                _fits(r, limits[name], joint, f"{key}.{name} of joint {joint.name!r}",
                      limits.lines[name], speed)


def _fits(r: _Reader, value: Any, joint: Component, what: str, line: int | None,
          speed: bool = False) -> None:
    wrong = mismatch(parse_unit(value), joint_dimension(joint.joint_type), speed)
    if wrong:
        raise r.fail(f"{what} ({value}): {joint.name} is a {joint.joint_type} joint, so it "
                     f"takes {wrong}", line)


def load_yaml_profile(path: Path) -> Profile:
    source = str(path)
    text = read_text(path, "YAML")
    data = parse_yaml(text, source)
    if data is None:
        raise ProfileError("the file is empty (expected a YAML profile)", source, 1)
    return profile_from_data(data, source)
