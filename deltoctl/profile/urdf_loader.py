"""Load the ``<ros2_control>`` blocks of a URDF or xacro file into the model.

Follows ros2_control's component_parser and the URDF model it builds with urdfdom: a ``<robot>``
root (or ``<sdf><model>``), at least one ``<ros2_control>``, only known tags under it, a
``<plugin>`` in every ``<hardware>``, valid ``rw_rate``/``is_async``/``thread_priority``,
transmissions whose joints are the block's, every joint present in the URDF and not fixed, mimic
joints without command interfaces mimicking a joint of the same block, revolute and prismatic
joints with a ``<limit>``, links that form one tree. Joint limits are merged as ros2_control does
(the stricter of the URDF ``<limit>`` and the interfaces' ``min``/``max``); a
``<safety_controller>`` becomes soft limits, kept apart. What ros2_control lets through but
deltoctl finds doubtful becomes a warning on the profile. deltoctl's own fields travel as
``<param name="deltoctl.…">`` entries, so an exported profile loads back unchanged.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from pathlib import Path

from deltoctl import registry
from deltoctl.errors import ProfileError
from deltoctl.profile.model import (
    Component,
    Hardware,
    Interface,
    Limits,
    Mimic,
    Profile,
    ProfileWarning,
    Safety,
    SoftLimits,
    Transmission,
    TransmissionEnd,
    clamp_soft_limits,
    fill_transmission,
    merge_interface_limits,
    parse_bool,
    parse_number,
)
from deltoctl.profile.validate import async_property_problems, block_attribute_problems
from deltoctl.profile.xmltree import Node, XMLSyntaxError, parse_xml

PREFIX = "deltoctl."
PROFILE_PREFIX = "deltoctl.profile."
LIMITS_PREFIX = "deltoctl.limits."  # limits neither <limit> nor the interfaces hold

_ROS2_CONTROL_CHILDREN = {"hardware", "properties", "joint", "sensor", "gpio", "transmission"}
_HARDWARE_CHILDREN = {"plugin", "param", "group"}
_COMPONENT_CHILDREN = {"command_interface", "state_interface", "param", "limits"}
_INTERFACE_CHILDREN = {"param", "limits"}
_URDF_JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")
_LIMIT_KINDS = ("position", "velocity", "effort", "acceleration", "jerk")
_SIZE = re.compile(r"[1-9][0-9]*")


@dataclass
class UrdfJoint:
    """A joint of the robot model, read as urdfdom and ``getJointLimits`` read it."""

    name: str
    type: str
    limits: Limits | None  # None: no <limit> (ros2_control's has_*_limits all false)
    mimic: Mimic | None
    soft_limits: SoftLimits | None = None  # the <safety_controller>, not yet clamped


class _Locator:
    """Maps an element to the best ``file:line`` a person can open, and collects warnings."""

    def __init__(self, source: str, expanded: bool, files: list[str]) -> None:
        self.source = source
        self.expanded = expanded
        self.warnings: list[ProfileWarning] = []
        self.texts: list[tuple[str, list[str]]] = []
        if expanded:
            for f in [source, *files]:
                try:
                    self.texts.append((f, Path(f).read_text(encoding="utf-8").splitlines()))
                except (OSError, UnicodeDecodeError):
                    continue

    def where(self, node: Node | None) -> tuple[str, int | None, str]:
        """(file, line, suffix for the message) of ``node``."""
        if node is None:
            return self.source, None, ""
        if not self.expanded:
            return self.source, node.line, ""
        name = node.attrib.get("name")
        if name:
            needle = f'name="{name}"'
            for f, lines in self.texts:
                for number, text in enumerate(lines, 1):
                    if f"<{node.tag}" in text and needle in text:
                        return f, number, ""
        return self.source, None, f" (line {node.line} of the xacro output)"

    def error(self, message: str, node: Node | None) -> ProfileError:
        source, line, suffix = self.where(node)
        return ProfileError(message + suffix, source, line)

    def warn(self, message: str, node: Node | None) -> None:
        source, line, suffix = self.where(node)
        self.warnings.append(ProfileWarning(message + suffix, source, line))


def load_urdf_profile(
    path: Path,
    xacro_args: Mapping[str, str] | None = None,
    packages: Mapping[str, str] | None = None,
    xacro: bool = False,
) -> Profile:
    source = str(path)
    try:
        raw = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ProfileError(f"cannot read the file: {exc.strerror}", source) from None
    except UnicodeDecodeError:
        raise ProfileError("not a text file (expected URDF or xacro XML)", source) from None
    expanded = path.name.endswith(".xacro") or xacro
    files: list[str] = []
    text = raw
    if expanded:
        from deltoctl.profile.xacro_runner import included_files, run_xacro

        try:
            parse_xml(raw)  # report plain XML errors against the file itself
        except XMLSyntaxError as exc:
            raise ProfileError(f"not well-formed XML: {exc}", source, exc.line) from None
        text = run_xacro(path, xacro_args or {}, packages)
        files = included_files()
    if not text.strip():
        raise ProfileError("empty URDF: the file holds no XML (expected a <robot> with a "
                           "<ros2_control> block)", source, 1)
    try:
        root = parse_xml(_blank_declaration(text))
    except XMLSyntaxError as exc:
        raise ProfileError(f"invalid URDF, not well-formed XML: {exc}", source, exc.line) from None
    return profile_from_urdf(root, _Locator(source, expanded, files), path)


def _blank_declaration(text: str) -> str:
    """The text with its ``<?xml …?>`` declaration turned into spaces. tinyxml2 (ros2_control's
    parser) accepts whitespace before the declaration, as launch files and the test assets
    write it; expat does not. Blanking it in place keeps every line number."""
    start = len(text) - len(text.lstrip())
    if not text.startswith("<?xml", start):
        return text
    end = text.find("?>", start)
    if end < 0:
        return text
    end += 2
    blank = "".join(c if c == "\n" else " " for c in text[start:end])
    return text[:start] + blank + text[end:]


def profile_from_urdf(root: Node, loc: _Locator, path: Path) -> Profile:
    model = _model_root(root, loc)
    blocks = model.find_all("ros2_control")
    if not blocks:
        raise loc.error(
            f"no <ros2_control> block in this URDF (no 'ros2_control' tag found; "
            f"{len(model.find_all('joint'))} joints found); deltoctl needs the block that names "
            "the hardware plugin and interfaces", root)
    hardware = [_hardware(b, loc) for b in blocks]
    urdf_joints = _sdf_joints(model, loc) if root.tag == "sdf" else _urdf_joints(model, loc)
    for hw, block in zip(hardware, blocks):
        joint_nodes = block.find_all("joint")
        for comp, node in zip(hw.joints, joint_nodes):
            _join_urdf(hw, comp, node, urdf_joints, loc)

    first = hardware[0].params
    profile_params = {k[len(PROFILE_PREFIX):]: first.pop(k)
                      for k in list(first) if k.startswith(PROFILE_PREFIX)}
    name = profile_params.pop("name", None) or model.attrib.get("name") or hardware[0].name
    profile = Profile(
        name=_slug(name),
        description=profile_params.pop("description", ""),
        family=profile_params.pop("family", None),
        model=profile_params.pop("model", None),
        status=profile_params.pop("status", "current"),
        source=loc.source,
    )
    profile.buses = {k[len("buses."):]: profile_params.pop(k)
                     for k in list(profile_params) if k.startswith("buses.")}
    profile.safety = _safety(profile_params, loc)
    if profile_params:
        unknown = ", ".join(PROFILE_PREFIX + k for k in profile_params)
        raise loc.error(f"unknown deltoctl params: {unknown}", blocks[0])
    profile.hardware = hardware
    for hw in hardware:
        if hw.family is None and profile.family is None:
            hw.family = registry.for_plugin(hw.plugin)
        _import_endpoint(profile, hw)
        family = registry.get(profile.family_of(hw))
        if family is not None and family.import_block:  # the plugin's own conventions
            registry._load(family.import_block)(profile, hw)
    profile.warnings = loc.warnings
    return profile


def _model_root(root: Node, loc: _Locator) -> Node:
    """``<robot>``, or the ``<model>`` of an ``<sdf>`` (which ros2_control also reads)."""
    if root.tag == "robot":
        return root
    model = root.find("model") if root.tag == "sdf" else None
    if model is None:
        raise loc.error(f"the root element must be <robot> (or <sdf> holding a <model>), not "
                        f"<{root.tag}>: the robot tag is not the root element", root)
    return model


def _slug(name: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", name.lower()).strip("-") or "profile"


def _float(value: str | None, what: str, node: Node | None, loc: _Locator) -> float | None:
    """A deltoctl param's number (validation then checks its range)."""
    if value is None or value.strip() == "":
        return None
    try:
        return float(value)
    except ValueError:
        raise loc.error(f"{what} must be a number, got {value!r}", node) from None


