"""The public ros2_control plugins of Feetech servos, read into deltoctl's model when a URDF is
loaded, so their descriptions run unchanged (reference §4), each with its own params:

- ``feetech_ros2_driver/FeetechHardwareInterface`` (JafarAbdi/feetech_ros2_driver): hardware
  ``usb_port`` (1 Mbps fixed); per joint ``id``, ``offset`` (steps of the zero pose).
- ``so_arm101_ros2_control/SoArm101HardwareInterface`` (renesas-rdk): hardware ``serial_port``,
  ``serial_baudrate``, ``calibration_file`` (LeRobot's JSON); joints named as LeRobot's
  motors, their IDs the file's (or 1..6 in order).
- ``sts_hardware_interface/STSHardwareInterface`` (adityakamath): hardware ``serial_port``,
  ``baud_rate``; per joint ``motor_id``.
- ``feetech_sts_hardware/FeetechSTSHardware`` (PChristoffersen): hardware ``port_name``,
  ``baud_rate``; per joint ``id``, ``zero_offset`` (steps; ``default_zero_offset`` of the
  hardware for joints without one).

A joint without an ID is its block's N-th servo (1-based), as LeRobot numbers an SO arm's.
"""

from __future__ import annotations

from pathlib import Path
from urllib.parse import quote

from deltoctl.errors import ProfileError
from deltoctl.profile.model import Component, Hardware, Profile

JAFAR = "feetech_ros2_driver/FeetechHardwareInterface"
SO_ARM101 = "so_arm101_ros2_control/SoArm101HardwareInterface"
STS = "sts_hardware_interface/STSHardwareInterface"
PCHRISTOFFERSEN = "feetech_sts_hardware/FeetechSTSHardware"
# plugin → (port param, baud param or None: 1 Mbps, the joint's ID param, its zero param)
PARAMS = {JAFAR: ("usb_port", None, "id", "offset"),
          SO_ARM101: ("serial_port", "serial_baudrate", "id", None),
          STS: ("serial_port", "baud_rate", "motor_id", None),
          PCHRISTOFFERSEN: ("port_name", "baud_rate", "id", "zero_offset")}


def _fail(profile: Profile, hw: Hardware, message: str) -> ProfileError:
    return ProfileError(f"<ros2_control name={hw.name!r}> ({hw.plugin}): {message}",
                        profile.source, hw.line)


def import_block(profile: Profile, hw: Hardware) -> None:
    """The block's bus from its plugin's port and baud params, and each joint's ID from its
    plugin's ID param or the calibration file (idempotent)."""
    if hw.plugin not in PARAMS:
        return
    for device_id, joint in servo_ids(profile, hw).items():
        joint.address = device_id
    if hw.bus is not None:
        return
    port_param, baud_param = PARAMS[hw.plugin][:2]
    port = hw.params.get(port_param)
    if not port:
        return  # the target then comes from -t
    baud = hw.params.get(baud_param, "1000000") if baud_param else "1000000"
    if not baud.strip().isdigit():
        raise _fail(profile, hw, f"{baud_param} must be a whole number, got {baud!r}")
    name = hw.name if hw.name not in profile.buses else f"{hw.name}-bus"
    profile.buses[name] = f"serial://{quote(port.strip(), safe='/')}?baud={int(baud)}"
    hw.bus = name


def _number(profile: Profile, hw: Hardware, joint: Component, param: str) -> int | None:
    text = joint.params.get(param)
    if text is None:
        return None
    try:
        return int(str(text).strip(), 0)
    except ValueError:
        raise _fail(profile, hw, f"joint {joint.name!r}: {param} must be a whole number, got "
                    f"{text!r}") from None


def servo_ids(profile: Profile, hw: Hardware) -> dict[int, Component]:
    """ID → joint: the joint's address, its plugin's ID param, the calibration file's ID for
    its name, or its place in the block (1-based)."""
    id_param = PARAMS.get(hw.plugin, (None, None, "id", None))[2]
    calibration = calibration_ids(profile, hw)
    ids: dict[int, Component] = {}
    for n, joint in enumerate(hw.joints, 1):
        found = joint.address if joint.address is not None else \
            _number(profile, hw, joint, id_param)
        if found is None:
            found = calibration.get(joint.name, n)
        if found in ids:
            raise _fail(profile, hw, f"joints {ids[found].name!r} and {joint.name!r} both have "
                        f"ID {found}")
        if not 0 <= found <= 253:
            raise _fail(profile, hw, f"joint {joint.name!r}: ID {found} is not 0..253")
        ids[found] = joint
    return ids


def zero_steps(profile: Profile, hw: Hardware, joint: Component) -> int | None:
    """The step a plugin says is the joint's zero (feetech_ros2_driver's ``offset``,
    feetech_sts_hardware's ``zero_offset`` or its block's ``default_zero_offset``)."""
    param = PARAMS.get(hw.plugin, (None, None, None, None))[3]
    if param is None:
        return None
    found = _number(profile, hw, joint, param)
    if found is None and hw.plugin == PCHRISTOFFERSEN and "default_zero_offset" in hw.params:
        found = _number(profile, hw, Component("joint", hw.name, params=hw.params),
                        "default_zero_offset")
    return found


def calibration_path(profile: Profile, hw: Hardware) -> Path | None:
    """The block's LeRobot calibration file (its ``calibration_file`` param), relative to the
    profile's own file."""
    text = hw.params.get("calibration_file")
    if not text:
        return None
    path = Path(text.strip()).expanduser()
    if not path.is_absolute() and profile.source:
        path = Path(profile.source).parent / path
    return path


def calibration_ids(profile: Profile, hw: Hardware) -> dict[str, int]:
    path = calibration_path(profile, hw)
    if path is None:
        return {}
    from deltoctl.families.feetech.calibration import load

    return {name: motor.id for name, motor in load(path).items()}
