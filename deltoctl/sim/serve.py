"""Serve the simulated devices of a profile: a Delto gripper on loopback TCP, each Dynamixel
bus on a pseudo-terminal, the I2C bus (Bioscara joints, LSM6DS3) over loopback — with the
faults asked for. Used by ``deltoctl sim serve`` and by the pytest fixture."""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass, fields

from deltoctl.errors import InvalidInput
from deltoctl.profile.model import Profile


@dataclass
class ServeOptions:
    host: str = "127.0.0.1"
    port: int = 0  # the gripper's TCP port (0: any free one)
    # a Delto gripper
    firmware: str = "3.0"  # MAJOR.MINOR
    model_id: int | None = None  # another model than the profile's
    short_version: bool = False
    input_1: bool = False
    delay: float = 0.0  # s before every reply
    stall: tuple[str, ...] = ()  # joints that cannot move (a Bioscara joint too)
    # the buses
    missing: tuple[str, ...] = ()  # joints that never answer
    pace: bool = False  # serial buses take the wire time of every byte
    wrong_baud: tuple[str, ...] = ()  # servos at another baud rate than their bus
    who_am_i: int = 0x6A
    orientation: tuple[float, ...] = (0.0, 0.0)  # the IMU's roll, pitch (and yaw), degrees


GRIPPER_ONLY = ("firmware", "model_id", "short_version", "input_1", "delay")
BUS_ONLY = ("missing", "pace", "wrong_baud", "who_am_i", "orientation")


def serve_profile(stack: contextlib.ExitStack, prof: Profile, options: ServeOptions) -> dict:
    """Start the profile's simulated devices (closed with ``stack``); returns ``{"profile",
    "buses": {bus: target URL}}`` and, for a gripper, its endpoint, model and firmware."""
    families = {prof.family_of(h) for h in prof.hardware}
    gripper = "delto" in families
    defaults = ServeOptions()
    misplaced = [f"--{f.name.replace('_', '-')}" for f in fields(options)
                 if f.name in (BUS_ONLY if gripper else GRIPPER_ONLY)
                 and getattr(options, f.name) != getattr(defaults, f.name)]
    if misplaced:
        raise InvalidInput(f"{', '.join(misplaced)}: not for {prof.name} "
                           f"({'a Delto gripper' if gripper else 'not a gripper'})")
    if gripper:
        return _serve_delto(stack, prof, options)
    if not families & {"dynamixel", "bioscara", "lsm6ds3"}:
        raise InvalidInput(f"no simulator for profile {prof.name!r} yet "
                           "(supported: delto, dynamixel, bioscara, lsm6ds3)")
    missing = _joint_addresses(prof, options.missing, "--missing")
    buses = {}
    if "dynamixel" in families:
        buses.update(_serve_dynamixel(
            stack, prof, options.pace, missing.get("dynamixel", set()),
            _joint_addresses(prof, options.wrong_baud, "--wrong-baud").get("dynamixel", set())))
    if families & {"bioscara", "lsm6ds3"}:
        blocked = _joint_addresses(prof, options.stall, "--stall").get("bioscara", set())
        buses.update(_serve_i2c(stack, prof, options, missing.get("bioscara", set()), blocked))
    return {"profile": prof.name, "buses": buses}