def _required(node: Node, attribute: str, loc: _Locator, context: str = "") -> str:
    """An attribute ros2_control requires: "no attribute 'name' in the <joint> tag"."""
    value = node.attrib.get(attribute)
    if value is None:
        raise loc.error(f"no attribute '{attribute}' in the <{node.tag}> tag{context}", node)
    return value.strip()


def _bool_attr(node: Node, attribute: str, loc: _Locator, context: str = "") -> bool:
    try:
        return parse_bool(_required(node, attribute, loc, context))
    except ValueError as exc:
        raise loc.error(f"{attribute} of <{node.tag}>{context}: {exc}", node) from None


# -- the robot model (what urdfdom checks before ros2_control looks at a joint) -----------------

def _urdf_number(node: Node, attribute: str, owner: str, loc: _Locator) -> float | None:
    """A number of the robot model, read as urdfdom reads it; ``None`` when absent."""
    text = node.attrib.get(attribute)
    if text is None:
        return None
    value = parse_number(text)
    if value is None:
        raise loc.error(f"{attribute} of joint {owner!r} must be a number, got {text!r} "
                        f"(urdfdom: {attribute} value is not a valid float)", node)
    return value


def _urdf_float(node: Node, attribute: str, owner: str, loc: _Locator, default: float) -> float:
    value = _urdf_number(node, attribute, owner, loc)
    return default if value is None else value


