"""Sans-I/O CANopen: the 16-byte frame record the local hub carries, and what a frame means.

A record is SocketCAN's ``struct can_frame`` in little-endian byte order: the identifier with
its flags (extended, remote, error), the data length, three pad bytes and eight data bytes.
``decode`` refuses any record a CAN controller could not have sent (one ``ProtocolError``).

``describe`` names a CANopen frame by its COB-ID (CiA 301's predefined connection set) and
decodes its payload: NMT commands, SYNC, EMCY, PDOs, SDO requests and replies, heartbeats,
LSS services.
The CiA 402 statusword and controlword facts live here too, shared by driver and emulator.
"""

from __future__ import annotations

import struct
from typing import NamedTuple

from deltoctl.errors import ProtocolError

RECORD = struct.Struct("<IB3x8s")
RECORD_SIZE = RECORD.size  # 16
EFF_FLAG, RTR_FLAG, ERR_FLAG = 0x80000000, 0x40000000, 0x20000000
SFF_MASK, EFF_MASK = 0x7FF, 0x1FFFFFFF
# a classic frame on the wire, at most: 47 bits of frame and 64 of data, plus stuff bits
MAX_FRAME_BITS = 135


class Frame(NamedTuple):
    can_id: int
    data: bytes = b""
    extended: bool = False
    remote: bool = False


def encode(frame: Frame) -> bytes:
    """A frame as its 16-byte record; a frame no controller could send is a ValueError."""
    limit = EFF_MASK if frame.extended else SFF_MASK
    if not 0 <= frame.can_id <= limit or len(frame.data) > 8:
        raise ValueError(f"not a classic CAN frame: id {frame.can_id:#x}, "
                         f"{len(frame.data)} data bytes")
    flags = (EFF_FLAG if frame.extended else 0) | (RTR_FLAG if frame.remote else 0)
    return RECORD.pack(frame.can_id | flags, len(frame.data), bytes(frame.data))


def decode(record: bytes) -> Frame:
    """A 16-byte record as a frame (its data cut to its length)."""
    if len(record) != RECORD_SIZE:
        raise ProtocolError(f"a CAN frame record is {RECORD_SIZE} bytes, got {len(record)}")
    word, dlc, data = RECORD.unpack(record)
    if word & ERR_FLAG:
        raise ProtocolError("an error frame record")
    extended = bool(word & EFF_FLAG)
    can_id = word & (EFF_MASK if extended else 0x1FFFFFFF)
    if dlc > 8 or (not extended and can_id > SFF_MASK):
        raise ProtocolError(f"not a classic CAN frame: id {can_id:#x}, length {dlc}")
    return Frame(can_id, data[:dlc], extended, bool(word & RTR_FLAG))


# -- CANopen (CiA 301) -------------------------------------------------------------------------

NMT_COMMANDS = {0x01: "start", 0x02: "stop", 0x80: "enter pre-operational",
                0x81: "reset node", 0x82: "reset communication"}
NMT_STATES = {0x00: "boot-up", 0x04: "STOPPED", 0x05: "OPERATIONAL", 0x7F: "PRE-OPERATIONAL"}
PDO_BASES = {0x180: "TPDO1", 0x200: "RPDO1", 0x280: "TPDO2", 0x300: "RPDO2",
             0x380: "TPDO3", 0x400: "RPDO3", 0x480: "TPDO4", 0x500: "RPDO4"}
SDO_ABORTS = {
    0x05040000: "SDO protocol timed out", 0x05040001: "command specifier not valid",
    0x06010000: "unsupported access", 0x06010001: "read of a write-only object",
    0x06010002: "write of a read-only object", 0x06020000: "object does not exist",
    0x06040041: "object cannot be mapped to a PDO", 0x06070010: "data type or length wrong",
    0x06090011: "sub-index does not exist", 0x06090030: "value out of range",
    0x06090031: "value too high", 0x06090032: "value too low",
    0x08000000: "general error", 0x08000020: "data cannot be stored now",
    0x08000022: "data cannot be stored in the device's present state",
    0x060A0023: "resource not available",
}


def node_of(can_id: int) -> int:
    return can_id & 0x7F


def describe(frame: Frame) -> str:
    """What a frame is, for people: ``SDO read 0x6041:00 → node 2``, ``TPDO1 node 3`` …"""
    cid, data = frame.can_id, frame.data
    if frame.extended:
        return f"extended frame {cid:#010x}"
    function, node = cid & 0x780, node_of(cid)
    if cid == 0x000:
        return _nmt(data)
    if cid == 0x080:
        return "SYNC" + (f" #{data[0]}" if data else "")
    if function == 0x080:
        return f"EMCY node {node}" + (f" {int.from_bytes(data[:2], 'little'):#06x}"
                                      if len(data) >= 2 else "")
    if cid == 0x100:
        return "TIME"
    if function in PDO_BASES and node:
        kind = PDO_BASES[function]
        return f"{kind} node {node}" + (" (remote request)" if frame.remote else "")
    if function == 0x580 and node:
        return "SDO reply from node " + f"{node}: {_sdo(data, reply=True)}"
    if function == 0x600 and node:
        return f"SDO request to node {node}: {_sdo(data, reply=False)}"
    if function == 0x700 and node:
        if frame.remote:
            return f"node guarding request to node {node}"
        state = NMT_STATES.get(data[0] & 0x7F, f"state {data[0]:#x}") if data else "empty"
        return f"heartbeat node {node}: {state}" if state != "boot-up" else f"boot-up node {node}"
    if cid in (0x7E4, 0x7E5):
        return _lss(data, reply=cid == 0x7E4)
    return f"frame {cid:#05x}"


