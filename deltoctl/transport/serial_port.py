"""Serial transport over pyserial: ``serial:///dev/ttyUSB0?baud=2000000&rs485=1``."""

from __future__ import annotations

import errno
import os
from typing import TYPE_CHECKING, Any
from urllib.parse import parse_qs

from deltoctl import trace
from deltoctl.errors import DeltoctlError, InvalidInput, Unreachable
from deltoctl.transport import Check, Target, Transport, split_url, url_hint

if TYPE_CHECKING:
    from deltoctl.transport.adapters import SerialAdapter

KEYS = ("baud", "rs485")
MAX_BAUD = 12_000_000
_BOOL = {"1": True, "true": True, "yes": True, "0": False, "false": False, "no": False}


def parse_serial_url(url: str) -> tuple[str, int, bool]:
    """``serial:///dev/PORT?baud=N&rs485=1`` → (path, baud, rs485); an unknown or repeated key,
    a baud that is not a rate, or ``serial://dev/…`` (two slashes) is an error naming it.
    ``usb:VID:PID[:SERIAL]?baud=N`` names the adapter instead of its port: its path is that
    spec, resolved to a port (``port_path``) only when the port is opened or checked."""
    parts = split_url(url)
    if parts.scheme == "usb":
        from deltoctl.transport.adapters import parse_usb

        spec = "usb:" + parts.path
        parse_usb(spec)
    elif parts.scheme != "serial" or not parts.path or parts.netloc:
        raise InvalidInput(f"{url!r} is not a serial target (expected "
                           "serial:///dev/PORT?baud=N[&rs485=1], three slashes)"
                           + url_hint(url, "serial"))
    else:
        spec = parts.path
    query = parse_qs(parts.query, keep_blank_values=True)
    for key, values in query.items():
        if key not in KEYS:
            raise InvalidInput(f"{url!r}: unknown key {key!r} (a serial target takes "
                               f"{', '.join(KEYS)})")
        if len(values) > 1:
            raise InvalidInput(f"{url!r}: {key} is given {len(values)} times")
    text = query.get("baud", ["1000000"])[0]
    if not text.isdigit() or not 0 < int(text) <= MAX_BAUD:
        raise InvalidInput(f"{url!r}: baud must be a rate in bits per second, up to "
                           f"{MAX_BAUD}, got {text!r}")
    flag = query.get("rs485", ["0"])[0].lower()
    if flag not in _BOOL:
        raise InvalidInput(f"{url!r}: rs485 must be 1 or 0, got {flag!r}")
    return spec, int(text), _BOOL[flag]


def port_path(path: str) -> str:
    """The port to open: a path as it is, ``usb:VID:PID[:SERIAL]`` the one adapter's that
    matches (deltoctl.transport.adapters.resolve_usb: exit 4 none, 2 several)."""
    if not path.startswith("usb:"):
        return path
    from deltoctl.transport.adapters import resolve_usb

    return resolve_usb(path)


def adapter_of_target(url: str) -> SerialAdapter | None:
    """The serial adapter a target URL reaches; None for a URL of another transport, or one
    that reaches no adapter (doctor's checks say why)."""
    from deltoctl.transport.adapters import adapter_of

    try:
        return adapter_of(port_path(parse_serial_url(url)[0]))
    except DeltoctlError:
        return None


def stable_hint(url: str) -> str | None:
    """For a target named in plug-in order (/dev/ttyUSB0, /dev/ttyACM0), what names its
    adapter instead; None for any other target."""
    from deltoctl.transport.adapters import ENUMERATED, adapter_of, stable_targets

    try:
        path = parse_serial_url(url)[0]
    except DeltoctlError:
        return None
    if not ENUMERATED.match(os.path.basename(path)):
        return None
    adapter = adapter_of(path)
    choices = stable_targets(url, adapter) if adapter is not None else []
    return (f"{path} is named in plug-in order (a reboot may swap it): name the adapter by "
            + (" or ".join(choices) if choices else "its /dev/serial/by-id/ link or "
               "usb:VID:PID[:SERIAL] (deltoctl ports lists them)"))


# errno of a port another process holds: its flock (pyserial's exclusive), or TIOCEXCL
_BUSY = frozenset({errno.EAGAIN, errno.EWOULDBLOCK, errno.EBUSY})


def holders(path: str) -> list[str]:
    """Who has the port open, ``name (pid N)`` each, as far as /proc lets us see (other users'
    processes need root); empty where there is no /proc."""
    target = os.path.realpath(path)
    found = []
    try:
        pids = [p for p in os.listdir("/proc") if p.isdigit()]
    except OSError:
        return []
    for pid in pids:
        try:
            if not any(os.readlink(f"/proc/{pid}/fd/{fd}") == target
                       for fd in os.listdir(f"/proc/{pid}/fd")):
                continue
            with open(f"/proc/{pid}/comm") as comm:
                name = comm.read().strip()
        except OSError:  # gone meanwhile, or not ours to look at
            continue
        found.append(f"this deltoctl (pid {pid})" if int(pid) == os.getpid()
                     else f"{name} (pid {pid})")
    return found