def _urdf_joints(robot: Node, loc: _Locator) -> dict[str, UrdfJoint]:
    links = _links(robot, loc)
    joints: dict[str, UrdfJoint] = {}
    children: set[str] = set()
    for node in robot.find_all("joint"):
        name = _required(node, "name", loc)
        if name in joints:
            raise loc.error(f"joint {name!r} is not unique in the URDF", node)
        jtype = _required(node, "type", loc, f" of joint {name!r}")
        if jtype not in _URDF_JOINT_TYPES:
            raise loc.error(f"joint {name!r} has no known type {jtype!r} (expected one of "
                            f"{', '.join(_URDF_JOINT_TYPES)})", node)
        for end in ("parent", "child"):
            link = _joint_link(node, end, name, links, loc)
            if end == "child":
                children.add(link)
        joints[name] = UrdfJoint(name, jtype, _urdf_limit(node, name, jtype, loc),
                                 _urdf_mimic(node, name, loc), _urdf_safety(node, name, loc))
    _check_tree(robot, links, children, loc)
    return joints


def _links(robot: Node, loc: _Locator) -> set[str]:
    links: set[str] = set()
    for node in robot.find_all("link"):
        name = _required(node, "name", loc)
        if name in links:
            raise loc.error(f"link {name!r} is not unique in the URDF", node)
        links.add(name)
    if not links:
        raise loc.error("no <link> elements found in the URDF: ros2_control cannot build the "
                        "robot model (failed to parse URDF)", robot)
    return links


