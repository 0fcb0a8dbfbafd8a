"""ROBOTIS Dynamixel Protocol 2.0 buses of X-series servos (the MH5's XL430s, OpenMANIPULATOR-X's
XM430s, …): codec, the models' control tables, bus driver, an emulated bus on a
pseudo-terminal, and the public ros2_control plugins' conventions."""

from deltoctl.registry import Family, Permission, SimOption

FAMILY = Family(
    name="dynamixel",
    summary="Dynamixel Protocol 2.0 servo buses (RS-485)",
    driver="deltoctl.families.dynamixel.driver:DynamixelDriver",
    frame_names="deltoctl.families.dynamixel.codec:frame_name",
    emulator="deltoctl.families.dynamixel.emulator:serve",
    plugins=("mh5_hardware/MH5DynamixelInterface", "dynamixel_hardware/DynamixelHardware",
             "dynamixel_hardware_interface/DynamixelHardware"),
    import_block="deltoctl.families.dynamixel.plugins:import_block",
    address_param="id",  # dynamixel_hardware's joint param
    mock_param="use_dummy",  # dynamixel_hardware's simulated servos
    schemes=("serial", "usb"),
    address_range=(0, 252),
    address_kind="Dynamixel ID",
    capabilities=frozenset({"identify", "detect", "home", "jog", "registers", "torque",
                            "reboot", "config"}),
    serve_options=(
        SimOption("missing", "joints", "Fault: a joint that never answers (repeatable)."),
        SimOption("pace", "flag", "Serial buses take the wire time of every byte at the baud "
                  "rate the host set, as a real bus does.", False),
        SimOption("stall", "joints", "Fault: a joint that cannot move (repeatable)."),
        SimOption("wrong_baud", "joints",
                  "Fault: a servo set to another baud rate than its bus (repeatable)."),
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


def parse_bus_url(url: str) -> tuple[str, int, bool]:
    """A bus target, ``serial:///dev/PORT?baud=N&rs485=1`` → (path, baud, rs485), whose baud
    is one the X-series servos run (their Baud Rate register's table): another is a usage
    error naming those, before any port is opened."""
    from deltoctl.errors import InvalidInput
    from deltoctl.families.dynamixel.control_table import BAUD_RATES
    from deltoctl.transport.serial_port import parse_serial_url

    path, baud, rs485 = parse_serial_url(url)
    if baud not in BAUD_RATES.values():
        rates = ", ".join(str(rate) for rate in sorted(BAUD_RATES.values()))
        raise InvalidInput(f"{url!r}: Dynamixel X-series servos cannot run at {baud} baud; "
                           f"their rates: {rates}")
    return path, baud, rs485
