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


class SyncCheck(Protocol):
    """The replies to one sync read checked in place as their bytes arrive: ``found`` holds
    (id, error, data) per reply in order (False for one that does not check) while
    ``in_shape`` (each the expected servo's, nothing stuffed)."""

    found: list
    in_shape: bool
    ids: list[int]

    def feed(self, data: bytes) -> None: ...


class SyncReplies:
    """The replies to one sync read, checked as their bytes arrive: ``feed`` the bytes so far
    while later replies are still on the wire, then ``result`` once all are in (or the time
    is up). While each is the expected servo's status with the data asked for they are read
    by their offsets (a status of ``overhead`` bytes besides its data, checked by the
    variant's ``status_at``); anything else is left to the variant's ``split``."""

    overhead = 0

    def __init__(self, length: int, ids: list[int]) -> None:
        self.length, self.ids, self.size = length, ids, self.overhead + length
        self.found: list = []  # (id, error, data), or False for one that does not check
        self.in_shape = True

    @staticmethod
    def status_at(data: bytes, offset: int, length: int, device_id: int) -> Reply | bool | None:
        """The expected status at ``offset``, False when it does not check, None when what
        is there is not that servo's status."""
        raise NotImplementedError

    @staticmethod
    def split(data: bytes) -> list[Reply]:
        raise NotImplementedError

    def feed(self, data: bytes) -> None:
        found, ids, size, length = self.found, self.ids, self.size, self.length
        k, whole = len(found), min(len(data) // size, len(ids))
        while k < whole and self.in_shape:
            reply = self.status_at(data, k * size, length, ids[k])
            if reply is None:
                self.in_shape = False
            else:
                found.append(reply)
                k += 1

    def result(self, data: bytes) -> list[Reply]:
        self.feed(data)
        if self.in_shape and len(self.found) == len(self.ids):
            return [r for r in self.found if r]
        return self.split(data)


class Frames(Protocol):
    """What a session needs of a frame variant."""

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

    def sync_replies(self, length: int, ids: list[int]) -> SyncCheck | None:
        """The in-place check of a sync read's replies (None: ``split`` them)."""
        ...

    def combined_size(self, servos: int, length: int) -> int:
        """The bytes of a Fast Sync Read's one status (a variant without: ProtocolError)."""
        ...

    def split_combined(self, data: bytes, length: int, ids: list[int]) -> list[Reply]:
        """A Fast Sync Read's status as (id, error, data) per servo."""
        ...

    def combined(self, blocks: list[tuple[int, int, bytes]]) -> bytes:
        """A Fast Sync Read's status of (error, id, data) blocks."""
        ...