def _joint_link(node: Node, end: str, joint: str, links: set[str], loc: _Locator) -> str:
    element = node.find(end)
    link = element.attrib.get("link") if element is not None else None
    if not link:
        raise loc.error(f"joint {joint!r} has no <{end} link=…>", node)
    if link not in links:
        raise loc.error(f"{end} link {link!r} of joint {joint!r} not found in the URDF", node)
    return link


def _check_tree(robot: Node, links: set[str], children: set[str], loc: _Locator) -> None:
    roots = sorted(links - children)
    if not roots:
        raise loc.error("no root link found: the links of the URDF do not form a tree", robot)
    if len(roots) > 1:
        raise loc.error(f"two root links found: [{roots[0]}] and [{roots[1]}]; the links of the "
                        "URDF must form one tree", robot)


def _urdf_limit(node: Node, name: str, jtype: str, loc: _Locator) -> Limits | None:
    """``<limit>`` as urdfdom reads it (lower/upper default to 0; effort and velocity it
    requires, deltoctl only warns: its own exporter leaves out what a profile does not know) and
    ``getJointLimits`` turns it into limits (positions only for revolute and prismatic joints,
    |velocity| and |effort|)."""
    limit = node.find("limit")
    if limit is None:
        if jtype in ("revolute", "prismatic"):
            raise loc.error(f"joint {name!r} is {jtype} but has no <limit> (urdfdom: joint of type "
                            f"{jtype.upper()} does not specify limits)", node)
        return None
    for attribute in ("effort", "velocity"):
        if attribute not in limit.attrib:
            loc.warn(f"the <limit> of joint {name!r} has no {attribute} attribute: urdfdom, "
                     "and so ros2_control, rejects such a URDF", limit)
    lower = _urdf_float(limit, "lower", name, loc, 0.0)
    upper = _urdf_float(limit, "upper", name, loc, 0.0)
    velocity = _urdf_number(limit, "velocity", name, loc)
    effort = _urdf_number(limit, "effort", name, loc)
    for attribute, value in (("velocity", velocity), ("effort", effort)):
        if value is not None and value < 0:
            loc.warn(f"the {attribute} limit of joint {name!r} is negative ({value:g}): "
                     "ros2_control takes its size", limit)
    positional = jtype in ("revolute", "prismatic")
    return Limits(
        lower=lower if positional else None,
        upper=upper if positional else None,
        velocity=None if velocity is None else abs(velocity),
        effort=None if effort is None else abs(effort),
    )


def _urdf_safety(node: Node, name: str, loc: _Locator) -> SoftLimits | None:
    safety = node.find("safety_controller")
    if safety is None:
        return None
    if "k_velocity" not in safety.attrib:
        raise loc.error(f"the <safety_controller> of joint {name!r} has no k_velocity "
                        "(urdfdom: joint safety: no k_velocity)", safety)
    return SoftLimits(  # urdfdom's defaults: 0
        lower=_urdf_float(safety, "soft_lower_limit", name, loc, 0.0),
        upper=_urdf_float(safety, "soft_upper_limit", name, loc, 0.0),
        k_position=_urdf_float(safety, "k_position", name, loc, 0.0),
        k_velocity=_urdf_float(safety, "k_velocity", name, loc, 0.0),
    )


def _urdf_mimic(node: Node, name: str, loc: _Locator) -> Mimic | None:
    mimic = node.find("mimic")
    if mimic is None:
        return None
    target = mimic.attrib.get("joint", "").strip()
    if not target:
        raise loc.error(f"the <mimic> of joint {name!r} names no joint", mimic)
    return Mimic(
        joint=target,
        multiplier=_urdf_float(mimic, "multiplier", name, loc, 1.0),
        offset=_urdf_float(mimic, "offset", name, loc, 0.0),
    )


