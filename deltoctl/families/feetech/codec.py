"""The Feetech instruction set on the kit's checksum frame (deltoctl.servo.frames.checksum,
``FF FF ID LEN INST params CHK``, 0xFE broadcast): its instructions, their requests, the
names of its frames and of the status error bits. Addresses and lengths are one byte; a data
word's byte order is the servo's (STS/SMS little-endian, SCS big-endian: models.py).
Reference: feetech-sts-and-lerobot.md §1."""

from __future__ import annotations

from collections.abc import Iterable

from deltoctl.servo.frames.checksum import (
    ACTION,
    BROADCAST_ID,
    FRAMES,
    HEADER,
    MAX_ID,
    PING,
    READ,
    REG_WRITE,
    SYNC_WRITE,
    WRITE,
    action,
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

__all__ = ["ACTION", "BROADCAST_ID", "DEVICE", "HOST", "MAX_ID", "PING", "READ", "REG_WRITE",
           "SYNC_WRITE", "WRITE", "action", "ping", "read", "read_params", "reg_write",
           "sync_write", "sync_write_params", "write", "write_params"]

SYNC_READ = 0x82
INSTRUCTIONS = {PING: "PING", READ: "READ", WRITE: "WRITE", REG_WRITE: "REG_WRITE",
                ACTION: "ACTION", SYNC_READ: "SYNC_READ", SYNC_WRITE: "SYNC_WRITE"}

# Response_Status_Level 0: a servo answers PING and READ only; 1 (the default): everything.
# A PING's status holds no data; a Sync Read is answered by each listed servo in turn.
INSTRUCTION_SET = Instructions(
    ping=PING, read=READ, answered_at=(frozenset({PING, READ}), None), ping_length=0,
    sync_read=SYNC_READ)

# the status error byte, bit → (name, what to do); the SDKs' bit order (§1.3)
ERRORS = {
    0: ("input voltage", "the supply is outside the servo's voltage limits: check that the "
        "supply matches the servo's variant (a 7.4 V STS3215 on 12 V trips it)"),
    1: ("angle sensor", "the magnetic encoder reads no angle: the servo needs service"),
    2: ("overheat", "let the servo cool, then lower its load or duty"),
    3: ("over-current", "the motor drew more than Protection_Current: lower the load"),
    5: ("overload", "the servo latched its overload protection and stays limp until its "
        "power is cycled: switch the supply off and on, then lower the load or its "
        "Max_Torque_Limit"),
}


def frame_name(data: bytes) -> str | None:
    """The instructions of the frames that start in ``data``, for the -vv trace (a status
    is ``STATUS``); None when no frame starts in it."""
    names = []
    at = data.find(HEADER)
    while at >= 0 and at + 4 < len(data):
        code = data[at + 4]
        # a status's error byte (0, or a fault's bits) reads as STATUS
        names.append(INSTRUCTIONS.get(code, "STATUS" if code <= 0x7F
                                      else f"instruction {code:#04x}"))
        at = data.find(HEADER, at + 4 + max(2, data[at + 3]))
    if len(set(names)) > 1:
        return " + ".join(names)
    return (names[0] if len(names) == 1 else f"{len(names)} × {names[0]}") if names else None


def error_names(error: int) -> list[str]:
    return [ERRORS[bit][0] if bit in ERRORS else f"bit {bit}" for bit in range(7)
            if error >> bit & 1]


def error_advice(error: int) -> str:
    return "; ".join(ERRORS[bit][1] for bit in range(7) if error >> bit & 1 and bit in ERRORS)


# -- requests of its own (the shared ones are the kit's: deltoctl.servo.frames.checksum) ----------

def sync_read_params(address: int, length: int, ids: Iterable[int]) -> bytes:
    return bytes((address, length)) + bytes(ids)


def sync_read(address: int, length: int, ids: Iterable[int]) -> bytes:
    return frame(BROADCAST_ID, SYNC_READ, sync_read_params(address, length, ids))


def session(role: str = HOST) -> Session:
    """The conversation on a Feetech bus, as the driver (``HOST``) or the emulated servos
    (``DEVICE``) hold it."""
    return Session(FRAMES, INSTRUCTION_SET, role)
