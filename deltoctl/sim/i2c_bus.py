"""A simulated I2C bus: device models at addresses, behind an object with smbus2's ``SMBus``
methods (``SimSMBus``), shareable with other processes over a loopback socket
(``I2CSocketServer`` serves it, ``SocketSMBus`` is the client behind ``i2c+tcp://``).

A device model has ``write(data)`` (the bytes after the address byte) and ``read(n)``; an
address with no device fails as the kernel does, with EREMOTEIO.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import os
import socket
import struct
import threading
from typing import Protocol

I2C_M_RD = 0x0001
# one wire operation: (address, bytes to write, or None for a read of ``length`` bytes)
Op = tuple[int, bytes | None, int]


class I2CDevice(Protocol):
    def write(self, data: bytes) -> None: ...
    def read(self, length: int) -> bytes: ...


class SMBusMethods:
    """smbus2's ``SMBus`` API on top of one ``transact(ops)``."""

    def transact(self, ops: list[Op]) -> list[bytes]:
        raise NotImplementedError

    def i2c_rdwr(self, *msgs) -> None:  # type: ignore[no-untyped-def]
        ops = [(m.addr, None, m.len) if m.flags & I2C_M_RD else (m.addr, bytes(m), 0)
               for m in msgs]
        replies = iter(self.transact(ops))
        for m in msgs:
            if m.flags & I2C_M_RD:
                data = next(replies)
                ctypes.memmove(m.buf, data, min(len(data), m.len))

    def _read(self, address: int, register: int | None, length: int) -> bytes:
        ops: list[Op] = [] if register is None else [(address, bytes([register]), 0)]
        return self.transact([*ops, (address, None, length)])[0]

    def write_quick(self, i2c_addr: int, force: bool | None = None) -> None:
        self.transact([(i2c_addr, b"", 0)])

    def read_byte(self, i2c_addr: int, force: bool | None = None) -> int:
        return self._read(i2c_addr, None, 1)[0]

    def write_byte(self, i2c_addr: int, value: int, force: bool | None = None) -> None:
        self.transact([(i2c_addr, bytes([value]), 0)])

    def read_byte_data(self, i2c_addr: int, register: int, force: bool | None = None) -> int:
        return self._read(i2c_addr, register, 1)[0]

    def write_byte_data(self, i2c_addr: int, register: int, value: int,
                        force: bool | None = None) -> None:
        self.transact([(i2c_addr, bytes([register, value]), 0)])

    def read_word_data(self, i2c_addr: int, register: int, force: bool | None = None) -> int:
        return int.from_bytes(self._read(i2c_addr, register, 2), "little")

    def write_word_data(self, i2c_addr: int, register: int, value: int,
                        force: bool | None = None) -> None:
        self.transact([(i2c_addr, bytes([register]) + value.to_bytes(2, "little"), 0)])

    def read_i2c_block_data(self, i2c_addr: int, register: int, length: int,
                            force: bool | None = None) -> list[int]:
        return list(self._read(i2c_addr, register, length))

    def write_i2c_block_data(self, i2c_addr: int, register: int, data: list[int],
                             force: bool | None = None) -> None:
        self.transact([(i2c_addr, bytes([register, *data]), 0)])

    def close(self) -> None:
        pass

    def __enter__(self):  # type: ignore[no-untyped-def]
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class SimSMBus(SMBusMethods):
    """Device models at addresses; one transaction at a time, as on a real bus."""

    def __init__(self, devices: dict[int, I2CDevice]) -> None:
        self.devices = devices
        self.lock = threading.Lock()

    def transact(self, ops: list[Op]) -> list[bytes]:
        replies = []
        with self.lock:
            for address, data, length in ops:
                device = self.devices.get(address)
                if device is None:
                    raise OSError(errno.EREMOTEIO, os.strerror(errno.EREMOTEIO))
                if data is None:
                    replies.append(device.read(length))
                else:
                    device.write(data)
        return replies


# -- sharing a simulated bus over loopback ------------------------------------------------------
# request:  u16 length, then per op: u8 kind (0 write, 1 read), u8 address, u16 length, [data]
# response: u16 length, u8 errno (0: ok), the bytes read, concatenated