def _sdf_joints(model: Node, loc: _Locator) -> dict[str, UrdfJoint]:
    """The joints of an SDF ``<model>``, as sdformat_urdf hands them to ros2_control."""
    if not model.find_all("link"):
        raise loc.error("no <link> elements found in the SDF model", model)
    joints: dict[str, UrdfJoint] = {}
    for node in model.find_all("joint"):
        name = _required(node, "name", loc)
        jtype = _required(node, "type", loc, f" of joint {name!r}")
        limits = None
        axis = node.find("axis")
        axis_limit = axis.find("limit") if axis is not None else None
        if jtype in ("revolute", "prismatic") and axis_limit is not None:
            limits = Limits(
                lower=_sdf_value(axis_limit, "lower", name, loc),
                upper=_sdf_value(axis_limit, "upper", name, loc),
                velocity=_sdf_value(axis_limit, "velocity", name, loc, magnitude=True),
                effort=_sdf_value(axis_limit, "effort", name, loc, magnitude=True),
            )
        joints[name] = UrdfJoint(name, jtype, limits, None)
    return joints


def _sdf_value(limit: Node, tag: str, joint: str, loc: _Locator,
               magnitude: bool = False) -> float | None:
    """An SDF limit; infinite (and, for velocity and effort, negative) means none."""
    element = limit.find(tag)
    if element is None or not element.text.strip():
        return None
    text = element.text.strip()
    try:
        value = float(text)
    except ValueError:
        raise loc.error(f"<{tag}> of joint {joint!r} must be a number, got {text!r}",
                        element) from None
    if math.isnan(value):
        raise loc.error(f"<{tag}> of joint {joint!r} must be a number, got {text!r}", element)
    if math.isinf(value) or abs(value) >= 1e16 or (magnitude and value < 0):
        return None
    return value


# -- the <ros2_control> blocks -----------------------------------------------------------------

def _params(node: Node, loc: _Locator, owner: str) -> dict[str, str]:
    params: dict[str, str] = {}
    for p in node.find_all("param"):
        name = p.attrib.get("name")
        if name is None:
            raise loc.error(f"no parameter name attribute set in a <param> tag for {owner!r}", p)
        params[name.strip()] = p.text.strip()
    return params


def _warn_unknown(node: Node, known: set[str], what: str, loc: _Locator) -> None:
    for child in node.children:
        if child.tag not in known:
            loc.warn(f"ros2_control ignores <{child.tag}> in {what} (expected one of: "
                     f"{', '.join(sorted(known))})", child)


def _hardware(block: Node, loc: _Locator) -> Hardware:
    name = _required(block, "name", loc)
    if "type" not in block.attrib:
        raise loc.error(f"<ros2_control name={name!r}> needs a type attribute "
                        "(system, actuator or sensor): no attribute 'type' in the tag", block)
    hw = Hardware(name=name, type=block.attrib["type"].strip(), line=block.line,
                  attributes={k: v for k, v in block.attrib.items() if k not in ("name", "type")})
    errors, warnings = block_attribute_problems(hw.attributes)
    if errors:
        raise loc.error(f"<ros2_control name={name!r}>: {errors[0]}", block)
    for message in warnings:
        loc.warn(f"<ros2_control name={name!r}>: {message}", block)
    params: dict[str, str] = {}
    has_hardware = False
    for child in block.children:
        if child.tag == "hardware":
            has_hardware = True
            params.update(_hardware_tag(hw, child, loc))
        elif child.tag == "properties":
            _properties(hw, child, loc)
        elif child.tag in ("joint", "sensor", "gpio"):
            getattr(hw, child.tag + "s").append(_component(child, loc))
        elif child.tag == "transmission":
            hw.transmissions.append(_transmission(child, loc))
        else:
            raise loc.error(f"invalid tag name <{child.tag}> in <ros2_control name={name!r}> "
                            f"(expected one of: {', '.join(sorted(_ROS2_CONTROL_CHILDREN))})",
                            child)
    if not has_hardware:
        loc.warn(f"<ros2_control name={name!r}> has no <hardware>: ros2_control reads the "
                 "block, but no plugin can be loaded for it", block)
    hw.family = params.pop(PREFIX + "family", None)
    hw.bus = params.pop(PREFIX + "bus", None)
    hw.params = params
    _fill_transmissions(hw, block, loc)
    hw.line = None if loc.expanded else block.line
    return hw


