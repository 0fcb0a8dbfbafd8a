"""The client side of a simulated I2C bus shared over loopback (``i2c+tcp://HOST:PORT``, served by
``deltoctl sim serve``): an object with smbus2's ``SMBus`` methods, like a kernel bus.

Wire format: request ``u16 length`` then per operation ``u8 kind (0 write, 1 read), u8 address,
u16 length, [data]``; response ``u16 length, u8 errno (0: ok)``, then the bytes read.
"""

from __future__ import annotations

import ctypes
import errno
import os
import socket
import struct
from typing import Any

I2C_M_RD = 0x0001
# one wire operation: (address, bytes to write, or None for a read of ``length`` bytes)
Op = tuple[int, bytes | None, int]


class SMBusMethods:
    """smbus2's ``SMBus`` API on top of one ``transact(ops)``."""

    def transact(self, ops: list[Op]) -> list[bytes]:
        raise NotImplementedError

    def i2c_rdwr(self, *msgs: Any) -> None:
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

    def __enter__(self) -> SMBusMethods:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def recv_exact(sock: socket.socket, n: int) -> bytes:
    buf = b""
    while len(buf) < n:
        chunk = sock.recv(n - len(buf))
        if not chunk:
            raise ConnectionError("connection closed")
        buf += chunk
    return buf


def encode_ops(ops: list[Op]) -> bytes:
    body = b"".join(struct.pack("<BBH", 1, a, n) if d is None
                    else struct.pack("<BBH", 0, a, len(d)) + d for a, d, n in ops)
    return struct.pack("<H", len(body)) + body


def decode_ops(body: bytes) -> list[Op]:
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
            self.sock.sendall(encode_ops(ops))
            (n,) = struct.unpack("<H", recv_exact(self.sock, 2))
            reply = recv_exact(self.sock, n)
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
