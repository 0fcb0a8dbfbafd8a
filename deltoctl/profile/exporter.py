"""Write a profile back out: a URDF (or xacro macro) with its ``<ros2_control>`` blocks, or YAML.

deltoctl's own fields become ``<param name="deltoctl.…">`` entries that ros2_control plugins
ignore, so the exported file both loads in ros2_control and reads back into an equal profile.
In a xacro macro every text is escaped, so that xacro gives it back as it was and evaluates
none of it: a param ``${…}`` or ``$(…)`` stays text.
"""

from __future__ import annotations

import dataclasses
import re
from typing import Any
from xml.sax.saxutils import escape, quoteattr

from deltoctl.errors import ProfileError
from deltoctl.profile.model import (
    Component,
    Hardware,
    Interface,
    Limits,
    Profile,
    Transmission,
    TransmissionEnd,
    merge_interface_limits,
)
from deltoctl.profile.urdf_loader import LIMITS_PREFIX, PREFIX, PROFILE_PREFIX
from deltoctl.units import format_number


def _profile_params(profile: Profile) -> dict[str, str]:
    params: dict[str, str] = {"name": profile.name}
    if profile.description:
        params["description"] = profile.description
    if profile.family:
        params["family"] = profile.family
    if profile.model:
        params["model"] = profile.model
    if profile.status != "current":
        params["status"] = profile.status
    for bus, url in profile.buses.items():
        params[f"buses.{bus}"] = url
    s = profile.safety
    for joint, value in s.home_pose.items():
        params[f"safety.home_pose.{joint}"] = format_number(value)
    for key in ("max_jog_step", "current_cap", "home_tolerance", "home_timeout"):
        value = getattr(s, key)
        if value is not None:
            params[f"safety.{key}"] = format_number(value)
    if s.homing_order:
        params["safety.homing_order"] = ",".join(s.homing_order)
    return {PROFILE_PREFIX + k: v for k, v in params.items()}


def _param_lines(params: dict[str, str], indent: str) -> list[str]:
    return [f"{indent}<param name={quoteattr(k)}>{escape(v)}</param>" for k, v in params.items()]


def _disabled(indent: str) -> str:
    return f'{indent}<limits enable="false"/>'


def _interface_xml(tag: str, itf: Interface, indent: str) -> list[str]:
    params: dict[str, str] = {}
    for key in ("min", "max"):
        value = getattr(itf, key)
        if value is not None:
            params[key] = format_number(value)
    if itf.initial_value is not None:
        params["initial_value"] = itf.initial_value
    params.update(itf.params)
    attrs = f" name={quoteattr(itf.name)}"
    if itf.data_type is not None:
        attrs += f" data_type={quoteattr(itf.data_type)}"
    if itf.size is not None:
        attrs += f' size="{itf.size}"'
    inner = _param_lines(params, indent + "  ")
    if not itf.enable_limits:
        inner.append(_disabled(indent + "  "))
    if not inner:
        return [f"{indent}<{tag}{attrs}/>"]
    return [f"{indent}<{tag}{attrs}>", *inner, f"{indent}</{tag}>"]


def _component_xml(comp: Component, urdf_limits: dict[str, Limits | None],
                   indent: str) -> list[str]:
    attrs = f" name={quoteattr(comp.name)}"
    if comp.mimic is not None:
        attrs += ' mimic="true"'
    lines = [f"{indent}<{comp.kind}{attrs}>"]
    for itf in comp.command_interfaces:
        lines += _interface_xml("command_interface", itf, indent + "  ")
    for itf in comp.state_interfaces:
        lines += _interface_xml("state_interface", itf, indent + "  ")
    params = dict(comp.params)
    if comp.bus is not None:
        params[PREFIX + "bus"] = comp.bus
    if comp.address is not None:
        params[PREFIX + "address"] = str(comp.address)
    if comp.inverse:
        params[PREFIX + "inverse"] = "true"
    if comp.offset:
        params[PREFIX + "offset"] = format_number(comp.offset)
    if comp.kind == "joint":
        params.update(_extra_limit_params(comp, urdf_limits.get(comp.name)))
    lines += _param_lines(params, indent + "  ")
    if not comp.enable_limits and comp.kind != "gpio":
        lines.append(_disabled(indent + "  "))
    lines.append(f"{indent}</{comp.kind}>")
    return lines


