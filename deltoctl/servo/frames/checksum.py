"""The checksum frame of Dynamixel Protocol 1.0 and Feetech (STS/SMS/SCS), sans-I/O.

Frame: ``FF FF | ID | LEN | INST | params | CHECKSUM``; a status has the servo's error byte
where a request has its instruction. LEN counts INST (or the error byte), the params and the
checksum; the checksum is ``~(ID + LEN + INST + Σ params) & 0xFF``. 0xFE is the broadcast ID; a
frame is at most 250 bytes. A reader resynchronises on noise as the vendors' SDKs do: a header
whose ID is 0xFF or whose length is out of bounds, or a frame whose checksum does not check, is
passed by one byte and the search for ``FF FF`` goes on from there. Reference:
feetech-sts-and-lerobot.md §1.1, §1.3, §1.5.
"""

from __future__ import annotations

from deltoctl.errors import ProtocolError
from deltoctl.servo import frames
from deltoctl.servo.frames import Frame, Reply

HEADER = b"\xff\xff"
BROADCAST_ID = 0xFE
MAX_ID = 0xFC
MAX_FRAME = 250  # bytes of a whole frame (the SDKs' TX/RX packet limit)

INCOMPLETE, NOT_A_FRAME, BAD_CHECKSUM = 0, -1, -2

# the instructions Dynamixel Protocol 1.0 and Feetech share, with the same codes and params
# (one-byte address and length); each family's set adds its own (RESET, BULK_READ, SYNC_READ)
PING, READ, WRITE, REG_WRITE, ACTION, SYNC_WRITE = 0x01, 0x02, 0x03, 0x04, 0x05, 0x83


def checksum(data: bytes, start: int = 0, end: int | None = None) -> int:
    """``~Σ data[start:end] & 0xFF``: over ID, LEN, INST (or error) and the params."""
    return ~sum(data[start:end]) & 0xFF


def frame(device_id: int, code: int, params: bytes = b"") -> bytes:
    """A request (``code`` its instruction) or a status (``code`` its error byte)."""
    if not 0 <= device_id <= BROADCAST_ID:
        raise ValueError(f"ID {device_id} is not 0..253 or 254 (broadcast)")
    if len(params) + 6 > MAX_FRAME:
        raise ValueError(f"{len(params)} bytes of params: a frame holds at most "
                         f"{MAX_FRAME - 6}")
    body = bytes((device_id, len(params) + 2, code)) + params
    return HEADER + body + bytes((checksum(body),))


def read_params(address: int, length: int) -> bytes:
    return bytes((address, length))


def write_params(address: int, data: bytes) -> bytes:
    return bytes((address,)) + data


def sync_write_params(address: int, length: int, data: dict[int, bytes]) -> bytes:
    params = bytearray((address, length))
    for device_id, values in data.items():
        if len(values) != length:
            raise ValueError(f"sync write to ID {device_id}: {len(values)} bytes, not {length}")
        params += bytes((device_id,)) + values
    return bytes(params)


def ping(device_id: int = BROADCAST_ID) -> bytes:
    return frame(device_id, PING)


def read(device_id: int, address: int, length: int) -> bytes:
    return frame(device_id, READ, read_params(address, length))


def write(device_id: int, address: int, data: bytes) -> bytes:
    return frame(device_id, WRITE, write_params(address, data))


def reg_write(device_id: int, address: int, data: bytes) -> bytes:
    return frame(device_id, REG_WRITE, write_params(address, data))


def action(device_id: int = BROADCAST_ID) -> bytes:
    return frame(device_id, ACTION)


def sync_write(address: int, length: int, data: dict[int, bytes]) -> bytes:
    return frame(BROADCAST_ID, SYNC_WRITE, sync_write_params(address, length, data))


def _size_at(data: bytes | bytearray, at: int) -> int:
    """The size of the frame whose header is at ``at``; INCOMPLETE while its bytes are not all
    in, NOT_A_FRAME for a header no frame has, BAD_CHECKSUM."""
    if len(data) < at + 4:
        return INCOMPLETE
    length = data[at + 3]
    if data[at + 2] == 0xFF or length < 2 or length + 4 > MAX_FRAME:
        return NOT_A_FRAME
    end = at + 4 + length
    if len(data) < end:
        return INCOMPLETE
    if checksum(data, at + 2, end - 1) != data[end - 1]:
        return BAD_CHECKSUM
    return end - at


def _frame(data: bytes | bytearray, at: int, size: int) -> Frame:
    return data[at + 2], data[at + 4], bytes(data[at + 5:at + size - 1])