def _hardware_tag(hw: Hardware, node: Node, loc: _Locator) -> dict[str, str]:
    _warn_unknown(node, _HARDWARE_CHILDREN, f"the <hardware> of {hw.name!r}", loc)
    plugin = node.find("plugin")
    if plugin is None:
        raise loc.error(f"missing <plugin> tag of <hardware> element for {hw.name!r}", node)
    hw.plugin = plugin.text.strip()
    if not hw.plugin:
        loc.warn(f"the <plugin> of the <hardware> of {hw.name!r} is empty: no plugin can be "
                 "loaded for it", plugin)
    group = node.find("group")
    if group is not None:
        hw.group = group.text.strip()
    return _params(node, loc, hw.name)


def _properties(hw: Hardware, node: Node, loc: _Locator) -> None:
    async_node = node.find("async")
    if async_node is None:
        return
    hw.async_properties = {k: v.strip() for k, v in async_node.attrib.items()}
    problems = async_property_problems(hw.async_properties)
    if problems:
        raise loc.error(f"error parsing the <async> tag of {hw.name!r}: {problems[0]}",
                        async_node)


def _component(node: Node, loc: _Locator) -> Component:
    kind = node.tag
    name = _required(node, "name", loc)
    comp = Component(kind=kind, name=name, line=None if loc.expanded else node.line)
    _warn_unknown(node, _COMPONENT_CHILDREN, f"<{kind} name={name!r}>", loc)
    limits = node.find("limits")
    if limits is not None and kind != "gpio":
        comp.enable_limits = _bool_attr(limits, "enable", loc, f" of {kind} {name!r}")
    for tag, attr in (("command_interface", "command_interfaces"),
                      ("state_interface", "state_interfaces")):
        for inode in node.find_all(tag):
            getattr(comp, attr).append(_interface(inode, kind, name, loc))
    params = _params(node, loc, name)
    comp.bus = params.pop(PREFIX + "bus", None)
    address = params.pop(PREFIX + "address", None)
    if address is not None:
        try:
            comp.address = int(address, 0)
        except ValueError:
            raise loc.error(f"deltoctl.address of {name!r} must be a whole number, "
                            f"got {address!r}", node) from None
    comp.inverse = params.pop(PREFIX + "inverse", "false").lower() == "true"
    comp.offset = _float(params.pop(PREFIX + "offset", None), "deltoctl.offset", node, loc) or 0.0
    if kind == "joint":  # joined with the URDF's <limit> in _join_urdf
        comp.limits = _extra_limits(params, name, node, loc)
    comp.params = params
    return comp


def _extra_limits(params: dict[str, str], joint: str, node: Node,
                  loc: _Locator) -> Limits | None:
    """The limits deltoctl's exporter writes as params because neither the URDF ``<limit>``
    nor the interfaces hold them (an acceleration limit, a continuous joint's position range
    in deltoctl's YAML form); ``None`` when there are none."""
    limits = Limits()
    for key in [f.name for f in fields(Limits)]:
        text = params.pop(LIMITS_PREFIX + key, None)
        if text is None:
            continue
        value = parse_number(text)
        if value is None:
            raise loc.error(f"{LIMITS_PREFIX}{key} of joint {joint!r} must be a finite number, "
                            f"got {text!r}", node)
        setattr(limits, key, value)
    return None if limits == Limits() else limits


