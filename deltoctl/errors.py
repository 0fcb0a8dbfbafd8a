"""The exit codes and their meanings (``deltoctl help exit-codes``), and the errors that carry
their exit code."""

from __future__ import annotations

from typing import Any

OK = 0
FAILED = 1
USAGE = 2
WARNINGS = 3
UNREACHABLE = 4
REFUSED = 5
INTERRUPTED = 130

EXIT_CODES = (
    (OK, "ok"),
    (FAILED, "the device or the operation failed"),
    (USAGE, "usage error or invalid input (bad profile, argument or file)"),
    (WARNINGS, "finished with warnings (reconnects, data gaps, a model mismatch you allowed)"),
    (UNREACHABLE, "device unreachable"),
    (REFUSED, "refused for safety (limit, not homed, no confirmation: a no, or no terminal "
              "and no --yes)"),
    (INTERRUPTED, "interrupted (Ctrl-C, at a confirmation question too)"),
)


class DeltoctlError(Exception):
    """A failure reported to the user as one line, exiting with ``exit_code``."""

    exit_code = FAILED

    def __init__(self, message: str, hint: str | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.hint = hint


class InvalidInput(DeltoctlError):
    """A bad profile, argument or file (exit 2)."""

    exit_code = USAGE


class DeviceError(DeltoctlError):
    """The device or the operation failed (exit 1)."""

    exit_code = FAILED


class Unreachable(DeltoctlError):
    """The device could not be reached (exit 4)."""

    exit_code = UNREACHABLE


class Refused(DeltoctlError):
    """Refused for safety: a limit, not homed, no confirmation (exit 5)."""

    exit_code = REFUSED


class NotHomed(Refused):
    """Refused for safety because a joint is not homed (exit 5)."""


class ProtocolError(DeviceError):
    """Bytes on the wire that do not follow the protocol."""


class NoAnswer(DeviceError):
    """A device that did not answer within its time, after every try the exchange allows."""


class DeviceFault(DeviceError):
    """A device that answered with an error of its own; ``code`` is the error as it sent it."""

    def __init__(self, message: str, code: int, hint: str | None = None) -> None:
        super().__init__(message, hint)
        self.code = code


class LinkLost(DeviceError):
    """A link that went away while in use (a closed connection, an unplugged adapter)."""


class OutsideEnvelope(Refused):
    """A command the safety envelope refuses (a limit, a step, a velocity or an effort)."""


class ProfileError(InvalidInput):
    """A profile problem, located as ``file:line``."""

    def __init__(self, message: str, source: str | None = None, line: int | None = None) -> None:
        where = source or "<profile>"
        if line:
            where = f"{where}:{line}"
        super().__init__(f"{where}: {message}")
        self.source = source
        self.line = line
        self.reason = message


PLOT_EXTRA = "pip install 'deltoctl[plot]'"


def need_plot(module: str) -> Any:
    """A module of the ``deltoctl[plot]`` extra (numpy, plotext, matplotlib), or one clear
    message naming the extra."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise DeltoctlError(f"plot needs {module.split('.')[0]}, which is not installed",
                            f"{PLOT_EXTRA} (plotext for the terminal, matplotlib for --out)") \
            from None
