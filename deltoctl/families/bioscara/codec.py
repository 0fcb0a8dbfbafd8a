"""The Bioscara joint protocol (uStepper S32 firmware as an I2C slave), sans-I/O.

Every transaction starts with a register code; the joint appends one flags byte to every
reply. Payloads are little-endian C types (float32, int32, uint8). Facts: reference §1.2.

The conversation is one combined transaction per request, kept here for both sides: the
host (the driver) turns a :class:`Request` into the bytes it writes and the length it reads,
and the bytes read into a :class:`Reply`; the device (the emulator) turns the bytes written
into a :class:`Request` and its answer into the bytes the host reads.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

from deltoctl.errors import DeviceFault, InvalidInput, ProtocolError

# register / command codes (stp_reg_t)
PING = 0x0F
SETUP = 0x10
SETRPM = 0x11
GETDRIVERRPM = 0x12  # a no-op in the firmware
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
NOT_HOMED, NOT_ENABLED, STALLED = -2, -3, -4
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
U8 = struct.Struct("<B")
NONE = struct.Struct("")
SETUP_ARGS = struct.Struct("<BB2x")  # a uint32: drive, hold, then two zero bytes
HOME_ARGS = struct.Struct("<4B")  # direction, |rpm|, sensitivity, current
# each command's arguments after its code (HOMEOFFSET: none to read it, a float to write it)
ARGS: dict[int, tuple[struct.Struct, ...]] = {
    PING: (NONE,), ANGLEMOVED: (NONE,), GETENCODERRPM: (NONE,), GETDRIVERRPM: (NONE,),
    HOMEOFFSET: (NONE, FLOAT), SETUP: (SETUP_ARGS,), HOME: (HOME_ARGS,),
    SETRPM: (FLOAT,), MOVETOANGLE: (FLOAT,), SETMAXACCELERATION: (FLOAT,),
    SETMAXVELOCITY: (FLOAT,), CHECKORIENTATION: (FLOAT,), MOVESTEPS: (INT32,),
    SETCURRENT: (U8,), SETHOLDCURRENT: (U8,), ENABLESTALLGUARD: (U8,), SETBRAKEMODE: (U8,),
    STOP: (U8,), DISABLECLOSEDLOOP: (U8,),
}
FLOAT_READS = frozenset({ANGLEMOVED, GETENCODERRPM, HOMEOFFSET})  # answered with a float32


def describe_flags(flags: int) -> str:
    words = [name for bit, name in FLAG_NAMES if flags & bit]
    return ", ".join(words) if words else "homed, enabled"


def frame_name(data: bytes) -> str | None:
    """The command an I2C write starts with, for the -vv trace."""
    return COMMANDS.get(data[0], f"register {data[0]:#04x}") if data else None


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


# -- the conversation, both roles ---------------------------------------------------------------
@dataclass(frozen=True)
class Request:
    """One command and its arguments, as the C types they travel as."""

    command: int
    args: tuple[float, ...] = ()

    @property
    def name(self) -> str:
        return COMMANDS.get(self.command, f"register {self.command:#04x}")

    @property
    def payload_size(self) -> int:
        """Bytes the joint answers before its flags: a float read's four, PING's 'O'."""
        if self.command == PING:
            return 1
        return FLOAT.size if self.command in FLOAT_READS and not self.args else 0


@dataclass(frozen=True)
class Reply:
    """The flags byte every reply ends with, and a read's value (None for a command)."""

    flags: int
    value: float | None = None


class Host:
    """The driver's side: the bytes of each request, the length of its reply, and the reply
    decoded. A NACK is the joint's own error (:class:`DeviceFault`); bytes that break the
    protocol are a :class:`ProtocolError`."""

    @staticmethod
    def encode(request: Request) -> tuple[bytes, int]:
        """What to write, and how many bytes to read after the repeated start."""
        layout = _layout(request.command, len(request.args))
        if layout is None:
            raise InvalidInput(f"{request.name} takes no {len(request.args)} arguments")
        try:
            data = bytes([request.command]) + layout.pack(*request.args)
        except (struct.error, OverflowError) as exc:  # OverflowError: a float past float32
            raise InvalidInput(f"{request.name}: {request.args} do not fit ({exc})") from None
        return data, request.payload_size + 1

    @staticmethod
    def decode(request: Request, reply: bytes) -> Reply:
        if request.command == PING:
            if len(reply) == 2 and reply[0] == NACK:
                raise DeviceFault("the joint answered PING with NACK", NACK)
            return Reply(decode_ping(reply))
        if request.payload_size:
            value, flags = decode_float(reply)
            return Reply(flags, value)
        if len(reply) != 1:
            raise ProtocolError(f"{request.name} expects the flags byte alone, got "
                                f"{reply.hex() or 'nothing'}")
        return Reply(reply[0])