def _interface(node: Node, kind: str, owner: str, loc: _Locator) -> Interface:
    name = node.attrib.get("name")
    if name is None:
        raise loc.error(f"no attribute 'name' in the <{node.tag}> of {kind} {owner!r}", node)
    name = name.strip()
    what = f"{owner}/{name}"
    _warn_unknown(node, _INTERFACE_CHILDREN, f"interface {what}", loc)
    params = _params(node, loc, owner)
    itf = Interface(name=name, line=None if loc.expanded else node.line)
    itf.min, itf.max = _min_max(params, what, node, loc)
    itf.initial_value = params.pop("initial_value", None)
    limits = node.find("limits")
    if limits is not None:
        itf.enable_limits = _bool_attr(limits, "enable", loc, f" of interface {what}")
    data_type = node.attrib.get("data_type")
    itf.data_type = None if data_type is None else data_type.strip()
    size = node.attrib.get("size")
    if size is not None:
        if not _SIZE.fullmatch(size.strip()):
            raise loc.error(f"could not parse the size of {what}: got {size.strip()!r}, but "
                            "expected a non-zero positive integer", node)
        itf.size = int(size.strip())
    itf.params = params
    return itf


def _min_max(params: dict[str, str], what: str, node: Node,
             loc: _Locator) -> tuple[float | None, float | None]:
    """The interface's ``min`` and ``max``. ros2_control skips a pair it cannot read (with a
    message) and so does deltoctl, keeping the text as params; ``inf`` and ``nan`` are refused
    outright, since they would switch a limit off."""
    texts = {key: params.get(key, "") for key in ("min", "max")}
    values = {key: parse_number(text) for key, text in texts.items()}
    for key, text in texts.items():
        if text and values[key] is None and _is_non_finite(text):
            raise loc.error(f"{key} of {what} must be a finite number, got {text!r}", node)
    if any(text and values[key] is None for key, text in texts.items()):
        loc.warn(f"min/max of {what} ({texts['min']!r}, {texts['max']!r}) is not a pair of "
                 "numbers: ros2_control skips it, and so no limit comes from it", node)
        return None, None
    for key in texts:
        params.pop(key, None)
    return values["min"], values["max"]


def _is_non_finite(text: str) -> bool:
    try:
        return not math.isfinite(float(text))
    except ValueError:
        return False


# -- transmissions ------------------------------------------------------------------------------

def _transmission(node: Node, loc: _Locator) -> Transmission:
    name = _required(node, "name", loc)
    plugin = node.find("plugin")
    if plugin is None:
        raise loc.error(f"missing <plugin> tag of <transmission> element for {name!r}", node)
    transmission = Transmission(name=name, type=plugin.text.strip(),
                                params=_params(node, loc, name),
                                line=None if loc.expanded else node.line)
    transmission.joints = [_transmission_end(n, name, loc) for n in node.find_all("joint")]
    transmission.actuators = [_transmission_end(n, name, loc) for n in node.find_all("actuator")]
    return transmission


def _transmission_end(node: Node, transmission: str, loc: _Locator) -> TransmissionEnd:
    context = f" of transmission {transmission!r}"
    end = TransmissionEnd(name=_required(node, "name", loc, context),
                          role=_required(node, "role", loc, context))
    if "read_only" in node.attrib:
        end.read_only = _bool_attr(node, "read_only", loc, context)
    for tag in ("mechanical_reduction", "offset"):
        element = node.find(tag)
        if element is None:
            continue
        value = parse_number(element.text)
        if value is None:  # ros2_control would fall back to the default: a wrong ratio
            raise loc.error(f"{tag} of {node.tag} {end.name!r}{context} must be a finite "
                            f"number, got {element.text.strip()!r}", element)
        setattr(end, tag, value)
    return end


def _fill_transmissions(hw: Hardware, block: Node, loc: _Locator) -> None:
    """What ros2_control fills in (model.fill_transmission), each problem at its tag."""
    for transmission, node in zip(hw.transmissions, block.find_all("transmission")):
        try:
            fill_transmission(hw, transmission)
        except ValueError as exc:
            raise loc.error(str(exc), node) from None


# -- a block's joint against the robot model ----------------------------------------------------

