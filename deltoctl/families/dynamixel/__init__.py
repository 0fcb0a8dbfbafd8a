"""ROBOTIS Dynamixel Protocol 2.0 buses (the MH5's XL430 servos): codec, control table, bus
driver, and an emulated bus on a pseudo-terminal."""

from deltoctl.registry import Family

FAMILY = Family(
    name="dynamixel",
    summary="Dynamixel Protocol 2.0 servo buses (RS-485)",
    driver="deltoctl.families.dynamixel.driver:DynamixelDriver",
    frame_names="deltoctl.families.dynamixel.codec:frame_name",
    emulator="deltoctl.families.dynamixel.emulator:serve",
    plugins=("mh5_hardware/MH5DynamixelInterface",),
    schemes=("serial",),
    address_range=(0, 252),
    address_kind="Dynamixel ID",
    capabilities=frozenset({"identify", "detect", "home", "jog", "registers", "torque",
                            "reboot", "config"}),
    serve_options=("missing", "pace", "wrong_baud"),
    register_items="deltoctl.families.dynamixel.control_table:item_names",
)