class Device:
    """The joint's side: the bytes the host wrote as a request, and the bytes it reads."""

    @staticmethod
    def parse(data: bytes) -> Request:
        """A request, or ProtocolError for an empty write, an unknown command or arguments of
        the wrong length (the firmware runs those as a blocking no-op)."""
        if not data:
            raise ProtocolError("an empty write carries no command")
        command, args = data[0], data[1:]
        layouts = ARGS.get(command)
        if layouts is None:
            raise ProtocolError(f"register {command:#04x} is no command the joint knows")
        layout = next((s for s in layouts if s.size == len(args)), None)
        if layout is None:
            sizes = " or ".join(str(s.size) for s in layouts)
            raise ProtocolError(f"{COMMANDS.get(command, hex(command))} takes {sizes} argument "
                                f"bytes, got {len(args)}")
        return Request(command, layout.unpack(args))

    @staticmethod
    def answer(request: Request, value: float | None = None) -> bytes:
        """The payload of the reply to ``request``: 'O' to a PING, a read's float32."""
        if request.command == PING:
            return bytes([ACK])
        return FLOAT.pack(0.0 if value is None else value) if request.payload_size else b""

    @staticmethod
    def reply(payload: bytes, flags: int, length: int) -> bytes:
        """The ``length`` bytes the host reads: the payload, cut or padded, then the flags
        (a one-byte read: the flags alone)."""
        if length < 1:
            return b""
        return payload[:length - 1].ljust(length - 1, b"\0") + bytes([flags])


def _layout(command: int, count: int) -> struct.Struct | None:
    """The layout of ``count`` arguments of ``command`` (None: it takes no such number)."""
    return next((s for s in ARGS.get(command, ()) if len(s.unpack(bytes(s.size))) == count),
                None)


# -- requests: what the host asks, checked before the wire -----------------------------------------
def read(command: int) -> Request:
    return Request(command)


def float_command(command: int, value: float) -> Request:
    return Request(command, (value,))


def u8_command(command: int, value: int) -> Request:
    if not 0 <= value <= 255:
        raise InvalidInput(f"register {command:#04x}: {value} does not fit in one byte")
    return Request(command, (value,))


def setup_command(drive_current: int, hold_current: int) -> Request:
    """SETUP: drive current first, then hold (0-100 % of 2.5 A), sent as a uint32."""
    for value in (drive_current, hold_current):
        if not 0 <= value <= 100:
            raise InvalidInput(f"currents are 0-100 % of 2.5 A, got {value}")
    return Request(SETUP, (drive_current, hold_current))


def home_command(rpm: float, sensitivity: int, current: int) -> Request:
    """HOME: [direction (1 = positive), |rpm|, sensitivity, current]."""
    speed = round(abs(rpm))
    if not HOME_RPM_RANGE[0] <= speed <= HOME_RPM_RANGE[1]:
        raise InvalidInput(f"homing speed is {speed} motor rpm; the joint accepts "
                           f"{HOME_RPM_RANGE[0]}-{HOME_RPM_RANGE[1]} ({ERRORS[-101]})")
    return Request(HOME, (1 if rpm > 0 else 0, speed, sensitivity & 0xFF, current & 0xFF))


# requests as the bytes the host writes (any register, as the firmware's tests poke them)
def read_request(register: int) -> bytes:
    return bytes([register])


def write_float(register: int, value: float) -> bytes:
    return bytes([register]) + FLOAT.pack(value)


def write_u8(register: int, value: int) -> bytes:
    return bytes([u8_command(register, value).command, value])


def setup(drive_current: int, hold_current: int) -> bytes:
    return Host.encode(setup_command(drive_current, hold_current))[0]


def home(rpm: float, sensitivity: int, current: int) -> bytes:
    return Host.encode(home_command(rpm, sensitivity, current))[0]


def move_steps(steps: int) -> bytes:
    return Host.encode(Request(MOVESTEPS, (steps,)))[0]


# -- units: the simple transmission of the Bioscara driver (uTransmission.h) -----------------------
def to_motor_degrees(position: float, reduction: float, offset: float) -> float:
    return math.degrees(reduction * (position - offset))


def from_motor_degrees(degrees: float, reduction: float, offset: float) -> float:
    return math.radians(degrees) / reduction + offset


def to_motor_rpm(velocity: float, reduction: float) -> float:
    return math.degrees(reduction * velocity) / 6.0


def from_motor_rpm(rpm: float, reduction: float) -> float:
    return math.radians(rpm) / reduction * 6.0
