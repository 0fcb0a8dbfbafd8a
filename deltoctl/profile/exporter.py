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

from deltoctl.profile.model import Component, Hardware, Interface, Profile
from deltoctl.profile.urdf_loader import PREFIX, PROFILE_PREFIX
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
    if not params:
        return [f"{indent}<{tag}{attrs}/>"]
    return [f"{indent}<{tag}{attrs}>",
            *_param_lines(params, indent + "  "), f"{indent}</{tag}>"]


def _component_xml(comp: Component, indent: str) -> list[str]:
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
    lines += _param_lines(params, indent + "  ")
    lines.append(f"{indent}</{comp.kind}>")
    return lines


def _block_xml(hw: Hardware, extra: dict[str, str], indent: str) -> list[str]:
    attrs = "".join(f" {k}={quoteattr(v)}" for k, v in hw.attributes.items())
    params = dict(hw.params)
    if hw.family is not None:
        params[PREFIX + "family"] = hw.family
    if hw.bus is not None:
        params[PREFIX + "bus"] = hw.bus
    params.update(extra)
    lines = [f"{indent}<ros2_control name={quoteattr(hw.name)} type={quoteattr(hw.type)}{attrs}>",
             f"{indent}  <hardware>",
             f"{indent}    <plugin>{escape(hw.plugin)}</plugin>",
             *([f"{indent}    <group>{escape(hw.group)}</group>"] if hw.group else []),
             *_param_lines(params, indent + "    "),
             f"{indent}  </hardware>"]
    for comp in hw.components():
        lines += _component_xml(comp, indent + "  ")
    lines.append(f"{indent}</ros2_control>")
    return lines


def _kinematics_xml(profile: Profile, indent: str) -> list[str]:
    """A star of links around base_link: enough URDF for the limits and mimic joints."""
    lines = [f'{indent}<link name="base_link"/>']
    for joint in profile.joints():
        child = f"{joint.name}_link"
        lines.append(f"{indent}<link name={quoteattr(child)}/>")
        lines.append(f"{indent}<joint name={quoteattr(joint.name)} "
                     f"type={quoteattr(joint.joint_type)}>")
        lines.append(f'{indent}  <parent link="base_link"/>')
        lines.append(f"{indent}  <child link={quoteattr(child)}/>")
        lim = joint.limits
        if lim is not None:
            attrs = "".join(f" {k}={quoteattr(format_number(getattr(lim, k)))}"
                            for k in ("lower", "upper", "velocity", "effort")
                            if getattr(lim, k) is not None)
            lines.append(f"{indent}  <limit{attrs}/>")
        if joint.mimic is not None:
            m = joint.mimic
            lines.append(f"{indent}  <mimic joint={quoteattr(m.joint)} "
                         f'multiplier="{format_number(m.multiplier)}" '
                         f'offset="{format_number(m.offset)}"/>')
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
    if macro:
        profile = _escaped(profile)
    blocks: list[str] = []
    for index, hw in enumerate(profile.hardware):
        extra = _profile_params(profile) if index == 0 else {}
        blocks += _block_xml(hw, extra, "    " if macro else "  ")
    if macro:
        body = ['<robot xmlns:xacro="http://www.ros.org/wiki/xacro">',
                f"  <xacro:macro name={quoteattr(macro_name)} params=\"\">",
                *blocks, "  </xacro:macro>", "</robot>"]
    else:
        body = [f"<robot name={quoteattr(profile.name)}>",
                *_kinematics_xml(profile, "  "), *blocks, "</robot>"]
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
    return itf.name if len(data) == 1 else data


def component_data(comp: Component) -> dict[str, Any]:
    data: dict[str, Any] = {"name": comp.name}
    if comp.kind == "joint" and comp.joint_type != "revolute":
        data["type"] = comp.joint_type
    if comp.limits is not None:
        data["limits"] = {k: v for k, v in vars(comp.limits).items() if v is not None}
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
    blocks = []
    for hw in profile.hardware:
        block: dict[str, Any] = {"name": hw.name, "type": hw.type, "plugin": hw.plugin}
        for key in ("group", "family", "bus"):
            if getattr(hw, key) is not None:
                block[key] = getattr(hw, key)
        if hw.attributes:
            block["attributes"] = dict(hw.attributes)
        if hw.params:
            block["params"] = dict(hw.params)
        for key in ("joints", "sensors", "gpios"):
            comps = getattr(hw, key)
            if comps:
                block[key] = [component_data(c) for c in comps]
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