def _extra_limit_params(joint: Component, urdf_limit: Limits | None) -> dict[str, str]:
    """The limits neither the URDF ``<limit>`` nor the joint's interfaces give back (an
    acceleration limit, the position range of a continuous joint in deltoctl's YAML form), as
    deltoctl params the URDF loader reads back."""
    if joint.limits is None:
        return {}
    given = merge_interface_limits(urdf_limit, joint) or Limits()
    return {LIMITS_PREFIX + f.name: format_number(getattr(joint.limits, f.name))
            for f in dataclasses.fields(Limits)
            if getattr(joint.limits, f.name) is not None
            and getattr(given, f.name) != getattr(joint.limits, f.name)}


def _transmission_end_xml(tag: str, end: TransmissionEnd, indent: str) -> list[str]:
    attrs = f" name={quoteattr(end.name)} role={quoteattr(end.role)}"
    if end.read_only:
        attrs += ' read_only="true"'
    inner = [f"{indent}  <{key}>{format_number(getattr(end, key))}</{key}>"
             for key, default in (("mechanical_reduction", 1.0), ("offset", 0.0))
             if getattr(end, key) != default]
    if not inner:
        return [f"{indent}<{tag}{attrs}/>"]
    return [f"{indent}<{tag}{attrs}>", *inner, f"{indent}</{tag}>"]


def _transmission_xml(transmission: Transmission, indent: str) -> list[str]:
    lines = [f"{indent}<transmission name={quoteattr(transmission.name)}>",
             f"{indent}  <plugin>{escape(transmission.type)}</plugin>"]
    for end in transmission.joints:
        lines += _transmission_end_xml("joint", end, indent + "  ")
    for end in transmission.actuators:
        if not end.implicit:  # ros2_control adds an actuator block's "actuator1" itself
            lines += _transmission_end_xml("actuator", end, indent + "  ")
    lines += _param_lines(transmission.params, indent + "  ")
    lines.append(f"{indent}</transmission>")
    return lines


def _hardware_xml(hw: Hardware, extra: dict[str, str], indent: str) -> list[str]:
    params = dict(hw.params)
    if hw.family is not None:
        params[PREFIX + "family"] = hw.family
    if hw.bus is not None:
        params[PREFIX + "bus"] = hw.bus
    params.update(extra)
    if not (hw.plugin or hw.group or params):
        return []  # a block without <hardware> stays without one (no empty <plugin>)
    return [f"{indent}<hardware>",
            f"{indent}  <plugin>{escape(hw.plugin)}</plugin>",
            *([f"{indent}  <group>{escape(hw.group)}</group>"] if hw.group else []),
            *_param_lines(params, indent + "  "),
            f"{indent}</hardware>"]


def _block_xml(hw: Hardware, extra: dict[str, str], urdf_limits: dict[str, Limits | None],
               indent: str) -> list[str]:
    attrs = "".join(f" {k}={quoteattr(v)}" for k, v in hw.attributes.items())
    lines = [f"{indent}<ros2_control name={quoteattr(hw.name)} type={quoteattr(hw.type)}{attrs}>",
             *_hardware_xml(hw, extra, indent + "  ")]
    if hw.async_properties:
        props = "".join(f" {k}={quoteattr(v)}" for k, v in hw.async_properties.items())
        lines += [f"{indent}  <properties>", f"{indent}    <async{props}/>",
                  f"{indent}  </properties>"]
    for comp in hw.components():
        lines += _component_xml(comp, urdf_limits, indent + "  ")
    for transmission in hw.transmissions:
        lines += _transmission_xml(transmission, indent + "  ")
    lines.append(f"{indent}</ros2_control>")
    return lines


# -- the robot model: one URDF joint per joint name, its <limit>, <safety_controller>, <mimic> ----

_DERIVATIVES = ("acceleration", "deceleration", "jerk")
_POSITIONAL = ("revolute", "prismatic")


