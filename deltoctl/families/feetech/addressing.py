"""How ``deltoctl setup`` gives a Feetech servo the profile's ID and rate, as the servo takes
it: torque off and Lock 0 at the old ID, ID written there (the status comes from the old ID),
Baud_Rate at the new ID (the status at the old rate), Lock 1 at the new ID and rate so the
EEPROM keeps them. Feetech documents no factory reset: RESET 0x06 is in no list of its SDKs'
instructions (only third-party tools send it), so setup offers none."""

from __future__ import annotations

from typing import Any

from deltoctl.errors import DeltoctlError, InvalidInput
from deltoctl.families.feetech import codec
from deltoctl.families.feetech.models import BAUD_RATES, Model, by_bytes, expected_model, label
from deltoctl.servo.addressing import (
    ANSWER_WAIT,
    Addressing,
    Wanted,
    ask,
    in_joint_order,
    one_servo,
)

PROTOCOL = "Feetech"
NO_RESET = ("Feetech documents no factory reset (instruction 0x06 is in none of its SDKs' "
            "lists); set the items you need with config restore or register set")


class FeetechAddresser:
    protocol = PROTOCOL
    reset_options: tuple[str, ...] = ()
    factory = frozenset({(1, 1_000_000)})

    def __init__(self) -> None:
        self._models: dict[int, Model] = {}  # by the ID it answers at

    def _write(self, port: Any, device_id: int, address: int, data: bytes, what: str) -> None:
        ask(port, codec.session(), device_id, codec.WRITE, codec.write_params(address, data),
            what)

    def _model(self, port: Any, device_id: int, timeout: float = ANSWER_WAIT) -> Model | None:
        if device_id not in self._models:
            try:
                reply = ask(port, codec.session(), device_id, codec.READ,
                            codec.read_params(3, 2), "model", timeout)
            except DeltoctlError:  # no answer, or bytes that break the protocol
                return None
            model = by_bytes(reply[2]) if reply is not None else None
            if model is None:
                return None
            self._models[device_id] = model
        return self._models[device_id]

    def identify(self, port: Any, device_id: int, timeout: float = ANSWER_WAIT) -> str | None:
        self._models.pop(device_id, None)  # read again: a verification
        model = self._model(port, device_id, timeout)
        if model is None:
            return None
        item = model.by_name["Present_Position"]  # twins' model reads superimpose cleanly
        one_servo(port, codec.session(), device_id, codec.READ,
                  codec.read_params(item.address, item.size), item.size)
        return model.name

    def _item(self, port: Any, device_id: int, name: str) -> int:
        model = self._model(port, device_id)
        if model is None:
            raise InvalidInput(f"the servo at ID {device_id} is no Feetech model deltoctl knows")
        return model.lock if name == "Lock" else model.by_name[name].address

    def prepare(self, port: Any, device_id: int) -> None:
        self._write(port, device_id, self._item(port, device_id, "Torque_Enable"), b"\x00",
                    "torque off")
        self._write(port, device_id, self._item(port, device_id, "Lock"), b"\x00",
                    "unlock the EEPROM (Lock 0)")

    def write_id(self, port: Any, device_id: int, new_id: int) -> None:
        self._write(port, device_id, self._item(port, device_id, "ID"), bytes([new_id]),
                    f"ID {new_id}")
        self._models[new_id] = self._models[device_id]

    def write_baud(self, port: Any, device_id: int, baud: int) -> None:
        code = next(c for c, b in BAUD_RATES.items() if b == baud)
        self._write(port, device_id, self._item(port, device_id, "Baud_Rate"), bytes([code]),
                    f"Baud_Rate {baud}")

    def finish(self, port: Any, device_id: int) -> None:
        self._write(port, device_id, self._item(port, device_id, "Lock"), b"\x01",
                    "lock the EEPROM (Lock 1)")

    def factory_reset(self, port: Any, device_id: int, option: str) -> None:
        raise InvalidInput(NO_RESET)


def wanted(profile: Any, hw: Any, url: str) -> list[Wanted]:
    """Each joint's servo: its ID, the bus URL's rate, its model."""
    from deltoctl.families.feetech import parse_bus_url
    from deltoctl.families.feetech.ros2_control import servo_ids

    _, baud, _ = parse_bus_url(url)

    def model(joint: Any) -> str:
        number = expected_model(hw.params, joint.params, joint.name)
        return label(number) if number is not None else ""

    return in_joint_order(hw, servo_ids(profile, hw), baud, PROTOCOL, model)


def addresser(protocol: str) -> FeetechAddresser | None:
    return FeetechAddresser() if protocol == PROTOCOL else None


def addressing() -> Addressing:
    return Addressing(wanted, addresser, NO_RESET)
