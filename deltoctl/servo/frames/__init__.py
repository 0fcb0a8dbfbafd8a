"""The frame variants of servo buses, sans-I/O: ``dxl2`` (Dynamixel Protocol 2.0: ``FF FF FD
00``, CRC-16, byte stuffing) and ``checksum`` (``FF FF ID LEN INST params CHECKSUM``, of
Dynamixel Protocol 1.0 and Feetech). Each module's ``FRAMES`` is the variant a session runs:
requests and statuses out, a reader that finds frames in a noisy stream, statuses split."""

from __future__ import annotations

from typing import Protocol

Frame = tuple[int, int, bytes]  # (ID, instruction or error byte, the rest), as a reader finds it
Reply = tuple[int, int, bytes]  # a status: (ID, error, data)


class Reader(Protocol):
    def feed(self, data: bytes) -> list[Frame]: ...

    def reset(self) -> None: ...


class Frames(Protocol):
    """What a session needs of a frame variant. A variant with a Fast Sync Read adds
    ``combined_size(servos, length)``, ``split_combined(data, length, ids)`` and
    ``combined(blocks)``; one whose sync replies are checked in place as they arrive adds
    ``sync_replies(length, ids)`` (Protocol 2.0 has both)."""

    name: str
    broadcast_id: int
    address_size: int  # bytes of a control-table address (and of a length) in a request

    def request(self, device_id: int, instruction: int, params: bytes = b"") -> bytes: ...

    def status(self, device_id: int, error: int = 0, data: bytes = b"") -> bytes: ...

    def request_size(self, params: int) -> int:
        """The bytes of a request with ``params`` bytes of params (nothing stuffed)."""
        ...

    def status_size(self, length: int) -> int:
        """The bytes of a status with ``length`` bytes of data (nothing stuffed)."""
        ...

    def reader(self) -> Reader: ...

    def as_status(self, frame: Frame) -> Reply:
        """A frame a host read as a status; ProtocolError when it is none."""
        ...

    def split(self, data: bytes) -> list[Reply]:
        """The valid statuses in ``data``, whatever its shape: a bad one costs only itself."""
        ...
