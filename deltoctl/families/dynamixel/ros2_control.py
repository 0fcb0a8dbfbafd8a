"""The public Dynamixel ros2_control plugins' conventions, read into deltoctl's model when a
URDF is loaded, so their descriptions run unchanged.

- ``dynamixel_hardware/DynamixelHardware`` (dynamixel-community/dynamixel_hardware, its README
  and src/dynamixel_hardware.cpp): hardware params ``usb_port``, ``baud_rate`` and
  ``use_dummy``; a param ``id`` per joint (the family's ``address_param``).
- ``dynamixel_hardware_interface/DynamixelHardware`` (ROBOTIS-GIT/dynamixel_hardware_interface,
  its README and src/dynamixel_hardware_interface.cpp; OpenMANIPULATOR-X's
  open_manipulator_x_position.ros2_control.xacro): hardware params ``port_name``,
  ``baud_rate``, ``number_of_joints``, ``number_of_transmissions`` and the optional
  ``transmission_to_joint_matrix`` (row-major, comma-separated, identity by default); a
  ``<gpio>`` per servo with params ``type`` (``dxl``) and ``ID``, and the control table items it
  writes at start. Joint i is driven by the servo its matrix row names (-1: reversed). The
  gpios stay in the profile as ros2_control parses them (listed, exported, their interfaces
  routed to the bus); the bus maps servos to joints from them when it starts.
"""

from __future__ import annotations

from dataclasses import replace
from urllib.parse import quote

from deltoctl.errors import ProfileError
from deltoctl.profile.model import Component, Hardware, Profile

COMMUNITY = "dynamixel_hardware/DynamixelHardware"
ROBOTIS = "dynamixel_hardware_interface/DynamixelHardware"
PORT_PARAMS = {COMMUNITY: "usb_port", ROBOTIS: "port_name"}
MAX_SERVOS = 253  # IDs 0..252: a matrix larger than that is no bus
ADDRESSES = (0, MAX_SERVOS - 1)


def import_block(profile: Profile, hw: Hardware) -> None:
    """The bus of a block written for one of the two plugins, and its servo gpios checked
    (idempotent: a block deltoctl exported keeps its bus)."""
    if hw.plugin == ROBOTIS:
        servo_gpios(profile, hw)
    if hw.plugin in PORT_PARAMS and hw.bus is None:
        _bus(profile, hw, PORT_PARAMS[hw.plugin])


def servo_ids(profile: Profile, hw: Hardware) -> dict[int, Component]:
    """ID → joint: the joint's address, its ``id`` param (dynamixel_hardware's), or the servo
    gpio its transmission row names (dynamixel_hardware_interface's: the joint as it drives
    that servo, reversed where the row says -1, the gpio's items among its params)."""
    from deltoctl.profile.validate import part_address

    ids = {}
    for joint in hw.joints:
        address = part_address(profile, hw, joint)
        if address is not None:
            ids[address] = joint
    if hw.plugin != ROBOTIS:
        return ids
    addressed = {j.name for j in ids.values()}  # a joint's own address comes first
    for device_id, (joint, gpio, factor) in servo_gpios(profile, hw).items():
        if joint.name not in addressed and device_id not in ids:
            params = {**{k: v for k, v in gpio.params.items() if k not in ("type", "ID")},
                      **joint.params}
            ids[device_id] = replace(joint, address=device_id, params=params,
                                     inverse=joint.inverse != (factor < 0))
    return ids


def _fail(profile: Profile, hw: Hardware, message: str) -> ProfileError:
    return ProfileError(f"<ros2_control name={hw.name!r}> ({hw.plugin}): {message}",
                        profile.source, hw.line)


def _bus(profile: Profile, hw: Hardware, port_param: str) -> None:
    """The serial port and baud rate params as the block's bus, named after the block."""
    port, baud = hw.params.get(port_param), hw.params.get("baud_rate")
    if not port:
        return  # the target then comes from -t
    if baud is not None and not baud.strip().isdigit():
        raise _fail(profile, hw, f"baud_rate must be a whole number, got {baud!r}")
    query = f"?baud={int(baud)}" if baud is not None else ""
    name = hw.name if hw.name not in profile.buses else f"{hw.name}-bus"
    profile.buses[name] = f"serial://{quote(port.strip(), safe='/')}{query}"
    hw.bus = name


