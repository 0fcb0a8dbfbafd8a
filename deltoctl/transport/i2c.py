"""I2C transport over smbus2: ``i2c:///dev/i2c-1`` (a kernel bus) or ``i2c+tcp://HOST:PORT``
(a simulated bus that ``deltoctl sim serve`` shares over loopback).

Both give an object with smbus2's ``SMBus`` methods; ``I2CBus`` adds what the drivers need:
combined transactions (write, repeated start, read), one try each (a driver's exchange policy
tries again), the bus's counters, and one clear message for a missing bus, a device that does
not answer, or a permission problem.
"""

from __future__ import annotations

import errno
from collections.abc import Callable
from typing import Any
from urllib.parse import parse_qsl

from smbus2 import i2c_msg

from deltoctl import trace
from deltoctl.errors import DeviceError, InvalidInput, NoAnswer, Unreachable
from deltoctl.transport import Check, Target, Transport, split_url, url_hint

# errnos of a device that did not acknowledge: NoAnswer (also importable from here)
NO_ANSWER = (errno.ENXIO, errno.EREMOTEIO, errno.EIO, errno.ETIMEDOUT, errno.EAGAIN)


def parse_i2c_url(url: str) -> tuple[str, str, int]:
    """``(kind, path_or_host, port)`` with kind ``dev`` or ``tcp``; a query key, a host on a
    kernel bus or a bad port is an error naming it."""
    parts = split_url(url)
    expected = "expected i2c:///dev/i2c-N or i2c+tcp://HOST:PORT from `deltoctl sim serve`"
    if parts.scheme not in ("i2c", "i2c+tcp"):
        raise InvalidInput(f"{url!r} is not an I2C target ({expected})" + url_hint(url, "i2c"))
    keys = [key for key, _ in parse_qsl(parts.query, keep_blank_values=True)]
    if keys:
        raise InvalidInput(f"{url!r}: unknown key {keys[0]!r} (an I2C target takes no keys)")
    if parts.scheme == "i2c" and parts.netloc:
        raise InvalidInput(f"{url!r}: {parts.netloc!r} is read as a host; {expected} "
                           "(three slashes)")
    if parts.scheme == "i2c" and parts.path and not parts.fragment:
        return "dev", parts.path, 0
    if parts.scheme == "i2c+tcp" and parts.hostname and parts.path in ("", "/"):
        try:
            port = parts.port
        except ValueError:
            port = 0
        if port == 0:
            raise InvalidInput(f"{url!r}: the port must be a number from 1 to 65535")
        if port is not None:
            return "tcp", parts.hostname, port
    raise InvalidInput(f"{url!r} is not an I2C target ({expected})")


def open_smbus(url: str) -> Any:
    """An SMBus-compatible object for the URL; Unreachable with what to do when it fails."""
    kind, where, port = parse_i2c_url(url)
    if kind == "tcp":
        from deltoctl.transport.i2c_socket import SocketSMBus

        try:
            return SocketSMBus(where, port)
        except OSError as exc:
            raise Unreachable(f"cannot reach the simulated I2C bus {url}: {exc.strerror or exc}",
                              hint="is `deltoctl sim serve` still running?") from None
    from smbus2 import SMBus

    try:
        return SMBus(where)
    except FileNotFoundError:
        raise Unreachable(f"no I2C bus {where}",
                          hint="enable I2C (Raspberry Pi: dtparam=i2c_arm=on) and load the "
                               "i2c-dev module") from None
    except PermissionError:
        raise Unreachable(f"no permission to open {where}",
                          hint="add the user to the i2c group, then log in again") from None
    except OSError as exc:
        raise Unreachable(f"cannot open {where}: {exc.strerror}") from None