class ChecksumReader:
    """Finds frames in a byte stream: ``feed(data)`` returns (ID, instruction or error,
    params) per frame whose checksum checks; a bad checksum raises ProtocolError once the
    frames before it are returned (the next ``feed``, with more bytes or none, raises it and
    the one after goes on past it)."""

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> list[Frame]:
        buf = self._buf
        buf += data
        out: list[Frame] = []
        while True:
            start = buf.find(HEADER)
            if start < 0:
                del buf[:len(buf) - 1 if buf[-1:] == b"\xff" else len(buf)]
                return out
            del buf[:start]
            size = _size_at(buf, 0)
            if size == INCOMPLETE:
                return out
            if size == BAD_CHECKSUM and out:
                return out  # the frames before it first; the next feed raises
            if size < 0:
                device_id = buf[2]
                del buf[:1]
                if size == BAD_CHECKSUM:
                    raise ProtocolError(f"checksum mismatch in a frame from ID {device_id}")
                continue
            out.append(_frame(buf, 0, size))
            del buf[:size]

    def reset(self) -> None:
        self._buf.clear()


def status(device_id: int, error: int = 0, data: bytes = b"") -> bytes:
    return frame(device_id, error, data)


def as_status(found: Frame) -> Reply:
    """A frame read by a host as a status: its error byte is at most 0x7F (a higher one is
    an instruction, such as a sync read heard back on a half-duplex line)."""
    device_id, error, data = found
    if error > 0x7F:
        raise ProtocolError(f"a frame from ID {device_id} with instruction {error:#04x} where a "
                            "status was expected")
    return device_id, error, data


def split_statuses(data: bytes) -> list[Reply]:
    """The statuses in ``data`` in whatever shape they came: a frame that does not check is
    passed by one byte, so it costs only itself."""
    out, at = [], 0
    while True:
        at = data.find(HEADER, at)
        if at < 0:
            return out
        size = _size_at(data, at)
        if size == INCOMPLETE:
            return out
        if size < 0:
            at += 1
            continue
        device_id, error, params = _frame(data, at, size)
        if error <= 0x7F:
            out.append((device_id, error, params))
        at += size


def status_at(data: bytes, offset: int, length: int, device_id: int) -> Reply | bool | None:
    """The common case of a sync read's reply — the expected servo, in order, ``length``
    bytes of data — read in place: ``(id, error, data)``; False for a bad checksum; None when
    the bytes do not have that shape (a short status, an instruction heard back, noise)."""
    end = offset + 6 + length
    if len(data) < end or not data.startswith(
            HEADER + bytes((device_id, length + 2)), offset) or data[offset + 4] > 0x7F:
        return None
    if checksum(data, offset + 2, end - 1) != data[end - 1]:
        return False
    return device_id, data[offset + 4], bytes(data[offset + 5:end - 1])


class SyncReplies(frames.SyncReplies):
    """The replies to one sync read, checked in place as they arrive (deltoctl.servo.frames)."""

    overhead = 6
    status_at = staticmethod(status_at)
    split = staticmethod(split_statuses)


def error_words(error: int, names: dict[int, str]) -> list[str]:
    """The names of the bits set in a status's error byte (``names``: bit → name, the
    family's), an unnamed bit as ``bit N``."""
    return [names.get(bit, f"bit {bit}") for bit in range(8) if error >> bit & 1]


class ChecksumFrames:
    """The checksum frame as a session's frame variant (addresses and lengths of one byte)."""

    name = "checksum frame (Dynamixel Protocol 1.0, Feetech)"
    broadcast_id = BROADCAST_ID
    address_size = 1

    def request(self, device_id: int, instruction: int, params: bytes = b"") -> bytes:
        return frame(device_id, instruction, params)

    def status(self, device_id: int, error: int = 0, data: bytes = b"") -> bytes:
        return frame(device_id, error, data)

    def request_size(self, params: int) -> int:
        return 6 + params

    def status_size(self, length: int) -> int:
        return 6 + length

    def reader(self) -> ChecksumReader:
        return ChecksumReader()

    def as_status(self, found: Frame) -> Reply:
        return as_status(found)

    def split(self, data: bytes) -> list[Reply]:
        return split_statuses(data)

    def sync_replies(self, length: int, ids: list[int]) -> SyncReplies:
        return SyncReplies(length, ids)

    def combined_size(self, servos: int, length: int) -> int:
        raise ProtocolError("the checksum frame has no Fast Sync Read")

    def split_combined(self, data: bytes, length: int, ids: list[int]) -> list[Reply]:
        raise ProtocolError("the checksum frame has no Fast Sync Read")

    def combined(self, blocks: list[tuple[int, int, bytes]]) -> bytes:
        raise ProtocolError("the checksum frame has no Fast Sync Read")


FRAMES = ChecksumFrames()