def servo_gpios(profile: Profile, hw: Hardware) -> dict[int, tuple[Component, Component, float]]:
    """ROBOTIS' convention: each ``type: dxl`` gpio is a servo; joint i takes the one its
    transmission-to-joint row names. ID → (joint, gpio, factor ±1)."""
    servos = [g for g in hw.gpios if g.params.get("type") == "dxl"]
    if not servos:
        return {}
    ids = [_id(profile, hw, g.name, g.params.get("ID")) for g in servos]
    low, high = ADDRESSES
    for gpio, device_id in zip(servos, ids):
        if not low <= device_id <= high:
            raise _fail(profile, hw, f"gpio {gpio.name!r}: ID {device_id} is not a Dynamixel "
                        f"ID ({low}..{high})")
        if ids.count(device_id) > 1:
            raise _fail(profile, hw, f"gpio {gpio.name!r}: ID {device_id} is given to "
                        f"{ids.count(device_id)} servo gpios")
    matrix = _matrix(profile, hw, len(hw.joints), len(servos))
    found = {}
    for row, joint in zip(matrix, hw.joints):
        drives = [(k, v) for k, v in enumerate(row) if v != 0.0]
        if len(drives) != 1 or abs(drives[0][1]) != 1.0:
            raise _fail(profile, hw, f"joint {joint.name!r} takes {len(drives)} servos' "
                        f"motion ({', '.join(f'{v:g}' for v in row)} in "
                        "transmission_to_joint_matrix): deltoctl drives each joint from one "
                        "servo, its factor 1 or -1")
        k, factor = drives[0]
        if ids[k] in found:
            raise _fail(profile, hw, f"joints {found[ids[k]][0].name!r} and {joint.name!r} "
                        f"both take servo {servos[k].name!r} in transmission_to_joint_matrix")
        found[ids[k]] = (joint, servos[k], factor)
    return found


# the readings a servo gpio may declare as state interfaces, and what the bus reads them as
GPIO_READINGS = ("Present Position", "Present Velocity", "Present Current", "Present Load",
                 "Present Input Voltage", "Present Temperature")


def gpio_readings(profile: Profile, hw: Hardware) -> dict[int, dict[str, str]]:
    """ID → {reading: the servo gpio's state interface}, for the readings it declares."""
    if hw.plugin != ROBOTIS:
        return {}
    return {device_id: {i.name: f"{gpio.name}/{i.name}" for i in gpio.state_interfaces
                        if i.name in GPIO_READINGS}
            for device_id, (_, gpio, _) in servo_gpios(profile, hw).items()}


def _id(profile: Profile, hw: Hardware, gpio: str, text: str | None) -> int:
    if text is None or not text.strip().isdigit():
        raise _fail(profile, hw, f"gpio {gpio!r} has no ID param with the servo's ID (got "
                    f"{text!r})")
    return int(text)


def _matrix(profile: Profile, hw: Hardware, joints: int, servos: int) -> list[list[float]]:
    """transmission_to_joint_matrix (joints × servos), or the identity."""
    if joints > MAX_SERVOS or servos > MAX_SERVOS:
        raise _fail(profile, hw, f"{joints} joints and {servos} servos: more than a bus holds")
    for key, count in (("number_of_joints", joints), ("number_of_transmissions", servos)):
        given = hw.params.get(key)
        if given is not None and given.strip() != str(count):
            raise _fail(profile, hw, f"{key} is {given!r}, but the block has {count}")
    text = hw.params.get("transmission_to_joint_matrix")
    if text is None:
        return [[1.0 if i == k else 0.0 for k in range(servos)] for i in range(joints)]
    from deltoctl.profile.model import parse_number

    values = ([parse_number(v) for v in text.split(",")]
              if text.count(",") + 1 == joints * servos else [])
    if len(values) != joints * servos or any(v is None for v in values):
        raise _fail(profile, hw, f"transmission_to_joint_matrix must hold {joints} × {servos} "
                    f"finite numbers, got {text.strip()!r}")
    return [[float(v or 0.0) for v in values[i * servos:(i + 1) * servos]]
            for i in range(joints)]
