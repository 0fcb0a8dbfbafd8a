"""Which CANopen node each joint of a block is, and its configuration.

A ``canopen_ros2_control/Cia402System`` block names its bus file in the ``bus_config`` param
(relative to the profile's file); a joint is the node whose ``node_id`` is the joint's
(``<param name="node_id">``, or ``address:`` in YAML) or the node its ``device_name`` param
names. Without a bus file, each joint with a node ID is a node of the plugin's generic EDS,
with ros2_canopen's scaling params read from the joint (or the block).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from deltoctl.errors import ProfileError

from deltoctl_canopen.busconfig import SCALES, BusConfig, NodeConfig

if TYPE_CHECKING:
    from deltoctl.profile.model import Component, Hardware, Profile

PROFILES = Path(__file__).resolve().parent / "profiles"
GENERIC_EDS = PROFILES / "generic-cia402.eds"
HOMING_METHOD = 0x6098


def bus_file(profile: Profile, hw: Hardware) -> Path | None:
    text = hw.params.get("bus_config")
    if not text:
        return None
    path = Path(text.strip().strip('"'))
    if not path.is_absolute() and profile.source:
        path = Path(profile.source).resolve().parent / path
    return path


def load_block_bus(profile: Profile, hw: Hardware) -> BusConfig | None:
    from deltoctl_canopen.busconfig import load_bus

    path = bus_file(profile, hw)
    if path is None:
        return None
    if not path.is_file():
        raise ProfileError(f"{hw.name}: bus_config {path} does not exist", profile.source,
                           hw.line)
    return load_bus(path)


def block_nodes(profile: Profile, hw: Hardware) -> dict[str, NodeConfig]:
    """joint name → its node's configuration (with the EDS to read: the generic one when the
    bus file names none)."""
    bus = load_block_bus(profile, hw)
    found: dict[str, NodeConfig] = {}
    for joint in hw.joints:
        node = _from_bus(profile, hw, joint, bus) if bus else _from_joint(profile, hw, joint)
        if node is not None:
            found[joint.name] = replace(node, dcf=node.dcf or _block_eds(profile, hw))
    return found


def homing_joints(profile: Profile, hw: Hardware) -> list[str]:
    """The joints whose node's start-up writes a homing method (0x6098 in its ``sdo:``
    list): ``home`` runs the drive's homing mode for them, as ros2_canopen's init does.
    Method 0 is CiA 402's "no homing": such a joint goes to the home pose."""
    return [joint for joint, node in block_nodes(profile, hw).items()
            if _homing_method(node) not in (None, 0)]


def _homing_method(node: NodeConfig) -> int | float | None:
    """The homing method the node's start-up writes last, if any."""
    methods = [write.value for write in node.sdo if write.index == HOMING_METHOD]
    return methods[-1] if methods else None


def _block_eds(profile: Profile, hw: Hardware) -> Path:
    text = hw.params.get("eds")
    if not text:
        return GENERIC_EDS
    path = Path(text)
    if not path.is_absolute() and profile.source:
        path = Path(profile.source).resolve().parent / path
    return path


def _from_bus(profile: Profile, hw: Hardware, joint: Component,
              bus: BusConfig) -> NodeConfig | None:
    name = joint.params.get("device_name")
    if name:
        node = bus.nodes.get(name)
        if node is None:
            raise ProfileError(f"{joint.name}: device_name {name!r} is not a node of "
                               f"{bus.source} (its nodes: {', '.join(bus.nodes)})",
                               profile.source, joint.line)
        return node
    address = _node_id(profile, hw, joint)
    if address is None:
        return None
    node = bus.by_id().get(address)
    if node is None:
        raise ProfileError(f"{joint.name}: node {address} is not in {bus.source} "
                           f"(its node IDs: {', '.join(str(i) for i in sorted(bus.by_id()))})",
                           profile.source, joint.line)
    return node


def _node_id(profile: Profile, hw: Hardware, joint: Component) -> int | None:
    """The joint's ``address:``, or its ``node_id`` param."""
    from deltoctl.profile.validate import part_address

    return part_address(profile, hw, joint)


def _from_joint(profile: Profile, hw: Hardware, joint: Component) -> NodeConfig | None:
    address = _node_id(profile, hw, joint)
    if address is None:
        return None
    scales = dict(SCALES)
    for key in SCALES:
        text = joint.params.get(key, hw.params.get(key))
        if text is not None:
            try:
                scales[key] = float(text)
            except ValueError:
                raise ProfileError(f"{joint.name}: {key} must be a number, got {text!r}",
                                   profile.source, joint.line) from None
    return NodeConfig(joint.name, address, None, scales)


def import_block(profile: Profile, hw: Hardware) -> None:
    """ros2_canopen's Cia402System params read into deltoctl's model: ``can_interface_name``
    as the block's bus (SocketCAN), ``bus_config`` resolved against the URDF's folder, and
    a joint named by ``device_name`` given its node's ID."""
    from deltoctl_canopen.transport import DEFAULT_BITRATE

    path = bus_file(profile, hw)
    if path is not None:
        hw.params["bus_config"] = str(path)
    name = hw.params.get("can_interface_name", "").strip().strip('"')
    if name and hw.bus is None:
        hw.bus = hw.name
        profile.buses.setdefault(hw.name, f"can://socketcan/{name}?bitrate={DEFAULT_BITRATE}")
    if path is not None and any(j.params.get("device_name") for j in hw.joints):
        bus = load_block_bus(profile, hw)
        assert bus is not None
        for joint in hw.joints:
            node = _from_bus(profile, hw, joint, bus)
            if node is not None and joint.address is None:
                joint.address = node.node_id


SERIAL_PARAM = "lss_serial"


def joint_serial(profile: Profile, joint: Component) -> int | None:
    """The serial number (0x1018:4, the last part of its LSS address) of the drive the
    joint's ``lss_serial`` param names, to tell two drives of one model apart; None without
    one."""
    text = joint.params.get(SERIAL_PARAM)
    if text is None:
        return None
    try:
        value = int(str(text).strip(), 0)
    except ValueError:
        value = -1
    if not 0 <= value <= 0xFFFFFFFF:
        raise ProfileError(f"{joint.name}: {SERIAL_PARAM} must be a 32-bit serial number "
                           f"(1234 or 0x4D2), got {text!r}", profile.source, joint.line)
    return value


def bus_bitrate(profile: Profile, bus: str) -> int:
    """The bit rate of the profile's bus (its URL's), the default one when it gives none."""
    import contextlib

    from deltoctl.errors import DeltoctlError

    from deltoctl_canopen.transport import DEFAULT_BITRATE, parse_can_url

    with contextlib.suppress(DeltoctlError):
        return parse_can_url(profile.buses.get(bus, "")).bitrate
    return DEFAULT_BITRATE
