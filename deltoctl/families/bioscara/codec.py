"""The Bioscara joint protocol (uStepper S32 firmware as an I2C slave), sans-I/O.

Every transaction starts with a register code; the joint appends one flags byte to every
reply. Payloads are little-endian C types (float32, int32, uint8). Facts: reference §1.2.
"""

from __future__ import annotations

import math
import struct

from deltoctl.errors import InvalidInput, ProtocolError

# register / command codes (stp_reg_t)
PING = 0x0F
SETUP = 0x10
SETRPM = 0x11
MOVESTEPS = 0x13
MOVETOANGLE = 0x15
ANGLEMOVED = 0x18
SETCURRENT = 0x19
SETHOLDCURRENT = 0x1A
SETMAXACCELERATION = 0x1B
SETMAXVELOCITY = 0x1D
ENABLESTALLGUARD = 0x1E
SETBRAKEMODE = 0x22
DISABLECLOSEDLOOP = 0x26
STOP = 0x29
CHECKORIENTATION = 0x2B
GETENCODERRPM = 0x2C
HOME = 0x2D
HOMEOFFSET = 0x2E

COMMANDS = {PING: "PING", SETUP: "SETUP", SETRPM: "SETRPM", MOVESTEPS: "MOVESTEPS",
            MOVETOANGLE: "MOVETOANGLE", ANGLEMOVED: "ANGLEMOVED", SETCURRENT: "SETCURRENT",
            SETHOLDCURRENT: "SETHOLDCURRENT", SETMAXACCELERATION: "SETMAXACCELERATION",
            SETMAXVELOCITY: "SETMAXVELOCITY", ENABLESTALLGUARD: "ENABLESTALLGUARD",
            SETBRAKEMODE: "SETBRAKEMODE", DISABLECLOSEDLOOP: "DISABLECLOSEDLOOP", STOP: "STOP",
            CHECKORIENTATION: "CHECKORIENTATION", GETENCODERRPM: "GETENCODERRPM", HOME: "HOME",
            HOMEOFFSET: "HOMEOFFSET"}
BLOCKING = frozenset({CHECKORIENTATION, HOME})  # run in the firmware's loop(), BUSY meanwhile
ACK, NACK = ord("O"), ord("N")

# the flags byte
STALL, BUSY, NOTHOMED, NOTENABLED = 0x01, 0x02, 0x04, 0x08
INITIAL_FLAGS = NOTHOMED | NOTENABLED
FLAG_NAMES = ((STALL, "stalled"), (BUSY, "busy"), (NOTHOMED, "not homed"),
              (NOTENABLED, "not enabled"))

# err_type_t of the Bioscara driver, as messages
ERRORS = {
    0: "no error",
    -1: "unspecified error",
    -2: "not homed",
    -3: "not enabled",
    -4: "stalled",
    -5: "not initialized",
    -6: "communication error",
    -101: "invalid argument",
    -109: "incorrect state (busy processing a blocking command)",
}

HOME_RPM_RANGE = (1, 250)
FLOAT = struct.Struct("<f")
INT32 = struct.Struct("<i")


def describe_flags(flags: int) -> str:
    words = [name for bit, name in FLAG_NAMES if flags & bit]
    return ", ".join(words) if words else "homed, enabled"


def frame_name(data: bytes) -> str | None:
    """The command an I2C write starts with, for the -vv trace."""
    return COMMANDS.get(data[0], f"register {data[0]:#04x}") if data else None


# -- requests: the bytes the master writes -------------------------------------------------------
def read_request(register: int) -> bytes:
    return bytes([register])


def write_float(register: int, value: float) -> bytes:
    return bytes([register]) + FLOAT.pack(value)


def write_u8(register: int, value: int) -> bytes:
    if not 0 <= value <= 255:
        raise InvalidInput(f"register {register:#04x}: {value} does not fit in one byte")
    return bytes([register, value])


def setup(drive_current: int, hold_current: int) -> bytes:
    """SETUP: drive current first, then hold (0-100 % of 2.5 A), sent as a uint32."""
    for value in (drive_current, hold_current):
        if not 0 <= value <= 100:
            raise InvalidInput(f"currents are 0-100 % of 2.5 A, got {value}")
    return bytes([SETUP, drive_current, hold_current, 0, 0])


def home(rpm: float, sensitivity: int, current: int) -> bytes:
    """HOME: [direction (1 = positive), |rpm|, sensitivity, current]."""
    speed = round(abs(rpm))
    if not HOME_RPM_RANGE[0] <= speed <= HOME_RPM_RANGE[1]:
        raise InvalidInput(f"homing speed is {speed} motor rpm; the joint accepts "
                           f"{HOME_RPM_RANGE[0]}-{HOME_RPM_RANGE[1]} ({ERRORS[-101]})")
    return bytes([HOME, 1 if rpm > 0 else 0, speed, sensitivity & 0xFF, current & 0xFF])


def move_steps(steps: int) -> bytes:
    return bytes([MOVESTEPS]) + INT32.pack(steps)


# -- replies: payload first, flags last ------------------------------------------------------------
def decode_float(reply: bytes) -> tuple[float, int]:
    if len(reply) != 5:
        raise ProtocolError(f"expected 4 payload bytes and a flags byte, got {reply.hex()}")
    return FLOAT.unpack_from(reply)[0], reply[4]


def decode_ping(reply: bytes) -> int:
    """The flags of a PING reply; ProtocolError when the joint does not answer 'O'."""
    if len(reply) != 2 or reply[0] != ACK:
        raise ProtocolError(f"PING answered {reply.hex()} instead of 'O' and the flags")
    return reply[1]


# -- units: the simple transmission of the Bioscara driver (uTransmission.h) -----------------------
def to_motor_degrees(position: float, reduction: float, offset: float) -> float:
    return math.degrees(reduction * (position - offset))


def from_motor_degrees(degrees: float, reduction: float, offset: float) -> float:
    return math.radians(degrees) / reduction + offset


def to_motor_rpm(velocity: float, reduction: float) -> float:
    return math.degrees(reduction * velocity) / 6.0


def from_motor_rpm(rpm: float, reduction: float) -> float:
    return math.radians(rpm) / reduction * 6.0
