"""The driver of a Dynamixel bus by the protocol its block says it speaks (``protocol_version``,
2.0 unless 1.0): the family's descriptor names :class:`BusDriver`."""

from __future__ import annotations

from deltoctl.core.driver import Block
from deltoctl.families.dynamixel import protocol_of
from deltoctl.families.dynamixel.driver import DynamixelDriver
from deltoctl.families.dynamixel.driver1 import Protocol1Driver


class BusDriver(DynamixelDriver):
    """A Protocol 2.0 bus's driver; a block whose protocol_version is 1.0 gets the Protocol
    1.0 bus's (:class:`Protocol1Driver`, made whole here, so its own __init__ is not run
    again)."""

    def __new__(cls, block: Block) -> DynamixelDriver:
        if protocol_of(block.hw.params, block.hw.name) == 1.0:
            return Protocol1Driver(block)
        return super().__new__(cls)