def _urdf_part(limits: Limits | None, joint_type: str) -> Limits | None:
    """What of ``limits`` a URDF ``<limit>`` holds, as ros2_control reads it (no acceleration,
    deceleration, jerk; a position range only on a revolute or prismatic joint)."""
    if limits is None:
        return None
    dropped = _DERIVATIVES if joint_type in _POSITIONAL else (*_DERIVATIVES, "lower", "upper")
    part = dataclasses.replace(limits, **dict.fromkeys(dropped))
    return None if part == Limits() else part


def _urdf_limits(profile: Profile) -> dict[str, Limits | None]:
    """The ``<limit>`` of each URDF joint: the limits of one of the block joints naming it that,
    merged with every such joint's interfaces as ros2_control merges them, gives each block's
    limits back (a joint may sit in an actuator block and a sensor block at once)."""
    occurrences: dict[str, list[Component]] = {}
    for joint in profile.joints():
        occurrences.setdefault(joint.name, []).append(joint)
    chosen: dict[str, Limits | None] = {}
    for name, joints in occurrences.items():
        kind = joints[0].joint_type
        candidates = [_urdf_part(j.limits, kind) for j in joints]
        chosen[name] = next(
            (c for c in candidates
             if all(_urdf_part(merge_interface_limits(c, j), kind) == _urdf_part(j.limits, kind)
                    for j in joints)), candidates[0])
    return chosen


def _unread(joint: Component, kind: str) -> bool:
    """Whether ros2_control reads no ``kind`` limit from the URDF for this joint: its limits,
    or those of its ``kind`` command interface, are switched off (``<limits enable="false"/>``)."""
    itf = joint.command(kind)
    return not joint.enable_limits or (itf is not None and not itf.enable_limits)


def _limit_xml(joint: Component, lim: Limits | None, indent: str,
               source: str | None = None) -> list[str]:
    """The joint's ``<limit>``, holding exactly what the profile holds.

    urdfdom requires a ``<limit>`` on a revolute or prismatic joint, and ``effort`` and
    ``velocity`` on every ``<limit>``; ros2_control reads all four values. No value is made up:
    - a continuous joint without limits gets no ``<limit>``;
    - a value ros2_control does not read (its limit switched off by ``<limits
      enable="false"/>``) is written as 0 (lower and upper: left out, urdfdom's 0);
    - a velocity or effort limit the profile does not give is left out, with a comment: such a
      file loads in deltoctl with a warning, and in ros2_control once the profile gives it;
    - a revolute or prismatic joint without position limits cannot be written at all (a
      missing lower or upper reads as 0, which would lock the joint): refused.
    """
    positional = joint.joint_type in _POSITIONAL
    if lim is None and not positional:
        return []
    lim = lim or Limits()
    attrs: dict[str, str] = {}
    missing: list[str] = []
    for key in ("lower", "upper", "velocity", "effort"):
        value = getattr(lim, key)
        position = key in ("lower", "upper")
        if position and not positional:
            continue
        if value is not None:
            attrs[key] = format_number(value)
        elif _unread(joint, "position" if position else key):
            if not position:
                attrs[key] = "0"
        elif position:
            raise ProfileError(f"cannot be written as URDF: joint {joint.name!r} is "
                               f"{joint.joint_type} without a {key} limit, which a URDF <limit> "
                               "cannot say (a missing bound reads as 0)", source, joint.line)
        else:
            missing.append(key)
    text = "".join(f" {k}={quoteattr(v)}" for k, v in attrs.items())
    lines = [f"{indent}<limit{text}/>"]
    if missing:
        lines.insert(0, f"{indent}<!-- the profile gives no {' or '.join(missing)} limit for "
                        "this joint: ros2_control requires it on <limit> -->")
    return lines


