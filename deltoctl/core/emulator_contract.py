"""The emulator contract: what a family's emulator receives and returns.

A family's descriptor names its emulator (``Family.emulator``, ``"module:function"``), an
:data:`Emulator`: given a :class:`ServeContext` and the profile's blocks of that family, it
serves their simulated devices behind real transports and returns each bus's target URL. The
simulators' server (``deltoctl.sim.serve``) builds the context; it is declared here, below the
emulators, so a family (in deltoctl or in a package of its own) depends on no simulator code.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from deltoctl.profile.model import Component, Hardware, Profile


class ServeSettings(Protocol):
    """The ``sim serve`` options an emulator reads: where to listen, and each fault or setting
    its family declares as an attribute (``options.firmware``): the value given or its
    declared default."""

    host: str
    port: int

    def __getattr__(self, name: str) -> Any: ...


# what a control line runs: its words after the first → a short reply; bad words are one
# InvalidInput naming them
ControlHandler = Callable[[list[str]], str]


class ServeContext(Protocol):
    """What an emulator gets: the profile, the options, the stack that closes what it starts,
    the report of each block it serves (``blocks[name] = {...}``), the simulated I2C buses
    that devices of several families share, and the control lines of ``sim serve``'s standard
    input it answers (``control``)."""

    stack: contextlib.ExitStack
    profile: Profile
    blocks: dict[str, dict[str, Any]]

    @property
    def options(self) -> ServeSettings: ...

    def named(self, option: str, hw: Hardware) -> list[Component]:
        """The joints of this block that a joint option (``missing`` …) names."""
        ...

    def i2c_bus(self, bus: str) -> tuple[Any, str]:
        """``(simulated bus, target URL)`` for a bus name, served once on loopback; each
        family adds its devices to the bus's ``devices``."""
        ...

    def control(self, word: str, usage: str, handler: ControlHandler) -> None:
        """Answer the control lines that start with ``word`` (``face -x``) on ``sim serve``'s
        standard input; ``usage`` (``face AXIS: …``) is what ``help`` lists."""
        ...


# A family's emulator: (context, its blocks) → {bus: target URL}
Emulator = Callable[[ServeContext, "list[Hardware]"], dict[str, str]]