# pyserial calls termios directly in these; the rest raise OSError (SerialException) already
_TERMIOS_CALLS = ("reset_input_buffer", "reset_output_buffer", "flush")


def _termios_errors_as_oserror(port: Any) -> None:
    """A port whose device went away (an adapter unplugged, a pty whose master closed: EIO)
    fails in ``tcflush``/``tcdrain`` with ``termios.error``, which is no OSError: raised as
    one, like every other failure of the port, so a driver's lost-link path takes it."""
    if os.name != "posix":
        return
    import termios

    def checked(call: Any) -> Any:
        def run() -> None:
            try:
                call()
            except termios.error as exc:
                code, text = exc.args if len(exc.args) == 2 else (errno.EIO, str(exc))
                raise OSError(code, text) from None
        return run

    for name in _TERMIOS_CALLS:
        setattr(port, name, checked(getattr(port, name)))


def open_serial(url: str, timeout: float = 0.05) -> Any:
    """An open pyserial port, locked for this process (two commands cannot share a bus); RS-485
    mode through the kernel where the port supports it."""
    import serial

    spec, baud, rs485 = parse_serial_url(url)
    path = port_path(spec)
    try:
        port = serial.Serial(path, baudrate=baud, timeout=timeout, exclusive=True)
    except (serial.SerialException, OSError) as exc:
        if getattr(exc, "errno", None) in _BUSY:
            who = ", ".join(holders(path)) or "another program"
            raise Unreachable(f"{path} is busy: open in {who}",
                              hint=f"stop it and try again (`fuser -v {path}` lists what "
                                   "holds the port)") from None
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
    _termios_errors_as_oserror(port)
    trace.link("serial %s: open at %d baud%s", path, baud, ", RS-485" if rs485 else "")
    if trace.PACKETS:  # checked once per port: an untraced port keeps its own methods
        trace.trace_serial(port, url)
    return port


_PLUG_IN = "plug the adapter in, then: ls /dev/serial/by-id/"


def _checks(target: Target) -> list[Check]:
    """The port is there (a ``usb:`` target: the one adapter it names), this user may open
    it, no process holds it; its adapter (a stable name, the rate its driver sets, the
    latency timer a loop at the asked rate needs); and (rs485=1) its kernel RS-485 mode."""
    from deltoctl.transport.adapters import adapter_of
    from deltoctl.transport.doctor import adapter_checks, check, device_checks

    spec, baud, rs485 = parse_serial_url(target.url)
    try:
        path = port_path(spec)
    except DeltoctlError as exc:
        return [check("adapter", target.bus, False, exc.message, exc.hint, exc.exit_code)]
    checks = device_checks(target.bus, path, "serial", _PLUG_IN, exclusive=True)
    if not checks[0]["ok"]:
        return checks
    adapter = adapter_of(path)
    if adapter is not None:
        checks += adapter_checks(target, path, adapter, baud)
    return checks + ([_rs485(target.bus, path)] if rs485 else [])


def _rs485(bus: str, path: str) -> Check:
    """The kernel's RS-485 mode of the port (TIOCGRS485), read without sending anything."""
    import fcntl
    import struct

    from deltoctl.transport.doctor import check

    try:
        fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    except OSError as exc:
        return check("rs485", bus, False, f"cannot open {path}: {exc.strerror}", None)
    try:
        flags = struct.unpack("I", fcntl.ioctl(fd, 0x542E, bytes(32))[:4])[0]
    except OSError:
        return check("rs485", bus, True, "no kernel RS-485 mode on this port: the adapter "
                     "must switch direction itself (most USB adapters do)")
    finally:
        os.close(fd)
    state = "on" if flags & 1 else "off (deltoctl turns it on when it opens the port)"
    return check("rs485", bus, True, f"kernel RS-485 mode {state}")


def _host_checks() -> list[Check]:
    """The host's serial adapters (as sysfs lists them), each checked: present, ours, free,
    and its latency timer."""
    from deltoctl.transport.adapters import serial_adapters
    from deltoctl.transport.doctor import adapter_checks, check, device_checks

    adapters = serial_adapters(holders=False)
    if not adapters:
        return [check("present", "serial", False,
                      "no serial adapter (ttyUSB, ttyACM, ttySC, ttyAMA)",
                      "plug the USB/RS-485 adapter in, then: deltoctl ports")]
    return [c for a in adapters
            for c in device_checks(a.name, a.device, "serial", _PLUG_IN, exclusive=True)
            + adapter_checks(Target(a.name, f"serial://{a.device}"), a.device, a, None)]


TRANSPORT = Transport("serial", "serial:///dev/PORT?baud=N", parse_serial_url, open_serial,
                      _checks, _host_checks)
# the adapter by its USB vendor, product and serial number: a port that a reboot cannot swap
USB = Transport("usb", "usb:VID:PID[:SERIAL]?baud=N", parse_serial_url, open_serial, _checks)