def _kinematics_xml(profile: Profile, indent: str) -> list[str]:
    """A star of links around base_link: enough URDF for the limits, soft limits and mimic
    joints of the blocks (one URDF joint for a joint several blocks name)."""
    urdf_limits = _urdf_limits(profile)
    lines = [f'{indent}<link name="base_link"/>']
    joints: dict[str, list[Component]] = {}
    for joint in profile.joints():
        joints.setdefault(joint.name, []).append(joint)
    for name, same in joints.items():
        joint = same[0]
        child = f"{name}_link"
        lines.append(f"{indent}<link name={quoteattr(child)}/>")
        lines.append(f"{indent}<joint name={quoteattr(name)} "
                     f"type={quoteattr(joint.joint_type)}>")
        lines.append(f'{indent}  <parent link="base_link"/>')
        lines.append(f"{indent}  <child link={quoteattr(child)}/>")
        lines += _limit_xml(joint, urdf_limits[name], indent + "  ", profile.source)
        soft = next((j.soft_limits for j in same if j.soft_limits is not None), None)
        if soft is not None:
            lines.append(f"{indent}  <safety_controller "
                         f'soft_lower_limit="{format_number(soft.lower)}" '
                         f'soft_upper_limit="{format_number(soft.upper)}" '
                         f'k_position="{format_number(soft.k_position)}" '
                         f'k_velocity="{format_number(soft.k_velocity)}"/>')
        mimic = next((j.mimic for j in same if j.mimic is not None), None)
        if mimic is not None:
            lines.append(f"{indent}  <mimic joint={quoteattr(mimic.joint)} "
                         f'multiplier="{format_number(mimic.multiplier)}" '
                         f'offset="{format_number(mimic.offset)}"/>')
        lines.append(f"{indent}</joint>")
    return lines


_DOLLARS = re.compile(r"\$+")


def xacro_literal(text: str) -> str:
    """``text`` spelled so that xacro reads it back unchanged and evaluates none of it."""

    def respell(match: re.Match[str]) -> str:
        run = match.group()
        following = text[match.end():match.end() + 1]
        if following and following in "{(":
            return "$" + run  # xacro reads '$${' as the text '${' (one '$' fewer)
        if len(run) == 1:
            return run  # a lone '$' before anything else is text already
        # xacro's lexer has no spelling for '$$' before other text: a constant expression
        return f"${{'$'*{len(run)}}}"

    return _DOLLARS.sub(respell, text)


def _escaped(value: Any) -> Any:
    """A copy of a profile (or any part of it) with every text escaped for xacro."""
    if type(value) is str:
        return xacro_literal(value)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        changes = {f.name: _escaped(getattr(value, f.name))
                   for f in dataclasses.fields(value) if f.init}
        return dataclasses.replace(value, **changes)
    if type(value) is dict:
        return {_escaped(k): _escaped(v) for k, v in value.items()}
    if type(value) in (list, tuple):
        return type(value)(_escaped(v) for v in value)
    return value


def _comment(text: str) -> str:
    return re.sub("-(?=-)", "- ", text)  # '--' may not appear in an XML comment


def to_urdf(profile: Profile, macro: bool = False) -> str:
    header = ['<?xml version="1.0"?>',
              f"<!-- {_comment(profile.name)}: exported by deltoctl; "
              "'deltoctl.*' params are deltoctl's own and ignored by ros2_control -->"]
    macro_name = profile.name.replace("-", "_") + "_ros2_control"
    kinematics = [] if macro else _kinematics_xml(profile, "  ")
    if macro:
        profile = _escaped(profile)
    urdf_limits = _urdf_limits(profile)
    blocks: list[str] = []
    for index, hw in enumerate(profile.hardware):
        extra = _profile_params(profile) if index == 0 else {}
        if not (hw.plugin or hw.group or hw.params) and list(extra) == [PROFILE_PREFIX + "name"]:
            extra = {}  # nothing but the name, which the robot's name carries
        blocks += _block_xml(hw, extra, urdf_limits, "    " if macro else "  ")
    if macro:
        body = ['<robot xmlns:xacro="http://www.ros.org/wiki/xacro">',
                f"  <xacro:macro name={quoteattr(macro_name)} params=\"\">",
                *blocks, "  </xacro:macro>", "</robot>"]
    else:
        body = [f"<robot name={quoteattr(profile.name)}>", *kinematics, *blocks, "</robot>"]
    return "\n".join(header + body) + "\n"


# -- YAML ------------------------------------------------------------------------------------

