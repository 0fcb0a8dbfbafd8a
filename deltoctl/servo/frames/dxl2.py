"""Dynamixel Protocol 2.0 frames, sans-I/O.

Packet: ``FF FF FD 00 | ID | LEN_L LEN_H | INST | params | CRC_L CRC_H``; a status packet has
INST 0x55 and an ERR byte before its params. LEN counts INST, params and the CRC. Between INST
and the CRC every ``FF FF FD`` is stuffed to ``FF FF FD FD``; the CRC (CRC-16/BUYPASS: poly
0x8005, init 0, no reflection) covers the stuffed packet. A sync read's replies are checked in
place as they arrive (``SyncReplies``); a Fast Sync Read's come as one status holding a block
per servo. Reference: bioscara-mh5-dynamixel.md §3.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass

from deltoctl.errors import ProtocolError
from deltoctl.servo import frames
from deltoctl.servo.frames import Frame, Reply

HEADER = b"\xff\xff\xfd\x00"
BROADCAST_ID = 0xFE
MAX_ID = 0xFC
STATUS = 0x55  # the instruction of a status packet
# The longest LEN of a packet of ours: a Fast Sync Read reply of the 10-byte PVL from every ID
# (INST, [ERR, ID, data, CRC] a servo), stuffed at every chance (a byte more in three). A
# header with a longer one is noise: the reader passes it by instead of waiting for 64 KiB.
MAX_LENGTH = (1 + (MAX_ID + 1) * (2 + 10 + 2)) * 4 // 3 + 2

STATUS_ERRORS = {1: "result fail", 2: "instruction error", 3: "CRC error",
                 4: "data range error", 5: "data length error", 6: "data limit error",
                 7: "access error"}


def _crc_table() -> list[int]:
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) if crc & 0x8000 else crc << 1
        table.append(crc & 0xFFFF)
    return table


_TABLE = _crc_table()
_TABLE16: list[int] | None = None  # two bytes a step; built on first use (about 10 ms)


def _table16() -> list[int]:
    # the register is 16 bits wide, so after two bytes it is the table entry of
    # (register ^ the two bytes): T16[w] = T8-step of the high byte, then of the low byte.
    # Built whole, then published: buses configured in parallel threads never see it half-made.
    global _TABLE16
    t = _TABLE
    _TABLE16 = [((t[hi] << 8) & 0xFFFF) ^ t[(t[hi] >> 8) ^ lo]
                for hi in range(256) for lo in range(256)]
    return _TABLE16


_WORDS: dict[int, Callable[..., tuple[int, ...]]] = {}  # n → unpack_from of n words (n ≤ 64)


def crc16(data: bytes, crc: int = 0, start: int = 0, end: int | None = None) -> int:
    """CRC-16 (polynomial 0x8005, not reflected) of the Dynamixel protocol, of
    ``data[start:end]`` (read in place: a reply is checked where it lies in the buffer)."""
    table = _TABLE16 or _table16()
    if end is None:
        end = len(data)
    n = (end - start) >> 1
    words = _WORDS.get(n)
    if words is None:
        words = struct.Struct(f">{n}H").unpack_from
        if n <= 64:  # a packet of the sync loops; longer ones are rare
            _WORDS[n] = words
    for word in words(data, start):
        crc = table[crc ^ word]
    if (end - start) & 1:
        crc = ((crc << 8) ^ _TABLE[(crc >> 8) ^ data[end - 1]]) & 0xFFFF
    return crc


def stuff(body: bytes) -> bytes:
    return body.replace(b"\xff\xff\xfd", b"\xff\xff\xfd\xfd")


def unstuff(body: bytes) -> bytes:
    return body.replace(b"\xff\xff\xfd\xfd", b"\xff\xff\xfd")


def packet(device_id: int, instruction: int, params: bytes = b"") -> bytes:
    """An instruction (or, with STATUS, a status) packet with stuffing and CRC."""
    if not 0 <= device_id <= BROADCAST_ID or device_id in (0xFD,):
        raise ValueError(f"ID {device_id} is not 0..252 or 254 (broadcast)")
    body = stuff(bytes([instruction]) + params)
    head = HEADER + bytes([device_id]) + struct.pack("<H", len(body) + 2)
    crc = crc16(head + body)
    return head + body + struct.pack("<H", crc)


@dataclass(frozen=True)
class Status:
    """A status packet: its ID, error byte (bit 7: a hardware alert) and data."""

    id: int
    error: int
    params: bytes

    @property
    def alert(self) -> bool:
        """Bit 7: read Hardware Error Status (70) for the cause."""
        return bool(self.error & 0x80)

    def error_text(self) -> str | None:
        code = self.error & 0x7F
        if not code and not self.alert:
            return None
        words = [STATUS_ERRORS.get(code, f"error {code}")] if code else []
        if self.alert:
            words.append("hardware alert")
        return ", ".join(words)


_HEADS: dict[tuple[int, int], tuple[bytes, int]] = {}  # (ID, data length) → see _status_head


def _status_head(device_id: int, length: int) -> tuple[bytes, int]:
    """The first 8 bytes of a status packet from ``device_id`` with ``length`` bytes of data
    (nothing stuffed), and their CRC: the same for every reply of a sync loop, so built once
    (for the first few thousand kinds) and the CRC of each reply goes on from there."""
    head = _HEADS.get((device_id, length))
    if head is None:
        size = length + 4  # INST, ERR, data, CRC
        prefix = HEADER + bytes((device_id, size & 0xFF, size >> 8, STATUS))
        head = (prefix, crc16(prefix))
        if len(_HEADS) < 4096:
            _HEADS[device_id, length] = head
    return head


def status(device_id: int, error: int = 0, params: bytes = b"") -> bytes:
    """The emulator's side: a status packet (as ``packet`` with STATUS builds it; a bus
    answers a sync read of N servos with N of them, so the common case goes faster)."""
    body = bytes((error,)) + params
    if not (0 <= device_id <= MAX_ID or device_id == BROADCAST_ID) or b"\xff\xff\xfd" in body:
        return packet(device_id, STATUS, body)
    head, crc = _status_head(device_id, len(params))
    crc = crc16(body, crc)
    return head + body + bytes((crc & 0xFF, crc >> 8))


class PacketReader:
    """Finds packets in a byte stream: ``feed(data)`` returns (id, instruction, body) tuples
    whose CRC checks; a bad CRC raises ProtocolError (the bytes are dropped) once the packets
    before it are returned (the next ``feed``, with more bytes or none, raises it)."""

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> list[Frame]:
        self._buf += data
        out = []
        while True:
            start = self._buf.find(HEADER)
            if start < 0:
                del self._buf[: max(0, len(self._buf) - 3)]  # keep a possible partial header
                return out
            del self._buf[:start]
            if len(self._buf) < 7:
                return out
            length = self._buf[5] | (self._buf[6] << 8)
            total = 7 + length
            if length < 3:
                del self._buf[:4]
                raise ProtocolError(f"packet length {length} is too short")
            if length > MAX_LENGTH:
                if out:
                    return out  # the packets before it first; the next feed raises
                del self._buf[:4]
                raise ProtocolError(f"packet length {length} is beyond any packet "
                                    f"({MAX_LENGTH} at most)")
            if len(self._buf) < total:
                return out
            raw = bytes(self._buf[:total])
            crc = raw[-2] | (raw[-1] << 8)
            if crc16(raw[:-2]) != crc and out:
                return out  # the packets before it first; the next feed raises
            del self._buf[:total]
            if crc16(raw[:-2]) != crc:
                raise ProtocolError(f"CRC mismatch from ID {raw[4]}: got {crc:#06x}, "
                                    f"expected {crc16(raw[:-2]):#06x}")
            body = unstuff(raw[7:-2])
            out.append((raw[4], body[0], body[1:]))

    def reset(self) -> None:
        self._buf.clear()


def decode_status(device_id: int, instruction: int, body: bytes) -> Status:
    if instruction != STATUS:
        raise ProtocolError(f"expected a status packet from ID {device_id}, got instruction "
                            f"{instruction:#04x}")
    if not body:
        raise ProtocolError(f"status packet from ID {device_id} has no error byte")
    return Status(device_id, body[0], bytes(body[1:]))


def status_at(data: bytes, offset: int, length: int, device_id: int) -> tuple | bool | None:
    """The common case of a sync read reply — the expected servo, in order, nothing stuffed
    — read in place: ``(id, error, data)``; False for a bad CRC; None when the bytes do not
    have that shape."""
    end = offset + 11 + length
    head, crc = _status_head(device_id, length)
    if len(data) < end or not data.startswith(head, offset):
        return None
    if crc16(data, crc, offset + 8, end - 2) != data[end - 2] | data[end - 1] << 8:
        return False
    return device_id, data[offset + 8], data[offset + 9:end - 2]


def split_statuses(data: bytes) -> list[Reply]:
    """Status packets in whatever shape they came (some missing, stuffed, out of order, in
    noise): ``(id, error, data)`` per valid one. Each header is tried where it lies; one that
    does not start a packet whose CRC checks is passed by, so a bad byte (even in a length)
    costs only its own reply."""
    out, at, size = [], data.find(HEADER), len(data)
    while 0 <= at <= size - 10:
        end = at + 7 + (data[at + 5] | data[at + 6] << 8)
        if end - at >= 10 and end <= size and \
                crc16(data, 0, at, end - 2) == data[end - 2] | data[end - 1] << 8:
            body = data[at + 7:end - 2]
            if b"\xff\xff\xfd\xfd" in body:
                body = unstuff(body)
            if body[0] == STATUS and len(body) > 1:
                out.append((data[at + 4], body[1], bytes(body[2:])))
            at = data.find(HEADER, end)
        else:
            at = data.find(HEADER, at + 1)
    return out


class SyncReplies(frames.SyncReplies):
    """The replies to one sync read, checked in place as they arrive (deltoctl.servo.frames);
    a stuffed one goes to ``split_statuses``."""

    overhead = 11
    status_at = staticmethod(status_at)
    split = staticmethod(split_statuses)


def fast_sync_status(blocks: list[tuple[int, int, bytes]]) -> bytes:
    """The emulator's side of a Fast Sync Read: one status packet from ID 0xFE holding
    [ERR, ID, data, CRC] per servo, stuffed as every status packet is. Each inner block's
    CRC is that of the unstuffed packet up to the block's end (unverified: dynamixel-sdk
    checks only the packet's own, the last one, over the stuffed packet as always)."""
    body = bytearray([STATUS])
    ends = []
    for error, device_id, data in blocks:
        body += bytes([error, device_id]) + data + b"\0\0"
        ends.append(len(body) - 2)
    head = HEADER + bytes([BROADCAST_ID])
    for end in ends[:-1]:
        prefix = head + struct.pack("<H", len(body)) + bytes(body[:end])
        body[end:end + 2] = struct.pack("<H", crc16(prefix))
    stuffed = stuff(bytes(body[:-2]))
    packet = head + struct.pack("<H", len(stuffed) + 2) + stuffed
    return packet + struct.pack("<H", crc16(packet))


