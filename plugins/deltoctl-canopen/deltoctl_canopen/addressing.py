"""What the CANopen family gives ``deltoctl setup`` (its ``link_setup``): each joint's drive
as the profile wants it (node ID, the bus's bit rate, the serial ``lss_serial`` names), found
on the CAN bus and given its node ID and bit rate over LSS (deltoctl_canopen.lss), then read
back at the node ID with canopen's SDO client."""

from __future__ import annotations

from contextlib import AbstractContextManager
from typing import Any

from deltoctl.core.link_setup import LinkJoint

from deltoctl_canopen import lss

PROTOCOL = "CANopen"


def model_of(identity: lss.Identity) -> str:
    """How setup names a drive's model: its vendor and product codes (0x1018:1-2)."""
    return f"vendor {identity.vendor:#x} product {identity.product:#x}"


class LssAddressing:
    """The CANopen drives of a block, set up through canopen's LssMaster."""

    protocol = PROTOCOL

    def __init__(self) -> None:
        self._found: dict[int, lss.Identity] = {}  # serial → LSS address, as located
        self._bitrate = 0  # the link's, as opened

    def joints(self, profile: Any, hw: Any) -> list[LinkJoint]:
        return [LinkJoint(s.joint, hw.name, s.node_id, s.bitrate, PROTOCOL, "", s.serial)
                for s in lss.plan(profile, hw)]

    def open(self, url: str) -> AbstractContextManager[Any]:
        from deltoctl_canopen.transport import parse_can_url

        self._bitrate = parse_can_url(url).bitrate
        return lss.network_at(url)

    def locate(self, network: Any, want: LinkJoint) -> dict[str, Any]:
        identity, already = lss.locate(network, _step(want))
        self._found[identity.serial] = identity
        return {"id": want.id if already else None, "baud": self._bitrate, "protocol": PROTOCOL,
                "model": model_of(identity), "serial": identity.serial}

    def assign(self, network: Any, want: LinkJoint, found: dict[str, Any]) -> None:
        identity = self._found.get(found["serial"])
        if identity is None:  # not located by this one: found again by its serial
            identity, _ = lss.locate(network, lss.Step(want.joint, want.id, want.baud,
                                                       found["serial"]))
        lss.assign(network, identity, want.id, want.baud)

    def identify(self, network: Any, want: LinkJoint) -> str | None:
        identity = lss.read_identity(network, want.id)
        if identity is None or want.serial not in (None, identity.serial):
            return None if identity is None else f"{model_of(identity)} serial " \
                f"{identity.serial:#x}"
        return model_of(identity)


def _step(want: LinkJoint) -> lss.Step:
    return lss.Step(want.joint, want.id, want.baud, want.serial)


def addressing() -> LssAddressing:
    return LssAddressing()