def _interface_data(itf: Interface) -> Any:
    data: dict[str, Any] = {"name": itf.name}
    for key in ("min", "max", "initial_value", "data_type", "size"):
        value = getattr(itf, key)
        if value is not None:
            data[key] = value
    if itf.params:
        data["params"] = dict(itf.params)
    if not itf.enable_limits:
        data["enable_limits"] = False
    return itf.name if len(data) == 1 else data


def _transmission_data(transmission: Transmission) -> dict[str, Any]:
    """A transmission as its block declares it: the interface names of its ends, and an actuator
    block's "actuator1", are filled in on loading, as ros2_control does."""
    data: dict[str, Any] = {"name": transmission.name, "type": transmission.type}
    for key, ends in (("joints", transmission.joints), ("actuators", transmission.actuators)):
        declared = [e for e in ends if not e.implicit]
        if declared:
            data[key] = [_end_data(e) for e in declared]
    if transmission.params:
        data["params"] = dict(transmission.params)
    return data


def _end_data(end: TransmissionEnd) -> dict[str, Any]:
    data: dict[str, Any] = {"name": end.name, "role": end.role}
    if end.mechanical_reduction != 1.0:
        data["mechanical_reduction"] = end.mechanical_reduction
    if end.offset:
        data["offset"] = end.offset
    if end.read_only:
        data["read_only"] = True
    return data


def component_data(comp: Component) -> dict[str, Any]:
    data: dict[str, Any] = {"name": comp.name}
    if comp.kind == "joint" and comp.joint_type != "revolute":
        data["type"] = comp.joint_type
    if comp.limits is not None:
        data["limits"] = {k: v for k, v in vars(comp.limits).items() if v is not None}
    if comp.soft_limits is not None:
        data["soft_limits"] = dict(vars(comp.soft_limits))
    if not comp.enable_limits:
        data["enable_limits"] = False
    if comp.mimic is not None:
        data["mimic"] = dict(vars(comp.mimic))
    for key in ("bus", "address"):
        if getattr(comp, key) is not None:
            data[key] = getattr(comp, key)
    if comp.inverse:
        data["inverse"] = True
    if comp.offset:
        data["offset"] = comp.offset
    for key in ("command_interfaces", "state_interfaces"):
        items = getattr(comp, key)
        if items:
            data[key] = _Flow(_interface_data(i) for i in items) \
                if all(not isinstance(_interface_data(i), dict) for i in items) \
                else [_interface_data(i) for i in items]
    if comp.params:
        data["params"] = dict(comp.params)
    return data


class _Flow(list):
    """A list written on one line."""


def profile_data(profile: Profile) -> dict[str, Any]:
    data: dict[str, Any] = {"name": profile.name}
    for key in ("description", "family", "model"):
        if getattr(profile, key):
            data[key] = getattr(profile, key)
    if profile.status != "current":
        data["status"] = profile.status
    if profile.buses:
        data["buses"] = dict(profile.buses)
    safety = {k: v for k, v in vars(profile.safety).items() if v not in (None, {}, [])}
    if safety:
        data["safety"] = safety
    if profile.report:
        data["report"] = dict(profile.report)
    blocks = []
    for hw in profile.hardware:
        block: dict[str, Any] = {"name": hw.name, "type": hw.type, "plugin": hw.plugin}
        for key in ("group", "family", "bus"):
            if getattr(hw, key) is not None:
                block[key] = getattr(hw, key)
        if hw.attributes:
            block["attributes"] = dict(hw.attributes)
        if hw.async_properties:
            block["async_properties"] = dict(hw.async_properties)
        if hw.params:
            block["params"] = dict(hw.params)
        for key in ("joints", "sensors", "gpios"):
            comps = getattr(hw, key)
            if comps:
                block[key] = [component_data(c) for c in comps]
        if hw.transmissions:
            block["transmissions"] = [_transmission_data(t) for t in hw.transmissions]
        blocks.append(block)
    data["ros2_control"] = blocks
    return data


def to_yaml(profile: Profile) -> str:
    import yaml

    class Dumper(yaml.SafeDumper):
        pass

    Dumper.add_representer(
        _Flow, lambda d, v: d.represent_sequence("tag:yaml.org,2002:seq", v, flow_style=True))
    return yaml.dump(profile_data(profile), Dumper=Dumper, sort_keys=False,
                     allow_unicode=True, width=100)
