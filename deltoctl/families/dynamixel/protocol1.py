"""Dynamixel Protocol 1.0 (AX, MX and RX servos in their default protocol): its instructions
on the kit's checksum frame (deltoctl.servo.frames.checksum: ``FF FF ID LEN INST params
CHECKSUM``, one-byte addresses and lengths), who answers what, and the status error bits
named with what to do. Protocol 1.0 has no SYNC_READ: a host reads each servo in turn, or an
MX bus in one BULK_READ. Reference: emanual.robotis.com/docs/en/dxl/protocol1/.
"""

from __future__ import annotations

from collections.abc import Iterable

from deltoctl.servo.frames.checksum import (
    ACTION,
    BROADCAST_ID,
    FRAMES,
    HEADER,
    PING,
    READ,
    REG_WRITE,
    SYNC_WRITE,
    WRITE,
    action,
    checksum,
    frame,
    ping,
    read,
    read_params,
    reg_write,
    sync_write,
    sync_write_params,
    write,
    write_params,
)
from deltoctl.servo.session import DEVICE, HOST, Instructions, Session

__all__ = ["ACTION", "BROADCAST_ID", "DEVICE", "HOST", "PING", "READ", "REG_WRITE", "SYNC_WRITE",
           "WRITE", "action", "ping", "read", "read_params", "reg_write", "sync_write",
           "sync_write_params", "write", "write_params"]

RESET, BULK_READ = 0x06, 0x92
INSTRUCTIONS = {PING: "PING", READ: "READ", WRITE: "WRITE", REG_WRITE: "REG_WRITE",
                ACTION: "ACTION", RESET: "RESET", SYNC_WRITE: "SYNC_WRITE",
                BULK_READ: "BULK_READ"}

# Status Return Level 0: a PING only; 1: a READ too; 2: everything. A PING's status has no
# data (the model number is read at address 0). A BULK_READ's params: 0x00, then per servo
# its length, ID and address (one byte each).
INSTRUCTION_SET = Instructions(
    ping=PING, read=READ, answered_at=(frozenset({PING}), frozenset({PING, READ}), None),
    ping_length=0, bulk_read=BULK_READ, bulk_prefix=1, bulk_entry=3, bulk_id_at=1,
    bulk_length_at=0)

# the status packet's error byte, bit by bit: what it means, and what to do
ERRORS = {
    0: ("input voltage", "the supply is outside the Min/Max Voltage Limit: check the power "
                         "supply and the limits (12, 13)"),
    1: ("angle limit", "the Goal Position is outside the CW/CCW Angle Limit: command a goal "
                       "within them, or widen the limits (6, 8)"),
    2: ("overheating", "the servo is hotter than its Temperature Limit: let it cool, and "
                       "lighten its load"),
    3: ("range", "a value is outside its item's range: check the value written"),
    4: ("checksum", "the servo heard a request whose checksum did not check: check the "
                    "wiring, the baud rate and noise on the bus"),
    5: ("overload", "the load exceeds the Torque Limit: free the joint, then switch the "
                    "torque off and on again"),
    6: ("instruction", "an unknown instruction, or ACTION with no REG_WRITE before it"),
}


def error_words(error: int) -> list[str]:
    return [ERRORS[bit][0] if bit in ERRORS else f"bit {bit}" for bit in range(8)
            if error >> bit & 1]


def error_text(error: int) -> str:
    return ", ".join(error_words(error)) + " error"


def error_hint(error: int) -> str:
    return "; ".join(ERRORS[bit][1] for bit in range(7) if error >> bit & 1)


def frame_name(data: bytes) -> str | None:
    """The instructions of the whole frames that start in ``data`` (STATUS for a status),
    for the -vv trace; bytes that only look like a header (the tail of a Protocol 2.0 reply
    holding FF FF) are no frame: their checksum does not check."""
    names = []
    at = data.find(HEADER)
    while at >= 0 and at + 5 < len(data):
        end = at + 4 + data[at + 3]
        if data[at + 3] >= 2 and end <= len(data) and checksum(data, at + 2, end - 1) == \
                data[end - 1]:
            names.append(INSTRUCTIONS.get(data[at + 4], "STATUS"))
            at = data.find(HEADER, end)
        else:
            at = data.find(HEADER, at + 1)
    if not names:
        return None
    return names[0] if len(names) == 1 else " + ".join(dict.fromkeys(names))


# -- requests of its own (the shared ones are the kit's: deltoctl.servo.frames.checksum) ----------

def bulk_read_params(requests: Iterable[tuple[int, int, int]]) -> bytes:
    """(ID, address, length) per servo."""
    return b"\x00" + b"".join(bytes((n, i, a)) for i, a, n in requests)


def reset(device_id: int) -> bytes:
    """Every item back to its factory default (the ID to 1)."""
    return frame(device_id, RESET)


def bulk_read(requests: Iterable[tuple[int, int, int]]) -> bytes:
    return frame(BROADCAST_ID, BULK_READ, bulk_read_params(requests))


def session(role: str = HOST) -> Session:
    """The conversation on a Protocol 1.0 bus, as the driver or the emulated servos hold it."""
    return Session(FRAMES, INSTRUCTION_SET, role)