def frame_name(record: bytes) -> str | None:
    """The -vv trace's name of a record on a CAN link."""
    try:
        return describe(decode(record))
    except ProtocolError:
        return None


LSS_SERVICES = {
    0x04: "switch state global", 0x11: "configure node ID", 0x13: "configure bit timing",
    0x15: "activate bit timing", 0x17: "store configuration", 0x40: "switch selective vendor",
    0x41: "switch selective product", 0x42: "switch selective revision",
    0x43: "switch selective serial", 0x44: "switch selective done",
    **{cs: "identify remote slave" for cs in range(0x46, 0x4C)},
    0x4C: "identify non-configured remote slave", 0x4F: "identify slave",
    0x50: "identify non-configured slave", 0x51: "fast scan", 0x5A: "inquire vendor",
    0x5B: "inquire product", 0x5C: "inquire revision", 0x5D: "inquire serial",
    0x5E: "inquire node ID"}


def _lss(data: bytes, reply: bool) -> str:
    """An LSS frame (CiA 305): its service, and the node ID or error a reply carries."""
    if not data:
        return "LSS (empty)"
    name = LSS_SERVICES.get(data[0], f"command {data[0]:#04x}")
    if not reply:
        return f"LSS {name}"
    if data[0] == 0x5E and len(data) > 1:
        return f"LSS reply {name}: " + (f"{data[1]}" if data[1] != 0xFF else "none")
    if data[0] in (0x11, 0x13, 0x17) and len(data) > 1:
        return f"LSS reply {name}: " + ("ok" if data[1] == 0 else f"error {data[1]}")
    return f"LSS reply {name}"


def _nmt(data: bytes) -> str:
    if len(data) < 2:
        return "NMT (short)"
    command = NMT_COMMANDS.get(data[0], f"command {data[0]:#04x}")
    return f"NMT {command} " + ("all nodes" if data[1] == 0 else f"node {data[1]}")


def _sdo(data: bytes, reply: bool) -> str:
    if len(data) < 8:
        return "short"
    ccs = data[0] >> 5
    where = f"{int.from_bytes(data[1:3], 'little'):#06x}:{data[3]:02x}"
    if ccs == 4:
        code = int.from_bytes(data[4:8], "little")
        return f"abort {where} {code:#010x} ({SDO_ABORTS.get(code, 'unknown abort code')})"
    if reply:
        names = {2: "read", 3: "write ok", 0: "segment", 1: "segment ack", 6: "block read",
                 5: "block write"}
        name = names.get(ccs, f"command {ccs}")
        if ccs == 2 and data[0] & 0x02:  # expedited read: the value is here
            size = 4 - ((data[0] >> 2) & 3) if data[0] & 1 else 4
            return f"{name} {where} = {data[4:4 + size].hex()}"
        return f"{name} {where}" if ccs in (2, 3, 5, 6) else name
    names = {1: "write", 2: "read", 0: "segment", 3: "segment", 5: "block read",
             6: "block write"}
    name = names.get(ccs, f"command {ccs}")
    if ccs == 1 and data[0] & 0x02:
        size = 4 - ((data[0] >> 2) & 3) if data[0] & 1 else 4
        return f"{name} {where} = {data[4:4 + size].hex()}"
    return f"{name} {where}" if ccs in (1, 2, 5, 6) else name


# -- CiA 402 -----------------------------------------------------------------------------------

# statusword & mask == value: the drive's state (CiA 402, as canopen's p402 SW_MASK)
STATES = {
    "NOT READY TO SWITCH ON": (0x4F, 0x00),
    "SWITCH ON DISABLED": (0x4F, 0x40),
    "READY TO SWITCH ON": (0x6F, 0x21),
    "SWITCHED ON": (0x6F, 0x23),
    "OPERATION ENABLED": (0x6F, 0x27),
    "QUICK STOP ACTIVE": (0x6F, 0x07),
    "FAULT REACTION ACTIVE": (0x4F, 0x0F),
    "FAULT": (0x4F, 0x08),
}
CW_SHUTDOWN, CW_SWITCH_ON, CW_ENABLE = 0x06, 0x07, 0x0F
CW_DISABLE_VOLTAGE, CW_QUICK_STOP, CW_FAULT_RESET = 0x00, 0x02, 0x80
CW_NEW_SETPOINT, CW_CHANGE_IMMEDIATELY, CW_RELATIVE, CW_HALT = 0x10, 0x20, 0x40, 0x100
SW_TARGET_REACHED, SW_SETPOINT_ACK, SW_HOMING_ATTAINED, SW_HOMING_ERROR = (
    0x400, 0x1000, 0x1000, 0x2000)
MODE_PROFILE_POSITION, MODE_PROFILE_VELOCITY, MODE_HOMING = 1, 3, 6
DEVICE_TYPE_SERVO = 0x00020192  # 0x1000 of a CiA 402 servo drive


def state_of(statusword: int) -> str:
    for name, (mask, value) in STATES.items():
        if statusword & mask == value:
            return name
    return "UNKNOWN"
