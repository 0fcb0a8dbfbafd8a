"""ROBOTIS Dynamixel buses: Protocol 2.0 of X-series servos (the MH5's XL430s, OpenMANIPULATOR-X's
XM430s, …) and Protocol 1.0 of AX, RX and MX servos (a block's ``protocol_version`` param says
which; a bus is one protocol): codecs, the models' control tables, bus drivers, emulated buses
on a pseudo-terminal, and the public ros2_control plugins' conventions."""

from deltoctl.registry import Family, Permission, SimOption

FAMILY = Family(
    name="dynamixel",
    summary="Dynamixel Protocol 2.0 and 1.0 servo buses (TTL, RS-485)",
    driver="deltoctl.families.dynamixel.protocols:BusDriver",
    frame_names="deltoctl.families.dynamixel.codec:frame_name",
    emulator="deltoctl.families.dynamixel.emulator:serve",
    scan="deltoctl.families.dynamixel.scan:probes",
    setup="deltoctl.families.dynamixel.addressing:addressing",
    plugins=("mh5_hardware/MH5DynamixelInterface", "dynamixel_hardware/DynamixelHardware",
             "dynamixel_hardware_interface/DynamixelHardware"),
    import_block="deltoctl.families.dynamixel.ros2_control:import_block",
    address_param="id",  # dynamixel_hardware's joint param
    mock_param="use_dummy",  # dynamixel_hardware's simulated servos
    schemes=("serial", "usb"),
    address_range=(0, 252),
    address_kind="Dynamixel ID",
    capabilities=frozenset({"identify", "detect", "home", "jog", "registers", "torque",
                            "reboot", "config", "calibrate_joints"}),
    serve_options=(
        SimOption("missing", "joints", "Fault: a joint that never answers (repeatable)."),
        SimOption("pace", "flag", "Serial buses take the wire time of every byte at the baud "
                  "rate the host set, as a real bus does.", False),
        SimOption("stall", "joints", "Fault: a joint that cannot move (repeatable)."),
        SimOption("wrong_baud", "joints",
                  "Fault: a servo set to another baud rate than its bus (repeatable)."),
        SimOption("other_protocol", "joints",
                  "Fault: a servo set to the other protocol than its bus's (repeatable)."),
        SimOption("factory_new", "flag", "Servos as they leave the factory, whatever the "
                  "profile says: Dynamixel at ID 1, 57,600 bps, Protocol 2.0 (X) or 1.0 (AX, "
                  "MX); Feetech at ID 1, 1 Mbps (deltoctl scan finds them).", False),
    ),
    permissions=(Permission(
        "torque-off",
        why="EEPROM items take writes only with torque off, and the torque is on",
        given="torque goes off for the EEPROM writes, then on again where they are",
        hint="switch the torque off first (deltoctl torque off), or pass --allow torque-off "
             "to have it switched off for the writes and on again (support the robot)"),),
    identity_fields=(("servos", "{} Dynamixel servos"),),
    register_items="deltoctl.families.dynamixel.models:item_names",
    config_rules="deltoctl.families.dynamixel.models:config_rules",
)


PROTOCOL_PARAMS = ("protocol_version", "protocol")  # dynamixel_workbench's name, and short


def protocol_of(params: dict[str, str], name: str = "") -> float:
    """A block's protocol (1.0 or 2.0, the default) from its ``protocol_version`` (or
    ``protocol``) param; another value is a usage error naming it."""
    from deltoctl.errors import InvalidInput

    for key in PROTOCOL_PARAMS:
        text = str(params.get(key, "")).strip()
        if text:
            if text in ("1", "1.0"):
                return 1.0
            if text in ("2", "2.0"):
                return 2.0
            raise InvalidInput(f"{name}: {key} {text!r} is not a Dynamixel protocol (1.0 or "
                               "2.0)")
    return 2.0


def parse_bus_url(url: str, protocol: float = 2.0) -> tuple[str, int, bool]:
    """A bus target, ``serial:///dev/PORT?baud=N&rs485=1`` → (path, baud, rs485), whose baud
    is one the X-series servos run (their Baud Rate register's table): another is a usage
    error naming those, before any port is opened."""
    from deltoctl.errors import InvalidInput
    from deltoctl.families.dynamixel.control_table import BAUD_RATES
    from deltoctl.transport.serial_port import parse_serial_url

    path, baud, rs485 = parse_serial_url(url)
    if protocol == 1.0:
        from deltoctl.families.dynamixel.models1 import BAUD_CODES

        if baud not in BAUD_CODES:
            rates = ", ".join(str(rate) for rate in sorted(BAUD_CODES))
            raise InvalidInput(f"{url!r}: Dynamixel Protocol 1.0 servos cannot run at {baud} "
                               f"baud; their rates: {rates}")
        return path, baud, rs485
    if baud not in BAUD_RATES.values():
        rates = ", ".join(str(rate) for rate in sorted(BAUD_RATES.values()))
        raise InvalidInput(f"{url!r}: Dynamixel X-series servos cannot run at {baud} baud; "
                           f"their rates: {rates}")
    return path, baud, rs485