class I2CBus:
    """Transactions on one bus, one try each. ``stats`` are the bus's counters, shared by the
    drivers on it: ``bytes`` moved (counted here), ``packets`` and ``errors`` (counted by the
    exchange that runs the tries: a transaction once, each failed try)."""

    def __init__(self, smbus: Any, url: str) -> None:
        self.smbus = smbus
        self.url = url
        self.stats = {"packets": 0, "errors": 0, "bytes": 0}
        self._writes: dict[tuple[int, bytes], object] = {}  # reused messages for fixed requests
        self._reads: dict[tuple[int, int], object] = {}
        trace.link("i2c %s: open", url)
        if trace.PACKETS:  # checked once per bus: an untraced bus's methods stay as they are
            trace.trace_i2c(self)

    def _message(self, address: int, data: bytes) -> Any:
        key = (address, data)
        msg = self._writes.get(key)
        if msg is None:
            msg = i2c_msg.write(address, data)
            if len(self._writes) < 256:
                self._writes[key] = msg
        return msg

    def _run(self, address: int, *msgs: Any) -> None:
        """One transaction: NoAnswer when the device does not acknowledge, DeviceError for
        any other failure of the adapter."""
        self.stats["bytes"] += sum(len(m) + 1 for m in msgs)  # payload + address byte
        try:
            self.smbus.i2c_rdwr(*msgs)
        except OSError as exc:
            if exc.errno not in NO_ANSWER:
                raise DeviceError(f"I2C transfer to {address:#04x} on {self.url} failed: "
                                  f"{exc.strerror or exc}") from None
            raise NoAnswer(f"no answer from {address:#04x} on {self.url}",
                           hint="check the device's power, wiring and address") from None

    def transfer(self, address: int, write: bytes, read: int) -> bytes:
        """Write ``write``, repeated start, read ``read`` bytes: one combined transaction."""
        key = (address, read)
        reply = self._reads.get(key)
        if reply is None:
            reply = self._reads[key] = i2c_msg.read(address, read)
        self._run(address, self._message(address, write), reply)
        return bytes(reply)

    def write(self, address: int, data: bytes) -> None:
        self._run(address, self._message(address, data))

    def probe(self, address: int) -> bool:
        """Whether a device acknowledges its address (a one-byte read, as ``i2cdetect -r``)."""
        try:
            self.smbus.i2c_rdwr(i2c_msg.read(address, 1))
            return True
        except OSError:
            return False

    def close(self) -> None:
        trace.link("i2c %s: closed", self.url)
        self.smbus.close()


# an exchange policy's run (deltoctl.core.exchange): attempt, what it is, failures tallied
PolicyRun = Callable[[Callable[[], bytes], str, dict[str, int]], bytes]


def exchange(bus: I2CBus, address: int, attempt: Callable[[], bytes], run: PolicyRun,
             tries: int) -> bytes:
    """One transaction with the device at ``address``, ``attempt`` tried as ``run`` (an
    exchange policy's, of ``tries`` tries) tries it: the bus counts it once in ``packets``
    and each failed try in ``errors``; no answer is one NoAnswer naming the device and bus."""
    failed: dict[str, int] = {}
    bus.stats["packets"] += 1
    try:
        return run(attempt, f"{address:#04x}", failed)
    except NoAnswer:
        raise NoAnswer(f"no answer from {address:#04x} on {bus.url} ({tries} tries)",
                       hint="check the device's power, wiring and address") from None
    except DeviceError:
        failed["errors"] = failed.get("errors", 0) + 1
        raise
    finally:
        bus.stats["errors"] += failed.get("errors", 0)


def wire_bits(write: int, read: int) -> int:
    """Bits on the wire for a combined transaction: 9 bits per byte (8 + ACK), the address
    byte sent twice (write, then after the repeated start, read)."""
    return 9 * (write + 1 + (read + 1 if read else 0))


_MODPROBE = "sudo modprobe i2c-dev   (Raspberry Pi: dtparam=i2c_arm=on in config.txt)"


def _open(url: str) -> I2CBus:
    return I2CBus(open_smbus(url), url)


def _kernel_checks(target: Target) -> list[Check]:
    from deltoctl.transport.doctor import device_checks

    return device_checks(target.bus, parse_i2c_url(target.url)[1], "i2c", _MODPROBE)


def _simulated_checks(target: Target) -> list[Check]:
    from deltoctl.transport.doctor import reach

    _, host, port = parse_i2c_url(target.url)
    return [reach(target, host, port)]


def _host_checks() -> list[Check]:
    """The host's I2C buses (under DELTOCTL_SYSFS_ROOT when it is set), each checked."""
    from deltoctl.transport.adapters import root, under
    from deltoctl.transport.doctor import present_nodes

    return present_nodes((under(root(), "/dev/i2c-*"),), "i2c", "no I2C bus (/dev/i2c-*)",
                         "sudo modprobe i2c-dev   (Raspberry Pi: dtparam=i2c_arm=on)",
                         _MODPROBE)


def trace_label(url: str, address: int | None) -> str:
    """A device's packets on a bus several devices share are labelled by its address."""
    return url if address is None else f"{url} @{address:#04x}"


KERNEL = Transport("i2c", "i2c:///dev/i2c-N", parse_i2c_url, _open, _kernel_checks,
                   _host_checks, trace_label, shared=True)
SIMULATED = Transport("i2c+tcp", "i2c+tcp://HOST:PORT", parse_i2c_url, _open,
                      _simulated_checks, None, trace_label, shared=True)
