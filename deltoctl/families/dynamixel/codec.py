"""Dynamixel Protocol 2.0: its instructions, their requests, and the names of its frames and
errors, on the kit's Protocol 2.0 frame (deltoctl.servo.frames.dxl2, whose names this module
also offers: packets, statuses, the CRC, the reader). Reference: bioscara-mh5-dynamixel.md §3.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable

from deltoctl.servo.frames.dxl2 import (
    _TABLE,
    BROADCAST_ID,
    FRAMES,
    HEADER,
    MAX_ID,
    STATUS,
    STATUS_ERRORS,
    PacketReader,
    Status,
    SyncReplies,
    crc16,
    decode_fast_sync,
    decode_status,
    fast_sync_status,
    packet,
    split_fast_sync,
    split_statuses,
    status,
    status_at,
    stuff,
    unstuff,
)
from deltoctl.servo.session import DEVICE, HOST, Instructions, Session

__all__ = [
    "BROADCAST_ID",
    "DEVICE",
    "HEADER",
    "HOST",
    "MAX_ID",
    "STATUS",
    "STATUS_ERRORS",
    "_TABLE",
    "PacketReader",
    "Status",
    "SyncReplies",
    "crc16",
    "decode_fast_sync",
    "decode_status",
    "fast_sync_status",
    "packet",
    "split_fast_sync",
    "split_statuses",
    "status",
    "status_at",
    "stuff",
    "unstuff",
]

PING, READ, WRITE, REG_WRITE, ACTION = 0x01, 0x02, 0x03, 0x04, 0x05
FACTORY_RESET, REBOOT, CLEAR = 0x06, 0x08, 0x10
SYNC_READ, SYNC_WRITE, FAST_SYNC_READ = 0x82, 0x83, 0x8A
BULK_READ, BULK_WRITE, FAST_BULK_READ = 0x92, 0x93, 0x9A
INSTRUCTIONS = {PING: "PING", READ: "READ", WRITE: "WRITE", REG_WRITE: "REG_WRITE",
                ACTION: "ACTION", FACTORY_RESET: "FACTORY_RESET", REBOOT: "REBOOT",
                CLEAR: "CLEAR", STATUS: "STATUS", SYNC_READ: "SYNC_READ",
                SYNC_WRITE: "SYNC_WRITE", FAST_SYNC_READ: "FAST_SYNC_READ",
                BULK_READ: "BULK_READ", BULK_WRITE: "BULK_WRITE",
                FAST_BULK_READ: "FAST_BULK_READ"}

# who answers what: at Status Return Level 0 a PING only, at 1 a READ too, at 2 everything;
# a PING's status holds the model number and the firmware version
INSTRUCTION_SET = Instructions(
    ping=PING, read=READ, answered_at=(frozenset({PING}), frozenset({PING, READ}), None),
    ping_length=3, sync_read=SYNC_READ, fast_sync_read=FAST_SYNC_READ, bulk_read=BULK_READ)
HARDWARE_ERRORS = {0: "input voltage", 2: "overheating", 3: "motor encoder",
                   4: "electrical shock", 5: "overload"}


def frame_name(data: bytes) -> str | None:
    """The instructions of the packets that start in ``data``, for the -vv trace:
    ``SYNC_READ``, ``STATUS``, ``22 × STATUS`` (the replies to a sync read read at once);
    None when no packet starts in it (the rest of a reply)."""
    names = []
    at = data.find(HEADER)
    while at >= 0 and at + 7 < len(data):
        inst = data[at + 7]
        names.append(INSTRUCTIONS.get(inst, f"instruction {inst:#04x}"))
        at = data.find(HEADER, at + 7 + max(1, data[at + 5] | data[at + 6] << 8))
    if len(set(names)) > 1:
        return " + ".join(names)
    return (names[0] if len(names) == 1 else f"{len(names)} × {names[0]}") if names else None


# -- instructions ---------------------------------------------------------------------------------

def _u16(value: int) -> bytes:
    return struct.pack("<H", value)


def read_params(address: int, length: int) -> bytes:
    return _u16(address) + _u16(length)


def write_params(address: int, data: bytes) -> bytes:
    return _u16(address) + data


def sync_read_params(address: int, length: int, ids: Iterable[int]) -> bytes:
    return _u16(address) + _u16(length) + bytes(ids)


def bulk_read_params(requests: Iterable[tuple[int, int, int]]) -> bytes:
    """(ID, address, length) per servo."""
    return b"".join(bytes([i]) + _u16(a) + _u16(n) for i, a, n in requests)


def ping(device_id: int = BROADCAST_ID) -> bytes:
    return packet(device_id, PING)


def read(device_id: int, address: int, length: int) -> bytes:
    return packet(device_id, READ, read_params(address, length))


def write(device_id: int, address: int, data: bytes) -> bytes:
    return packet(device_id, WRITE, write_params(address, data))


def reg_write(device_id: int, address: int, data: bytes) -> bytes:
    return packet(device_id, REG_WRITE, write_params(address, data))


def action(device_id: int = BROADCAST_ID) -> bytes:
    return packet(device_id, ACTION)


def factory_reset(device_id: int, option: int = 0xFF) -> bytes:
    """option 0xFF: all; 0x01: all but the ID; 0x02: all but the ID and the baud rate."""
    if device_id == BROADCAST_ID and option == 0xFF:
        raise ValueError("a broadcast factory reset of everything is refused by the firmware")
    return packet(device_id, FACTORY_RESET, bytes([option]))


def reboot(device_id: int) -> bytes:
    return packet(device_id, REBOOT)


def clear_multi_turn(device_id: int) -> bytes:
    return packet(device_id, CLEAR, b"\x01\x44\x58\x4c\x22")


def sync_read(address: int, length: int, ids: Iterable[int], fast: bool = False) -> bytes:
    return packet(BROADCAST_ID, FAST_SYNC_READ if fast else SYNC_READ,
                  sync_read_params(address, length, ids))


def sync_write(address: int, length: int, data: dict[int, bytes]) -> bytes:
    params = bytearray(_u16(address) + _u16(length))
    for device_id, values in data.items():
        if len(values) != length:
            raise ValueError(f"sync write to ID {device_id}: {len(values)} bytes, not {length}")
        params += bytes([device_id]) + values
    return packet(BROADCAST_ID, SYNC_WRITE, bytes(params))


def bulk_read(requests: Iterable[tuple[int, int, int]], fast: bool = False) -> bytes:
    return packet(BROADCAST_ID, FAST_BULK_READ if fast else BULK_READ,
                  bulk_read_params(requests))


def bulk_write(writes: Iterable[tuple[int, int, bytes]]) -> bytes:
    params = b"".join(bytes([i]) + _u16(a) + _u16(len(d)) + d for i, a, d in writes)
    return packet(BROADCAST_ID, BULK_WRITE, params)


def hardware_error_text(bits: int) -> list[str]:
    return [name for bit, name in HARDWARE_ERRORS.items() if bits >> bit & 1]


def session(role: str = HOST) -> Session:
    """The conversation on a Protocol 2.0 bus, as the driver (``HOST``) or the emulated
    servos (``DEVICE``) hold it."""
    return Session(FRAMES, INSTRUCTION_SET, role)