def _serve_delto(stack: contextlib.ExitStack, prof: Profile, o: ServeOptions) -> dict:
    from deltoctl.families.delto.models import MODELS
    from deltoctl.families.delto.emulator import DeltoServer, firmware_for_profile

    try:
        major, minor = (int(x) for x in o.firmware.split("."))
    except ValueError:
        raise InvalidInput(f"--firmware {o.firmware!r} is not MAJOR.MINOR (e.g. 2.8)") from None
    if o.model_id is not None and o.model_id not in MODELS:
        raise InvalidInput(f"--model-id {o.model_id:#06x} is not a Delto model "
                           f"({', '.join(f'{m:#06x}' for m in MODELS)})")
    device = firmware_for_profile(prof, model_id=o.model_id, firmware=(major, minor),
                                  short_version=o.short_version)
    device.input_1 = o.input_1
    device.faults.delay = o.delay
    hw = next(h for h in prof.hardware if prof.family_of(h) == "delto")
    joints = [j.name for j in hw.joints]
    for name in o.stall:
        if name not in joints:
            raise InvalidInput(f"--stall: {prof.name} has no joint {name!r}")
        device.faults.stalled.add(joints.index(name))
    server = stack.enter_context(DeltoServer(device, host=o.host, port=o.port))
    return {"profile": prof.name, "endpoint": server.endpoint,
            "buses": {hw.bus or "gripper": server.endpoint}, "model": device.model.name,
            "firmware": o.firmware}


def _joint_addresses(prof: Profile, names: tuple[str, ...], option: str) -> dict[str, set[int]]:
    """The bus addresses of the named joints (Dynamixel IDs, I2C addresses) by family."""
    from deltoctl.profile.validate import part_address

    found: dict[str, set[int]] = {}
    for name in names:
        hw_comp = next(((h, c) for h, c in prof.components() if c.name == name), None)
        address = part_address(prof, *hw_comp) if hw_comp else None
        if hw_comp is None or address is None:
            raise InvalidInput(f"{option}: {prof.name} has no joint {name!r} with a bus address")
        found.setdefault(prof.family_of(hw_comp[0]) or "", set()).add(address)
    return found


def _serve_dynamixel(stack: contextlib.ExitStack, prof: Profile, pace: bool, missing: set[int],
                     wrong_baud: set[int]) -> dict[str, str]:
    """One pseudo-terminal per Dynamixel bus of the profile, its servos at the joints' IDs,
    listening at the bus URL's baud rate."""
    from deltoctl.families.dynamixel.emulator import DynamixelBus, DynamixelPtyServer, Servo
    from deltoctl.transport.serial_port import parse_serial_url

    buses = {}
    for hw in prof.hardware:
        if prof.family_of(hw) != "dynamixel":
            continue
        url = prof.buses.get(hw.bus or "", "serial:///dev/ttyUSB0?baud=1000000")
        _, baud, _ = parse_serial_url(url)
        bus = DynamixelBus([Servo(j.address) for j in hw.joints if j.address is not None],
                           baud=baud)
        bus.faults.missing |= missing
        for device_id in wrong_baud & set(bus.servos):
            bus.servos[device_id].memory[8] = 1 if baud != 57600 else 2  # 57600 (or 115200)
        server = stack.enter_context(DynamixelPtyServer(bus, pace=pace))
        query = url.split("?", 1)[1] if "?" in url else f"baud={baud}"
        buses[hw.bus or hw.name] = f"serial://{server.port}?{query}"
    return buses


def _serve_i2c(stack: contextlib.ExitStack, prof: Profile, o: ServeOptions, missing: set[int],
               blocked: set[int]) -> dict[str, str]:
    """The profile's I2C devices on one simulated bus, served over loopback TCP."""
    from deltoctl.families.lsm6ds3.codec import WHO_AM_I
    from deltoctl.families.bioscara.emulator import JointFirmware
    from deltoctl.sim.i2c_bus import I2CSocketServer, bus_for_profile
    from deltoctl.families.lsm6ds3.emulator import Lsm6ds3Chip

    bus = bus_for_profile(prof, missing=tuple(missing))
    for address, device in bus.devices.items():
        if isinstance(device, Lsm6ds3Chip):
            device.registers[WHO_AM_I] = o.who_am_i
            device.set_orientation(*(math.radians(a) for a in o.orientation[:3]))
        elif isinstance(device, JointFirmware) and address in blocked:
            device.blocked = True
    server = stack.enter_context(I2CSocketServer(bus, host=o.host))
    names = {h.bus for h in prof.hardware if prof.family_of(h) in ("bioscara", "lsm6ds3")}
    return {name or "i2c": server.url for name in names}
