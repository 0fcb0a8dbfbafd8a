"""Transports: bytes moved over TCP, a serial port or an I2C bus, chosen by URL.

Each kind of link is a ``Transport``, found by its URL's scheme through ``deltoctl.registry``:
the built-in ones below (``BUILTIN``: scheme → "module:attr", imported only when a link of that
kind is opened or checked), and those a package brings through the ``deltoctl.transports``
entry-point group. A transport opens a link, parses and validates its URL, names what
``deltoctl doctor`` checks of a target, and labels the link's packets in the ``-vv`` trace.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from deltoctl.errors import InvalidInput

if TYPE_CHECKING:
    from urllib.parse import SplitResult

BUILTIN = {
    "tcp": "deltoctl.transport.tcp:TRANSPORT",
    "serial": "deltoctl.transport.serial_port:TRANSPORT",
    "usb": "deltoctl.transport.serial_port:USB",
    "i2c": "deltoctl.transport.i2c:KERNEL",
    "i2c+tcp": "deltoctl.transport.i2c:SIMULATED",
}

Check = dict[str, Any]  # one doctor check: check, subject, ok, detail, fix, exit_code


@dataclass(frozen=True)
class Target:
    """What ``doctor`` asks a transport to check: a bus's URL, how long to wait, and what
    the families on it advise when their device refuses or does not answer."""

    bus: str
    url: str
    timeout: float = 1.0
    hints: tuple[str, ...] = ()
    rate_hz: float = 0.0  # the cycle rate a profile's loop asks of the bus (0: none)


def _no_checks(target: Target) -> list[Check]:
    return []


@dataclass(frozen=True)
class Transport:
    """One kind of link, by URL scheme."""

    scheme: str
    example: str  # how its URL looks, for messages: "tcp://HOST:PORT"
    parse: Callable[[str], Any]  # a URL → its parts; InvalidInput naming what is wrong
    open: Callable[..., Any]  # open(url, **options) → the link (closed with .close())
    checks: Callable[[Target], list[Check]] = _no_checks  # doctor's checks of a target
    host_checks: Callable[[], list[Check]] | None = None  # doctor with no profile or target
    # a traced packet's bus label for a device address on the link (None: the URL itself)
    trace_label: Callable[[str, int | None], str] | None = None
    shared: bool = False  # one link per URL for every block of a System (an I2C bus)


def split_url(url: str) -> SplitResult:
    """``urlsplit``, with a URL it cannot read (``tcp://[::1``: an IPv6 address without its
    closing bracket) one clear error naming it."""
    from urllib.parse import urlsplit

    try:
        return urlsplit(url)
    except ValueError as exc:
        raise InvalidInput(f"{url!r} is not a valid URL ({exc})") from None
