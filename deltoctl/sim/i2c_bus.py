"""A simulated I2C bus: device models at addresses, behind an object with smbus2's ``SMBus``
methods (``SimSMBus``), shareable with other processes over a loopback socket
(``I2CSocketServer`` serves it; ``deltoctl.transport.i2c_socket.SocketSMBus`` is the client
behind ``i2c+tcp://``).

A device model has ``write(data)`` (the bytes after the address byte) and ``read(n)``; an
address with no device fails as the kernel does, with EREMOTEIO.
"""

from __future__ import annotations

import contextlib
import errno
import os
import socket
import struct
import threading
from typing import Protocol

from deltoctl.transport.i2c_socket import Op, SMBusMethods, decode_ops, recv_exact


class I2CDevice(Protocol):
    def write(self, data: bytes) -> None: ...
    def read(self, length: int) -> bytes: ...


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


class I2CSocketServer:
    """Serves a ``SimSMBus`` on loopback TCP; ``url`` is the target other processes use."""

    def __init__(self, bus: SimSMBus, host: str = "127.0.0.1", port: int = 0) -> None:
        self.bus = bus
        self.listener = socket.create_server((host, port))
        host, port = self.listener.getsockname()[:2]
        self.url = f"i2c+tcp://{host}:{port}"
        self._stop = threading.Event()
        self.listener.settimeout(0.2)  # here, not in the thread: a close may come first
        self._thread = threading.Thread(target=self._accept, name="i2c-sim", daemon=True)

    def start(self) -> I2CSocketServer:
        self._thread.start()
        return self

    def _accept(self) -> None:
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
                (n,) = struct.unpack("<H", recv_exact(conn, 2))
                ops = decode_ops(recv_exact(conn, n))
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