def _recv_exact(sock: socket.socket, n: int) -> bytes:
    buf = b""
    while len(buf) < n:
        chunk = sock.recv(n - len(buf))
        if not chunk:
            raise ConnectionError("connection closed")
        buf += chunk
    return buf


def _encode_ops(ops: list[Op]) -> bytes:
    body = b"".join(struct.pack("<BBH", 1, a, n) if d is None
                    else struct.pack("<BBH", 0, a, len(d)) + d for a, d, n in ops)
    return struct.pack("<H", len(body)) + body


def _decode_ops(body: bytes) -> list[Op]:
    ops: list[Op] = []
    k = 0
    while k < len(body):
        kind, address, n = struct.unpack_from("<BBH", body, k)
        k += 4
        if kind:
            ops.append((address, None, n))
        else:
            ops.append((address, body[k:k + n], 0))
            k += n
    return ops


class SocketSMBus(SMBusMethods):
    """The client side of ``i2c+tcp://HOST:PORT``."""

    def __init__(self, host: str, port: int) -> None:
        self.sock = socket.create_connection((host, port), timeout=2.0)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    def transact(self, ops: list[Op]) -> list[bytes]:
        try:
            self.sock.sendall(_encode_ops(ops))
            (n,) = struct.unpack("<H", _recv_exact(self.sock, 2))
            reply = _recv_exact(self.sock, n)
        except OSError as exc:
            raise OSError(errno.EIO, f"simulated bus: {exc}") from None
        if reply[0]:
            raise OSError(reply[0], os.strerror(reply[0]))
        data, out, k = reply[1:], [], 0
        for _, d, length in ops:
            if d is None:
                out.append(data[k:k + length])
                k += length
        return out

    def close(self) -> None:
        self.sock.close()


class I2CSocketServer:
    """Serves a ``SimSMBus`` on loopback TCP; ``url`` is the target other processes use."""

    def __init__(self, bus: SimSMBus, host: str = "127.0.0.1", port: int = 0) -> None:
        self.bus = bus
        self.listener = socket.create_server((host, port))
        host, port = self.listener.getsockname()[:2]
        self.url = f"i2c+tcp://{host}:{port}"
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._accept, name="i2c-sim", daemon=True)

    def start(self) -> I2CSocketServer:
        self._thread.start()
        return self

    def _accept(self) -> None:
        self.listener.settimeout(0.2)
        while not self._stop.is_set():
            try:
                conn, _ = self.listener.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            threading.Thread(target=self._serve, args=(conn,), daemon=True).start()

    def _serve(self, conn: socket.socket) -> None:
        with conn, contextlib.suppress(OSError, ConnectionError):
            conn.settimeout(None)
            while not self._stop.is_set():
                (n,) = struct.unpack("<H", _recv_exact(conn, 2))
                ops = _decode_ops(_recv_exact(conn, n))
                try:
                    reply = b"\0" + b"".join(self.bus.transact(ops))
                except OSError as exc:
                    reply = bytes([exc.errno or errno.EIO])
                conn.sendall(struct.pack("<H", len(reply)) + reply)

    def close(self) -> None:
        self._stop.set()
        self.listener.close()
        self._thread.join(timeout=1)

    def __enter__(self) -> I2CSocketServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()



def bus_for_profile(profile, missing: tuple[int, ...] = ()) -> SimSMBus:  # type: ignore[no-untyped-def]
    """Every I2C device of the profile on one simulated bus: the Bioscara joints and the
    LSM6DS3 chips, at their addresses (less the ``missing`` ones)."""
    from deltoctl.families.bioscara.emulator import joints_for_profile
    from deltoctl.families.lsm6ds3.emulator import Lsm6ds3Chip

    devices: dict[int, I2CDevice] = dict(joints_for_profile(profile))
    for hw in profile.hardware:
        if profile.family_of(hw) == "lsm6ds3":
            devices.update({s.address: Lsm6ds3Chip() for s in hw.sensors
                            if s.address is not None})
    return SimSMBus({a: d for a, d in devices.items() if a not in missing})
