"""Load the ``<ros2_control>`` blocks of a URDF or xacro file into the model.

Follows ros2_control's component_parser: ``<robot>`` root, at least one ``<ros2_control>``,
only known tags, a ``<plugin>`` in every ``<hardware>``, every joint present in the URDF and
not fixed, no command interfaces on mimic joints; the URDF ``<limit>`` and
``<safety_controller>`` merged in with the stricter value winning. deltoctl's own fields travel
as ``<param name="deltoctl.…">`` entries, so an exported profile loads back unchanged.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from deltoctl.errors import ProfileError
from deltoctl import registry
from deltoctl.profile.model import (
    Component,
    Hardware,
    Interface,
    Limits,
    Mimic,
    Profile,
    Safety,
)
from deltoctl.profile.xmltree import Node, XMLSyntaxError, parse_xml

PREFIX = "deltoctl."
PROFILE_PREFIX = "deltoctl.profile."

_ROS2_CONTROL_CHILDREN = {"hardware", "properties", "joint", "sensor", "gpio", "transmission"}
_HARDWARE_CHILDREN = {"plugin", "param", "group"}
_COMPONENT_CHILDREN = {"command_interface", "state_interface", "param", "limits"}
_INTERFACE_SPECIAL = {"min", "max", "initial_value", "data_type", "size"}


@dataclass
class UrdfJoint:
    name: str
    type: str
    limits: Limits | None
    mimic: Mimic | None


class _Locator:
    """Maps an element to the best ``file:line`` a person can open."""

    def __init__(self, source: str, expanded: bool, files: list[str]) -> None:
        self.source = source
        self.expanded = expanded
        self.texts: list[tuple[str, list[str]]] = []
        if expanded:
            for f in [source, *files]:
                try:
                    self.texts.append((f, Path(f).read_text(encoding="utf-8").splitlines()))
                except (OSError, UnicodeDecodeError):
                    continue

    def error(self, message: str, node: Node | None) -> ProfileError:
        if node is None:
            return ProfileError(message, self.source)
        if not self.expanded:
            return ProfileError(message, self.source, node.line)
        name = node.attrib.get("name")
        if name:
            needle = f'name="{name}"'
            for f, lines in self.texts:
                for number, text in enumerate(lines, 1):
                    if f"<{node.tag}" in text and needle in text:
                        return ProfileError(message, f, number)
        return ProfileError(f"{message} (line {node.line} of the xacro output)", self.source)


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
    try:
        root = parse_xml(text)
    except XMLSyntaxError as exc:
        raise ProfileError(f"not well-formed XML: {exc}", source, exc.line) from None
    return profile_from_urdf(root, _Locator(source, expanded, files), path)


def profile_from_urdf(root: Node, loc: _Locator, path: Path) -> Profile:
    if root.tag != "robot":
        raise loc.error(f"the root element must be <robot>, not <{root.tag}>", root)
    urdf_joints = _urdf_joints(root, loc)
    blocks = root.find_all("ros2_control")
    if not blocks:
        raise loc.error(
            f"no <ros2_control> block in this URDF ({len(urdf_joints)} joints found); "
            "deltoctl needs the block that names the hardware plugin and interfaces", None)
    hardware = [_hardware(b, urdf_joints, loc) for b in blocks]

    first = hardware[0].params
    profile_params = {k[len(PROFILE_PREFIX):]: first.pop(k)
                      for k in list(first) if k.startswith(PROFILE_PREFIX)}
    name = profile_params.pop("name", None) or root.attrib.get("name") or hardware[0].name
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
    return profile


def _slug(name: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", name.lower()).strip("-") or "profile"


def _float(value: str | None, what: str, node: Node, loc: _Locator) -> float | None:
    if value is None or value.strip() == "":
        return None
    try:
        return float(value)
    except ValueError:
        raise loc.error(f"{what} must be a number, got {value!r}", node) from None


def _stricter(a: float | None, b: float | None, pick) -> float | None:  # type: ignore[no-untyped-def]
    if a is None:
        return b
    if b is None:
        return a
    return pick(a, b)


def _urdf_joints(root: Node, loc: _Locator) -> dict[str, UrdfJoint]:
    joints: dict[str, UrdfJoint] = {}
    for node in root.find_all("joint"):
        name = node.attrib.get("name", "")
        jtype = node.attrib.get("type", "")
        limits = None
        limit = node.find("limit")
        if limit is not None and jtype != "fixed":
            limits = Limits(
                lower=_float(limit.attrib.get("lower"), f"lower limit of {name}", limit, loc),
                upper=_float(limit.attrib.get("upper"), f"upper limit of {name}", limit, loc),
                velocity=_float(limit.attrib.get("velocity"), f"velocity limit of {name}",
                                limit, loc),
                effort=_float(limit.attrib.get("effort"), f"effort limit of {name}", limit, loc),
            )
            if jtype == "continuous":
                limits.lower = limits.upper = None
        safety = node.find("safety_controller")
        if safety is not None and limits is not None and jtype != "continuous":
            soft_lo = _float(safety.attrib.get("soft_lower_limit"), "soft_lower_limit",
                             safety, loc)
            soft_hi = _float(safety.attrib.get("soft_upper_limit"), "soft_upper_limit",
                             safety, loc)
            limits.lower = _stricter(limits.lower, soft_lo, max)
            limits.upper = _stricter(limits.upper, soft_hi, min)
        mimic = None
        mnode = node.find("mimic")
        if mnode is not None:
            mimic = Mimic(
                joint=mnode.attrib.get("joint", ""),
                multiplier=_float(mnode.attrib.get("multiplier"), "mimic multiplier",
                                  mnode, loc) or 1.0,
                offset=_float(mnode.attrib.get("offset"), "mimic offset", mnode, loc) or 0.0,
            )
        joints[name] = UrdfJoint(name, jtype, limits, mimic)
    return joints


def _params(node: Node, loc: _Locator) -> dict[str, str]:
    params: dict[str, str] = {}
    for p in node.find_all("param"):
        name = p.attrib.get("name")
        if not name:
            raise loc.error("a <param> has no name attribute", p)
        params[name] = p.text.strip()
    return params


def _hardware(block: Node, urdf_joints: dict[str, UrdfJoint], loc: _Locator) -> Hardware:
    name = block.attrib.get("name")
    if not name:
        raise loc.error("<ros2_control> needs a name attribute", block)
    if "type" not in block.attrib:
        raise loc.error(f"<ros2_control name={name!r}> needs a type attribute "
                        "(system, actuator or sensor)", block)
    for child in block.children:
        if child.tag not in _ROS2_CONTROL_CHILDREN:
            raise loc.error(f"invalid tag name <{child.tag}> in <ros2_control name={name!r}> "
                            f"(expected one of: {', '.join(sorted(_ROS2_CONTROL_CHILDREN))})",
                            child)
    hw_node = block.find("hardware")
    if hw_node is None:
        raise loc.error(f"<ros2_control name={name!r}> has no <hardware> element", block)
    for child in hw_node.children:
        if child.tag not in _HARDWARE_CHILDREN:
            raise loc.error(f"invalid tag name <{child.tag}> in <hardware> of {name!r} "
                            f"(expected one of: {', '.join(sorted(_HARDWARE_CHILDREN))})", child)
    plugin = hw_node.find("plugin")
    if plugin is None or not plugin.text.strip():
        raise loc.error(f"missing <plugin> tag of <hardware> element for {name!r}", hw_node)
    params = _params(hw_node, loc)
    hw = Hardware(
        name=name,
        type=block.attrib["type"],
        plugin=plugin.text.strip(),
        attributes={k: v for k, v in block.attrib.items() if k not in ("name", "type")},
        line=block.line,
    )
    group = hw_node.find("group")
    hw.group = group.text.strip() if group is not None else None
    hw.family = params.pop(PREFIX + "family", None)
    hw.bus = params.pop(PREFIX + "bus", None)
    hw.params = params
    for child in block.children:
        if child.tag in ("joint", "sensor", "gpio"):
            comp = _component(child, loc)
            getattr(hw, child.tag + "s").append(comp)
            if child.tag == "joint":
                _join_urdf(comp, child, urdf_joints, loc)
    hw.line = None if loc.expanded else block.line
    return hw


def _component(node: Node, loc: _Locator) -> Component:
    name = node.attrib.get("name")
    if not name:
        raise loc.error(f"<{node.tag}> needs a name attribute", node)
    for child in node.children:
        if child.tag not in _COMPONENT_CHILDREN:
            raise loc.error(f"invalid tag name <{child.tag}> in <{node.tag} name={name!r}> "
                            f"(expected one of: {', '.join(sorted(_COMPONENT_CHILDREN))})", child)
    comp = Component(kind=node.tag, name=name, line=None if loc.expanded else node.line)
    params = _params(node, loc)
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
    comp.params = params
    for tag, attr in (("command_interface", "command_interfaces"),
                      ("state_interface", "state_interfaces")):
        for inode in node.find_all(tag):
            getattr(comp, attr).append(_interface(inode, name, loc))
    return comp


def _interface(node: Node, owner: str, loc: _Locator) -> Interface:
    name = node.attrib.get("name", "")
    if not name:
        raise loc.error(f"an interface of {owner!r} has no name attribute", node)
    for child in node.children:
        if child.tag != "param":
            raise loc.error(f"invalid tag name <{child.tag}> in interface {owner}/{name} "
                            "(expected <param>)", child)
    params = _params(node, loc)
    what = f"{owner}/{name}"
    size = params.pop("size", None) or node.attrib.get("size")
    data_type = params.pop("data_type", None) or node.attrib.get("data_type")
    try:
        size_value = int(size) if size is not None else None
    except ValueError:
        raise loc.error(f"size of {what} must be a whole number, got {size!r}", node) from None
    return Interface(
        name=name,
        min=_float(params.pop("min", None), f"min of {what}", node, loc),
        max=_float(params.pop("max", None), f"max of {what}", node, loc),
        initial_value=params.pop("initial_value", None),
        data_type=data_type,
        size=size_value,
        params=params,
        line=None if loc.expanded else node.line,
    )


def _join_urdf(comp: Component, node: Node, urdf_joints: dict[str, UrdfJoint],
               loc: _Locator) -> None:
    urdf = urdf_joints.get(comp.name)
    if urdf is None:
        raise loc.error(f"joint {comp.name!r} not found in the URDF (a <ros2_control> joint "
                        "must name a URDF <joint>)", node)
    comp.joint_type = urdf.type
    if urdf.type == "fixed" and (comp.command_interfaces or comp.state_interfaces):
        raise loc.error(f"joint {comp.name!r} is fixed in the URDF and cannot have "
                        "interfaces", node)
    mimic_attr = node.attrib.get("mimic")
    if mimic_attr == "true" and urdf.mimic is None:
        raise loc.error(f"joint {comp.name!r} has mimic=\"true\" but no <mimic> in the URDF", node)
    if mimic_attr != "false" and urdf.mimic is not None:
        comp.mimic = urdf.mimic
    comp.limits = urdf.limits


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
