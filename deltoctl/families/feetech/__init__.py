"""Feetech serial bus servos — STS/SMS (little-endian) and SCS (big-endian) — and the LeRobot
SO-100/SO-101 arms built of them: codec, the models' control tables, bus driver, an emulated
bus on a pseudo-terminal, LeRobot's calibration file and the public ros2_control plugins'
conventions. Reference: feetech-sts-and-lerobot.md."""

from deltoctl.registry import Family, SimOption

FAMILY = Family(
    name="feetech",
    summary="Feetech STS/SMS/SCS serial bus servos (TTL half duplex; LeRobot SO-100/SO-101)",
    driver="deltoctl.families.feetech.driver:FeetechDriver",
    frame_names="deltoctl.families.feetech.codec:frame_name",
    emulator="deltoctl.families.feetech.emulator:serve",
    scan="deltoctl.families.feetech.scan:probes",
    setup="deltoctl.families.feetech.addressing:addressing",
    plugins=("feetech_ros2_driver/FeetechHardwareInterface",
             "so_arm101_ros2_control/SoArm101HardwareInterface",
             "sts_hardware_interface/STSHardwareInterface",
             "feetech_sts_hardware/FeetechSTSHardware"),
    import_block="deltoctl.families.feetech.ros2_control:import_block",
    address_param="id",
    schemes=("serial", "usb"),
    address_range=(0, 253),
    address_kind="Feetech ID",
    address_by_position=True,  # a joint without an ID is its block's N-th, as LeRobot's motors
    capabilities=frozenset({"identify", "detect", "home", "jog", "registers", "torque",
                            "config", "calibrate_servos", "calibrate_joints"}),
    serve_options=(
        SimOption("missing", "joints", "Fault: a servo that never answers (repeatable)."),
        SimOption("pace", "flag", "The bus takes the wire time of every byte at the baud "
                  "rate the host set, as a real bus does.", False),
        SimOption("wrong_baud", "joints",
                  "Fault: a servo set to another baud rate than its bus (repeatable)."),
        SimOption("duplicate", "joints", "Fault: a second servo answers at this joint's ID "
                  "(a new servo still at its factory ID): their replies collide (repeatable)."),
        SimOption("overload", "joints", "Fault: the servo has latched its overload "
                  "protection (torque off until its power is cycled) (repeatable)."),
        SimOption("voltage", "joints", "Fault: the servo's supply is outside its voltage "
                  "limits (16 V on a 12 V servo) (repeatable)."),
        SimOption("old_firmware", "joints", "Fault: the servo runs firmware 3.9 where the "
                  "others run 3.10 (repeatable)."),
        SimOption("factory_new", "flag", "Servos as they leave the factory, whatever the "
                  "profile says: Dynamixel at ID 1, 57,600 bps, Protocol 2.0 (X) or 1.0 (AX, "
                  "MX); Feetech at ID 1, 1 Mbps (deltoctl scan finds them).", False),
    ),
    identity_fields=(("servos", "{} Feetech servos"),),
    register_items="deltoctl.families.feetech.models:item_names",
    config_rules="deltoctl.families.feetech.models:config_rules",
)


def parse_bus_url(url: str) -> tuple[str, int, bool]:
    """A bus target, ``serial:///dev/PORT?baud=N`` → (path, baud, rs485), whose baud is one
    of the Baud_Rate register's codes (Feetech's table): another is a usage error naming
    them, before any port is opened."""
    from deltoctl.errors import InvalidInput
    from deltoctl.families.feetech.models import BAUD_RATES
    from deltoctl.transport.serial_port import parse_serial_url

    path, baud, rs485 = parse_serial_url(url)
    if baud not in BAUD_RATES.values():
        rates = ", ".join(str(rate) for rate in sorted(BAUD_RATES.values()))
        raise InvalidInput(f"{url!r}: Feetech servos cannot run at {baud} baud; their "
                           f"rates: {rates}")
    return path, baud, rs485
