"""Transports: bytes moved over TCP, a serial port or an I2C bus, chosen by URL."""

from __future__ import annotations

from typing import TYPE_CHECKING

from deltoctl.errors import InvalidInput

if TYPE_CHECKING:
    from urllib.parse import SplitResult


def split_url(url: str) -> SplitResult:
    """``urlsplit``, with a URL it cannot read (``tcp://[::1``: an IPv6 address without its
    closing bracket) one clear error naming it."""
    from urllib.parse import urlsplit

    try:
        return urlsplit(url)
    except ValueError as exc:
        raise InvalidInput(f"{url!r} is not a valid URL ({exc})") from None
