"""The driver families deltoctl knows: one table, read by validation and by the loaders."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Family:
    name: str
    plugins: tuple[str, ...]  # ros2_control plugins that imply this family on import
    schemes: tuple[str, ...]  # target URL schemes its buses use
    address_range: tuple[int, int] | None  # valid part addresses, inclusive
    address_param: str | None = None  # a plugin param that carries the address
    address_kind: str = "address"


FAMILIES: dict[str, Family] = {
    f.name: f
    for f in (
        Family("delto", ("delto_hardware/SystemInterface",), ("tcp",), (1, 20),
               address_kind="motor index"),
        Family("dynamixel", ("mh5_hardware/MH5DynamixelInterface",), ("serial",), (0, 252),
               address_kind="Dynamixel ID"),
        Family("bioscara", ("bioscara_hardware_interfaces/BioscaraArmHardwareInterface",),
               ("i2c",), (0x08, 0x77), address_param="i2c_address",
               address_kind="I2C address"),
        Family("lsm6ds3", ("mh5_hardware/MH5I2CInterface",), ("i2c",), (0x08, 0x77),
               address_kind="I2C address"),
        Family("generic", ("mock_components/GenericSystem",), (), None),
    )
}


def family_for_plugin(plugin: str) -> str | None:
    return next((f.name for f in FAMILIES.values() if plugin in f.plugins), None)