def _join_urdf(hw: Hardware, comp: Component, node: Node, urdf_joints: dict[str, UrdfJoint],
               loc: _Locator) -> None:
    urdf = urdf_joints.get(comp.name)
    if urdf is None:
        raise loc.error(f"joint {comp.name!r} not found in the URDF (a <ros2_control> joint "
                        "must name a URDF <joint>)", node)
    comp.joint_type = urdf.type
    mimic_attr = None
    if "mimic" in node.attrib:
        mimic_attr = _bool_attr(node, "mimic", loc, f" {comp.name!r}")
    if mimic_attr is True and urdf.mimic is None:
        raise loc.error(f"joint {comp.name!r} has mimic=\"true\" but no mimic information in "
                        "the URDF (no <mimic> in its <joint>)", node)
    if urdf.mimic is not None and mimic_attr is not False:
        if comp.command_interfaces:
            raise loc.error(f"joint {comp.name!r} mimics {urdf.mimic.joint!r} and so cannot "
                            "have command interfaces (activated mimic joints cannot have command "
                            "interfaces; mimic=\"false\" turns mimicking off)", node)
        if all(j.name != urdf.mimic.joint for j in hw.joints):
            raise loc.error(f"mimic joint {urdf.mimic.joint!r} (mimicked by {comp.name!r}) not "
                            f"found in <ros2_control name={hw.name!r}> tag", node)
        comp.mimic = urdf.mimic
    if urdf.type == "fixed":
        raise loc.error(f"joint {comp.name!r} is fixed in the URDF (type 'fixed'): fixed joints "
                        "do not make sense in ros2_control", node)
    _warn_unread_limits(comp, node, loc)
    comp.limits = merge_interface_limits(_with_extras(urdf.limits, comp.limits), comp)
    if urdf.soft_limits is not None:
        comp.soft_limits = clamp_soft_limits(urdf.soft_limits, comp.limits)


def _with_extras(urdf: Limits | None, extras: Limits | None) -> Limits | None:
    if extras is None:
        return urdf
    given = {k: v for k, v in vars(extras).items() if v is not None}
    return replace(urdf or Limits(), **given)


def _warn_unread_limits(comp: Component, node: Node, loc: _Locator) -> None:
    if not comp.enable_limits:
        return  # ros2_control reads none of them
    for itf in comp.command_interfaces:
        if itf.min is None and itf.max is None:
            continue
        if itf.name not in _LIMIT_KINDS:
            loc.warn(f"ros2_control reads no joint limit from the min/max of {comp.name}/"
                     f"{itf.name} (only from {', '.join(_LIMIT_KINDS)})", node)
        elif itf.name == "jerk" and itf.min is not None:
            loc.warn(f"the min of {comp.name}/jerk is ignored: jerk takes only a max", node)


def _safety(params: dict[str, str], loc: _Locator) -> Safety:
    safety = Safety()
    for key in list(params):
        if not key.startswith("safety."):
            continue
        value = params.pop(key)
        field = key[len("safety."):]
        node = None
        if field.startswith("home_pose."):
            safety.home_pose[field[len("home_pose."):]] = _float(value, key, node, loc) or 0.0
        elif field == "homing_order":
            safety.homing_order = [j.strip() for j in value.split(",") if j.strip()]
        elif field in ("max_jog_step", "current_cap", "home_tolerance", "home_timeout"):
            setattr(safety, field, _float(value, key, node, loc))
        else:
            raise loc.error(f"unknown deltoctl param {PROFILE_PREFIX}{key}", None)
    return safety


def _import_endpoint(profile: Profile, hw: Hardware) -> None:
    """A third-party block that names its device by params (host, port) gets a bus."""
    family = registry.get(profile.family_of(hw))
    if hw.bus is not None or family is None or family.endpoint_params is None:
        return
    host_param, port_param, default_port = family.endpoint_params
    ip = hw.params.get(host_param)
    if not ip:
        return
    port = hw.params.get(port_param, str(default_port))
    bus = "gripper" if "gripper" not in profile.buses else f"{hw.name}-gripper"
    profile.buses[bus] = f"{family.schemes[0]}://{ip}:{port}"
    hw.bus = bus