def split_fast_sync(data: bytes, length: int, ids: list[int]) -> list[Reply]:
    """The reply to a Fast Sync Read as ``(id, error, data)`` per servo; nothing when the
    packet does not check."""
    try:
        found = PacketReader().feed(data)
        if not found:
            return []
        blocks = decode_fast_sync(decode_status(*found[0]), length, ids)
    except ProtocolError:
        return []
    return [(i, error, block) for i, (error, block) in blocks.items()]


def decode_fast_sync(status_: Status, length: int, ids: list[int]) -> dict[int, tuple[int, bytes]]:
    """A Fast Sync Read reply: one status (ID 0xFE) with [ERR, ID, data, CRC] per servo."""
    out: dict[int, tuple[int, bytes]] = {}
    data = status_.error.to_bytes(1, "little") + status_.params
    stride = length + 4
    for k, expected in enumerate(ids):
        block = data[k * stride:(k + 1) * stride]
        if len(block) < length + 2:
            break
        if block[1] != expected:
            raise ProtocolError(f"fast sync read: block {k} is from ID {block[1]}, "
                                f"expected {expected}")
        out[expected] = (block[0], bytes(block[2:2 + length]))
    return out


class Dxl2Frames:
    """Protocol 2.0 as a session's frame variant."""

    name = "Dynamixel Protocol 2.0"
    broadcast_id = BROADCAST_ID
    address_size = 2

    def request(self, device_id: int, instruction: int, params: bytes = b"") -> bytes:
        return packet(device_id, instruction, params)

    def status(self, device_id: int, error: int = 0, data: bytes = b"") -> bytes:
        return status(device_id, error, data)

    def request_size(self, params: int) -> int:
        return 10 + params

    def status_size(self, length: int) -> int:
        return 11 + length

    def sync_replies(self, length: int, ids: list[int]) -> SyncReplies:
        return SyncReplies(length, ids)

    def reader(self) -> PacketReader:
        return PacketReader()

    def as_status(self, frame: Frame) -> Reply:
        found = decode_status(*frame)
        return found.id, found.error, found.params

    def split(self, data: bytes) -> list[Reply]:
        return split_statuses(data)

    def combined_size(self, servos: int, length: int) -> int:
        """The bytes of a Fast Sync Read's one status for ``servos`` servos."""
        return 8 + servos * (length + 4)

    def split_combined(self, data: bytes, length: int, ids: list[int]) -> list[Reply]:
        return split_fast_sync(data, length, ids)

    def combined(self, blocks: list[tuple[int, int, bytes]]) -> bytes:
        return fast_sync_status(blocks)


FRAMES = Dxl2Frames()
