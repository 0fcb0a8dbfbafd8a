"""Serial transport over pyserial: ``serial:///dev/ttyUSB0?baud=2000000&rs485=1``."""

from __future__ import annotations

from typing import Any
from urllib.parse import parse_qs, urlsplit

from deltoctl.errors import InvalidInput, Unreachable


def parse_serial_url(url: str) -> tuple[str, int, bool]:
    parts = urlsplit(url)
    if parts.scheme != "serial" or not parts.path:
        raise InvalidInput(f"{url!r} is not a serial target (expected "
                           "serial:///dev/PORT?baud=N[&rs485=1])")
    query = parse_qs(parts.query)
    try:
        baud = int(query.get("baud", ["1000000"])[0])
    except ValueError:
        raise InvalidInput(f"{url!r}: baud must be a number") from None
    rs485 = query.get("rs485", ["0"])[0].lower() in ("1", "true", "yes")
    return parts.path, baud, rs485


def open_serial(url: str, timeout: float = 0.05) -> Any:
    """An open pyserial port; RS-485 mode through the kernel where the port supports it."""
    import serial

    path, baud, rs485 = parse_serial_url(url)
    try:
        port = serial.Serial(path, baudrate=baud, timeout=timeout)
    except (serial.SerialException, OSError) as exc:
        raise Unreachable(f"cannot open {path}: {exc}",
                          hint="check the adapter is plugged in and you may use it "
                               "(the dialout group)") from None
    if rs485:
        try:
            import serial.rs485

            port.rs485_mode = serial.rs485.RS485Settings(rts_level_for_tx=True,
                                                         rts_level_for_rx=False)
        except (ValueError, OSError, serial.SerialException):
            port.rs485_mode = None  # e.g. a USB adapter that switches direction itself
    return port
