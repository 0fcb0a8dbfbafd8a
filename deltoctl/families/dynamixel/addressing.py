"""How ``deltoctl setup`` gives a Dynamixel servo the profile's ID and rate: Protocol 2.0
(X series: ID at 7, Baud Rate at 8, Torque Enable at 64; FACTORY_RESET 0x06 with option 0xFF
everything, 0x01 all but the ID, 0x02 all but the ID and rate) and Protocol 1.0 (AX, MX: ID
at 3, Baud Rate at 4, Torque Enable at 24; RESET 0x06, everything). EEPROM takes writes only
with the torque off; there is no lock."""

from __future__ import annotations

import struct
from typing import Any

from deltoctl.errors import DeltoctlError
from deltoctl.families.dynamixel import codec, protocol1
from deltoctl.families.dynamixel.control_table import BAUD_RATES
from deltoctl.families.dynamixel.models import by_number, expected_model
from deltoctl.families.dynamixel.models1 import BAUD_CODES
from deltoctl.servo.addressing import (
    ANSWER_WAIT,
    Addressing,
    Wanted,
    ask,
    checked,
    in_joint_order,
    one_servo,
)

PROTOCOL_2, PROTOCOL_1 = "Dynamixel 2.0", "Dynamixel 1.0"
RESETS_2 = {"all": 0xFF, "keep-id": 0x01, "keep-id-baud": 0x02}


def _name(number: int) -> str:
    model = by_number(number)
    return model.name if model else f"model number {number}"


def _error_2(error: int) -> str:
    return codec.STATUS_ERRORS.get(error & 0x7F, f"error {error}")


class Protocol2:
    protocol = PROTOCOL_2
    reset_options = tuple(RESETS_2)
    factory = frozenset({(1, 57_600)})

    def _write(self, port: Any, device_id: int, address: int, data: bytes, what: str) -> None:
        reply = ask(port, codec.session(), device_id, codec.WRITE,
                    codec.write_params(address, data), what)
        checked(reply, what, _error_2)

    def identify(self, port: Any, device_id: int, timeout: float = ANSWER_WAIT) -> str | None:
        try:
            reply = ask(port, codec.session(), device_id, codec.PING, b"", "PING", timeout)
        except DeltoctlError:  # no answer, or bytes that break the protocol: not there
            return None
        if reply is None or len(reply[2]) < 3:
            return None
        model = by_number(struct.unpack_from("<H", reply[2])[0])
        item = model.by_name.get("Present Position") if model is not None else None
        if item is not None:  # a PING from twins superimposes cleanly: their positions differ
            one_servo(port, codec.session(), device_id, codec.READ,
                      codec.read_params(item.address, item.size), item.size)
        return _name(struct.unpack_from("<H", reply[2])[0])

    def prepare(self, port: Any, device_id: int) -> None:
        self._write(port, device_id, 64, b"\x00", "torque off")

    def write_id(self, port: Any, device_id: int, new_id: int) -> None:
        self._write(port, device_id, 7, bytes([new_id]), f"ID {new_id}")

    def write_baud(self, port: Any, device_id: int, baud: int) -> None:
        code = next(c for c, b in BAUD_RATES.items() if b == baud)
        self._write(port, device_id, 8, bytes([code]), f"Baud Rate {baud}")

    def finish(self, port: Any, device_id: int) -> None:
        pass

    def factory_reset(self, port: Any, device_id: int, option: str) -> None:
        what = f"FACTORY_RESET ({option})"
        reply = ask(port, codec.session(), device_id, codec.FACTORY_RESET,
                    bytes([RESETS_2[option]]), what)
        checked(reply, what, _error_2)


class Protocol1:
    protocol = PROTOCOL_1
    reset_options = ("all",)
    factory = frozenset({(1, 1_000_000), (1, 57_600)})  # AX, MX

    def _write(self, port: Any, device_id: int, address: int, data: bytes, what: str) -> None:
        reply = ask(port, protocol1.session(), device_id, protocol1.WRITE,
                    bytes([address, *data]), what)
        checked(reply, what, protocol1.error_text)

    def identify(self, port: Any, device_id: int, timeout: float = ANSWER_WAIT) -> str | None:
        try:
            reply = ask(port, protocol1.session(), device_id, protocol1.READ, bytes([0, 3]),
                        "model", timeout)
        except DeltoctlError:  # no answer, or bytes that break the protocol: not there
            return None
        if reply is None or len(reply[2]) < 2:
            return None
        one_servo(port, protocol1.session(), device_id, protocol1.READ,
                  protocol1.read_params(36, 2), 2)  # Present Position: twins differ in it
        return _name(struct.unpack_from("<H", reply[2])[0])

    def prepare(self, port: Any, device_id: int) -> None:
        self._write(port, device_id, 24, b"\x00", "torque off")

    def write_id(self, port: Any, device_id: int, new_id: int) -> None:
        self._write(port, device_id, 3, bytes([new_id]), f"ID {new_id}")

    def write_baud(self, port: Any, device_id: int, baud: int) -> None:
        self._write(port, device_id, 4, bytes([BAUD_CODES[baud]]), f"Baud Rate {baud}")

    def finish(self, port: Any, device_id: int) -> None:
        pass

    def factory_reset(self, port: Any, device_id: int, option: str) -> None:
        reply = ask(port, protocol1.session(), device_id, protocol1.RESET, b"", "RESET")
        checked(reply, "RESET", protocol1.error_text)


def wanted(profile: Any, hw: Any, url: str) -> list[Wanted]:
    """Each joint's servo: its ID, the bus URL's rate, the block's protocol, its model."""
    from deltoctl.families.dynamixel import parse_bus_url, protocol_of
    from deltoctl.families.dynamixel.ros2_control import servo_ids

    protocol = protocol_of(hw.params, hw.name)
    _, baud, _ = parse_bus_url(url, protocol)

    def model(joint: Any) -> str:
        number = expected_model(hw.params, joint.params, joint.name)
        return _name(number) if number is not None else ""

    return in_joint_order(hw, servo_ids(profile, hw), baud,
                          PROTOCOL_1 if protocol == 1.0 else PROTOCOL_2, model)


def addresser(protocol: str) -> Any:
    return {PROTOCOL_2: Protocol2, PROTOCOL_1: Protocol1}.get(protocol, lambda: None)()


def addressing() -> Addressing:
    return Addressing(wanted, addresser)
