"""What a family on a link of its own (a CAN bus) gives ``deltoctl setup``, beside the serial
servos' addressing: each joint's part as the profile wants it (``LinkJoint``) and a
``LinkAddressing`` that opens the link, finds the joint's part there, gives it its address
and rate, and reads back what answers at the new address. The family declares it as
``Family.link_setup``; the procedure (planning, confirmation, the rows of the result) is
deltoctl.app.setup's, whichever family answers."""

from __future__ import annotations

from contextlib import AbstractContextManager
from dataclasses import dataclass
from typing import Any, Protocol


@dataclass(frozen=True)
class LinkJoint:
    """A joint's part as the profile wants it: its address (``id``: a CANopen node ID) and
    rate on the link, and the serial that names the part (None: the one connected)."""

    joint: str
    block: str
    id: int
    baud: int
    protocol: str
    model: str = ""
    serial: int | None = None


class LinkAddressing(Protocol):
    """A family's setup of the parts on one kind of link."""

    protocol: str

    def joints(self, profile: Any, hw: Any) -> list[LinkJoint]:
        """The block's joints, in the profile's order."""
        ...

    def open(self, url: str) -> AbstractContextManager[Any]:
        """The link at ``url``, opened (Unreachable when it does not open)."""
        ...

    def locate(self, link: Any, want: LinkJoint) -> dict[str, Any]:
        """The part that is ``want``'s: ``{id, baud, protocol, model, serial}`` (``id``
        None: no address yet; ``want.id``: set already). Refused when it cannot be told
        from another, NoAnswer when none answers; nothing is written."""
        ...

    def assign(self, link: Any, want: LinkJoint, found: dict[str, Any]) -> None:
        """The part ``locate`` found given ``want``'s address and rate, stored."""
        ...

    def identify(self, link: Any, want: LinkJoint) -> str | None:
        """The model of what answers at ``want``'s address (None: nothing)."""
        ...
