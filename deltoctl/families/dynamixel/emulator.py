"""A Dynamixel bus of X-series servos: Protocol 2.0 answered from each servo's control table,
behind a pseudo-terminal that pyserial (and so dynamixel-sdk) opens as a serial port.

Each servo is one model (models.py): it keeps that model's control table (EEPROM and RAM,
access rights, EEPROM refused while torque is on), runs the operating modes the model has (a
mode it lacks is a data range error; position mode keeps goals within the position limits,
extended and current-based position do not; velocity mode turns at the goal velocity, within
the velocity limit), moves to a goal with a time-based or velocity-based profile, reports its
current in its own unit (or its load, without a current sensor), temperature and voltage, and
honours Status Return Level, broadcast semantics, REG_WRITE and ACTION, reboot and factory
reset, and answers only at its Baud Rate (the rate the host set on the pty). Faults: a missing
servo, a corrupted CRC, no reply, a servo at another baud rate. Paced, the bus takes the wire
time of every byte.
"""

from __future__ import annotations

import contextlib
import os
import struct
import sys
import termios
import threading
import time
import tty
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from deltoctl.core.serving import ServeContext
from deltoctl.errors import ProtocolError
from deltoctl.families.dynamixel import codec
from deltoctl.families.dynamixel.control_table import BAUD_RATES, item_at
from deltoctl.families.dynamixel.models import (
    EXTENDED,
    POSITION,
    VELOCITY,
    XL430_W250,
    Model,
    by_number,
    expected_model,
)

if TYPE_CHECKING:
    from deltoctl.profile.model import Component, Hardware

_SPEEDS = {getattr(termios, f"B{b}"): b for b in BAUD_RATES.values() if hasattr(termios, f"B{b}")}
ACCESS_ERROR, DATA_LENGTH_ERROR, INSTRUCTION_ERROR, RESULT_FAIL = 7, 5, 2, 1
DATA_RANGE_ERROR, DATA_LIMIT_ERROR = 4, 6
PR_SET_TIMERSLACK = 29  # prctl(2)
PRECISE_MARGIN = 0.0001  # s a paced bus spins before a byte time, its timer slack cut
RAW_PER_REV = 4096
RPM_PER_UNIT = 0.229
MOVING_CURRENT_MA = 120.0  # what a servo draws while it moves (no load model)


class Servo:
    def __init__(self, device_id: int, firmware: int = 46, model: Model = XL430_W250) -> None:
        self.model = model
        self.items = model.by_name
        self.size = model.table_size
        self.memory = bytearray(self.size)
        self.factory_reset(0xFF)
        self.set("ID", device_id)
        self.set("Firmware Version", firmware)
        self.set("Present Position", 2047)
        self.set("Goal Position", 2047)
        self.set("Present Input Voltage", 120)
        self.set("Present Temperature", 30)
        self.registered: tuple[int, bytes] | None = None
        self._at = self.items["Present Position"].address  # written at each read
        self.position = 2047.0
        self._move: tuple[float, float, float, float] | None = None  # start, goal, t0, duration
        self._turned_at = time.monotonic()  # velocity mode: when the position was last moved

    # -- the table ---------------------------------------------------------------------------
    def get(self, name: str) -> int:
        item = self.items[name]
        raw = bytes(self.memory[item.address:item.address + item.size])
        return int.from_bytes(raw, "little", signed=item.signed)

    def set(self, name: str, value: int) -> None:
        item = self.items[name]
        self.memory[item.address:item.address + item.size] = value.to_bytes(
            item.size, "little", signed=item.signed)

    @property
    def id(self) -> int:
        return self.memory[7]

    def factory_reset(self, option: int) -> None:
        keep = {"ID": self.memory[7], "Baud Rate": self.memory[8]} if any(self.memory) else {}
        for item in self.model.table:
            self.set(item.name, item.default)
        if option in (0x01, 0x02) and keep:
            self.memory[7] = keep["ID"]
        if option == 0x02 and keep:
            self.memory[8] = keep["Baud Rate"]

    def reboot(self) -> None:
        for item in self.model.table:
            if not item.eeprom and item.access == "RW":
                self.set(item.name, item.default)
        self.set("Hardware Error Status", 0)
        self.set("Goal Position", round(self.position))
        self._move = None

    def read(self, address: int, length: int) -> tuple[int, bytes]:
        self.update()
        if address + length > self.size or length == 0:
            return ACCESS_ERROR, b""
        return 0, bytes(self.memory[address:address + length])

    def write(self, address: int, data: bytes) -> int:
        if address + len(data) > self.size or not data:
            return ACCESS_ERROR
        torque_on = self.memory[64] == 1
        for offset in range(len(data)):
            item = item_at(address + offset, self.model.table)
            if item is None or item.access != "RW" or (item.eeprom and torque_on):
                return ACCESS_ERROR
        if self.memory[70] and address <= 64 < address + len(data) and data[64 - address]:
            return RESULT_FAIL  # a shut-down servo comes back only by reboot
        self.update()
        before = bytes(self.memory)
        self.memory[address:address + len(data)] = data
        error = self._refused()
        if error:
            self.memory[:] = before  # a refused write changes nothing
            return error
        if address <= 116 < address + len(data):
            self._start_move()
        return 0

    def _refused(self) -> int:
        """The error a write just made earns: a mode the model lacks (data range), a goal
        beyond its limit (data limit)."""
        mode = self.get("Operating Mode")
        if mode not in self.model.modes:
            return DATA_RANGE_ERROR
        if abs(self.get("Goal Velocity")) > self.get("Velocity Limit"):
            return DATA_LIMIT_ERROR
        if "Goal Current" in self.items and abs(self.get("Goal Current")) > self.get(
                "Current Limit"):
            return DATA_LIMIT_ERROR
        if mode == POSITION and self.memory[64] and not (
                self.get("Min Position Limit") <= self.get("Goal Position")
                <= self.get("Max Position Limit")):
            return DATA_LIMIT_ERROR
        return 0

    # -- motion ----------------------------------------------------------------------------------
    def _start_move(self) -> None:
        goal = float(self.get("Goal Position"))
        if self.memory[64] != 1 or self.get("Operating Mode") not in (POSITION, EXTENDED, 5):
            return
        time_based = self.memory[10] & 0x04
        profile = self.get("Profile Velocity")
        distance = abs(goal - self.position)
        if time_based:
            duration = profile / 1000.0
        else:
            units = profile or self.get("Velocity Limit") or 1
            rev_per_s = units * RPM_PER_UNIT / 60.0
            duration = distance / (rev_per_s * RAW_PER_REV)
        self._move = (self.position, goal, time.monotonic(), duration)

    def update(self) -> None:
        now = time.monotonic()
        turned, self._turned_at = self._turned_at, now
        if self.memory[64] == 1 and self.get("Operating Mode") == VELOCITY:
            units = self.get("Goal Velocity")
            self.position += units * RPM_PER_UNIT / 60.0 * RAW_PER_REV * (now - turned)
            self.set("Present Velocity", units)
            self.set("Moving", int(units != 0))
            self._effort(units != 0)
        elif self._move is not None and self.memory[64] == 1:
            start, goal, t0, duration = self._move
            fraction = 1.0 if duration <= 0 else min(1.0, (time.monotonic() - t0) / duration)
            previous = self.position
            self.position = start + (goal - start) * fraction
            velocity = 0.0 if duration <= 0 else (goal - start) / duration  # raw/s
            self.set("Present Velocity", round(velocity * 60 / RAW_PER_REV / 0.229)
                     if fraction < 1.0 else 0)
            self.set("Moving", 1 if fraction < 1.0 else 0)
            if fraction >= 1.0:
                self._move = None
            self._effort(previous != self.position)
        self.memory[self._at:self._at + 4] = round(self.position).to_bytes(4, "little",
                                                                          signed=True)

    def _effort(self, moving: bool) -> None:
        """Present Current in the model's unit, or Present Load (0.1 %) without a sensor."""
        unit = self.model.current_unit
        if unit is None:
            self.set("Present Load", 50 if moving else 0)
        else:
            self.set("Present Current", round(MOVING_CURRENT_MA / unit) if moving else 0)


@dataclass
class BusFaults:
    missing: set[int] = field(default_factory=set)  # IDs that never answer
    corrupt_crc: set[int] = field(default_factory=set)  # IDs whose replies carry a bad CRC
    no_reply: bool = False  # the whole bus is silent


class DynamixelBus:
    """The servos on one bus: instruction packets in, the bytes of their replies out."""

    def __init__(self, servos: list[Servo], baud: int | None = None) -> None:
        """With ``baud``, every servo's Baud Rate item is set to it and a servo answers only
        a host speaking its own rate (a wrong rate is one Baud Rate write away)."""
        self.servos = {s.id: s for s in servos}
        self.faults = BusFaults()
        self.baud = baud
        self.line_baud: int | None = None  # what the host speaks, told by the transport
        if baud is not None:
            code = next((c for c, b in BAUD_RATES.items() if b == baud), None)
            if code is None:
                raise ValueError(f"{baud} is not an XL430 baud rate")
            for servo in servos:
                servo.memory[8] = code

    def _present(self, device_id: int) -> Servo | None:
        servo = self.servos.get(device_id)
        if servo is None or device_id in self.faults.missing:
            return None
        if self.baud is not None and BAUD_RATES.get(servo.memory[8]) != self.line_baud:
            return None  # it hears only noise
        return servo

    def _status(self, servo: Servo, error: int = 0, params: bytes = b"") -> bytes:
        data = codec.status(servo.memory[7], error, params)
        if self.faults.corrupt_crc and servo.id in self.faults.corrupt_crc:
            data = data[:-1] + bytes([data[-1] ^ 0xFF])
        return data

    def _answers(self, servo: Servo, instruction: int) -> bool:
        level = servo.memory[68]
        return instruction == codec.PING or level == 2 or (level == 1 and instruction in (
            codec.READ, codec.SYNC_READ, codec.BULK_READ))

    def handle(self, device_id: int, instruction: int, params: bytes) -> bytes:
        if self.faults.no_reply:
            return b""
        broadcast = device_id == codec.BROADCAST_ID
        if instruction == codec.PING:
            targets = sorted(self.servos) if broadcast else [device_id]
            return b"".join(self._status(s, 0, struct.pack("<HB", s.get("Model Number"),
                                                           s.get("Firmware Version")))
                            for i in targets if (s := self._present(i)))
        if instruction in (codec.SYNC_READ, codec.SYNC_WRITE, codec.BULK_READ,
                           codec.BULK_WRITE, codec.FAST_SYNC_READ):
            return self._group(instruction, params)
        targets = list(self.servos) if broadcast else [device_id]
        replies = []
        for i in targets:
            servo = self._present(i)
            if servo is None:
                continue
            error, data = self._single(servo, instruction, params)
            if not broadcast and self._answers(servo, instruction):
                replies.append(self._status(servo, error, data))
        return b"".join(replies)

    def _single(self, servo: Servo, instruction: int, params: bytes) -> tuple[int, bytes]:
        if instruction == codec.READ and len(params) == 4:
            address, length = struct.unpack("<HH", params)
            return servo.read(address, length)
        if instruction in (codec.WRITE, codec.REG_WRITE) and len(params) > 2:
            address = params[0] | params[1] << 8
            if instruction == codec.REG_WRITE:
                servo.registered = (address, bytes(params[2:]))
                servo.memory[69] = 1
                return 0, b""
            return servo.write(address, bytes(params[2:])), b""
        if instruction == codec.ACTION:
            if servo.registered is None:
                return RESULT_FAIL, b""
            address, data = servo.registered
            servo.registered, servo.memory[69] = None, 0
            return servo.write(address, data), b""
        if instruction == codec.REBOOT:
            servo.reboot()
            return 0, b""
        if instruction == codec.FACTORY_RESET and len(params) == 1:
            servo.factory_reset(params[0])
            return 0, b""
        if instruction == codec.CLEAR:
            return (RESULT_FAIL if servo.memory[122] else 0), b""
        return INSTRUCTION_ERROR, b""

    def _group(self, instruction: int, params: bytes) -> bytes:
        replies = []
        if instruction == codec.FAST_SYNC_READ:  # every servo's data in one status packet
            address, length = struct.unpack_from("<HH", params)
            blocks = []
            for i in params[4:]:
                servo = self._present(i)
                if servo is not None:
                    error, data = servo.read(address, length)
                    blocks.append((error, servo.id, data))
            return codec.fast_sync_status(blocks) if blocks else b""
        if instruction in (codec.SYNC_READ, codec.SYNC_WRITE):
            address, length = struct.unpack_from("<HH", params)
            body = params[4:]
            if instruction == codec.SYNC_READ:
                for i in body:
                    servo = self._present(i)
                    if servo is not None:
                        error, data = servo.read(address, length)
                        replies.append(self._status(servo, error, data))
            else:
                for k in range(0, len(body), length + 1):
                    servo = self._present(body[k])
                    if servo is not None:
                        servo.write(address, bytes(body[k + 1:k + 1 + length]))
        elif instruction == codec.BULK_READ:
            for k in range(0, len(params), 5):
                device_id, address, length = struct.unpack_from("<BHH", params, k)
                servo = self._present(device_id)
                if servo is not None:
                    error, data = servo.read(address, length)
                    replies.append(self._status(servo, error, data))
        else:
            k = 0
            while k + 5 <= len(params):
                device_id, address, length = struct.unpack_from("<BHH", params, k)
                servo = self._present(device_id)
                if servo is not None:
                    servo.write(address, bytes(params[k + 5:k + 5 + length]))
                k += 5 + length
        return b"".join(replies)


def wait_until(deadline: float, margin: float = 0.0002) -> None:
    """Sleep to ``margin`` before the deadline, then spin: byte-time precision. The spin
    yields the CPU at each turn, so a host on a small machine is not starved by its devices;
    a thread whose sleeps overshoot less (``precise_timers``) can sleep closer."""
    while True:
        left = deadline - time.perf_counter()
        if left <= 0:
            return
        if left > margin + 0.0001:
            time.sleep(left - margin)
        else:
            os.sched_yield()


def precise_timers() -> bool:
    """The calling thread's timer slack cut from Linux's default 50 µs to 1 ns, so that its
    sleeps end at their time, within the wake-up latency, instead of up to 50 µs after it
    (a sleep of ``wait_until`` then leaves its spin the margin it counts on, even on a busy
    machine). Returns whether it took (False elsewhere than on Linux)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        import ctypes

        return ctypes.CDLL(None, use_errno=True).prctl(PR_SET_TIMERSLACK, 1, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def split_packets(data: bytes) -> list[bytes]:
    out, k = [], 0
    while k + 7 <= len(data):
        end = k + 7 + (data[k + 5] | data[k + 6] << 8)
        out.append(data[k:end])
        k = end
    return out


class DynamixelPtyServer:
    """Serves a bus on a pseudo-terminal; ``port`` is the path a serial client opens.

    With ``pace``, the bus takes the time a real one would at the baud rate the host set: the
    instruction's bytes arrive, each servo waits its Return Delay Time, and its status packet
    leaves when its last byte would have crossed the wire (10 bits a byte). ``latency``: seconds
    each reply is held before the host sees it, as a USB adapter's latency timer holds a short
    packet (an FTDI's: 16 ms unless set)."""

    def __init__(self, bus: DynamixelBus, pace: bool = False, latency: float = 0.0) -> None:
        self.bus = bus
        self.pace = pace
        self.latency = latency
        self.master, self.slave = os.openpty()
        tty.setraw(self.master)
        tty.setraw(self.slave)
        self.port = os.ttyname(self.slave)
        self._stop = threading.Event()
        self._margin = 0.0002  # s spun before each byte time (the default timer slack's)
        self._thread = threading.Thread(target=self._serve, name="dxl-sim", daemon=True)

    def start(self) -> DynamixelPtyServer:
        self._thread.start()
        return self

    def _serve(self) -> None:
        import select

        reader = codec.PacketReader()
        if self.pace:
            if precise_timers():  # this thread's: it sleeps to its byte times, spins less
                self._margin = PRECISE_MARGIN
            os.set_blocking(self.master, False)
        while not self._stop.is_set():
            data = self._spin_read() if self.pace else b""
            if not data:
                if not select.select([self.master], [], [], 0.1)[0]:
                    continue
                try:
                    data = os.read(self.master, 4096)
                except BlockingIOError:
                    continue
                except OSError:
                    return
            arrived = time.perf_counter()
            if self.bus.baud is not None or self.pace:  # the rate the host set on the pty
                self.bus.line_baud = _SPEEDS.get(termios.tcgetattr(self.master)[5])
            try:
                packets = reader.feed(data)
            except ProtocolError:
                continue  # a corrupted instruction is ignored, as a servo would
            for device_id, instruction, params in packets:
                reply = self.bus.handle(device_id, instruction, params)
                if self.pace and self.bus.line_baud:
                    self._paced(arrived, 10 + len(params), reply)
                elif reply:
                    if self.latency:
                        time.sleep(self.latency)
                    os.write(self.master, reply)

    def _spin_read(self, spin: float = 0.002) -> bytes:
        """Paced, the bus watches the line like a UART: no wake-up delay for the next
        instruction within ``spin`` seconds of the last one."""
        end = time.perf_counter() + spin
        while time.perf_counter() < end:
            try:
                return os.read(self.master, 4096)
            except BlockingIOError:
                os.sched_yield()
                continue
            except OSError:
                break
        return b""

    def _paced(self, arrived: float, sent: int, reply: bytes) -> None:
        byte_time = 10.0 / (self.bus.line_baud or 1)
        t = arrived + sent * byte_time  # the instruction's last byte is in
        for packet in split_packets(reply):
            servo = self.bus.servos.get(packet[4])
            t += (servo.memory[9] * 2e-6 if servo else 0.0) + len(packet) * byte_time
            wait_until(t, self._margin)
            os.write(self.master, packet)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=1)
        for fd in (self.master, self.slave):
            with contextlib.suppress(OSError):
                os.close(fd)

    def __enter__(self) -> DynamixelPtyServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()


def _model_of(hw: Hardware, joint: Component) -> Model:
    """The model the profile names for a joint's servo (the XL430-W250 when it names none,
    or one deltoctl has no table for)."""
    number = expected_model(hw.params, joint.params, joint.name)
    return (by_number(number) if number is not None else None) or XL430_W250


def serve(ctx: ServeContext, blocks: list[Hardware]) -> dict[str, str]:
    """One pseudo-terminal per bus block, its servos at the joints' IDs, listening at the bus
    URL's baud rate."""
    from deltoctl.families.dynamixel import parse_bus_url
    from deltoctl.families.dynamixel.plugins import servo_ids

    o = ctx.options
    buses = {}
    for hw in blocks:
        url = ctx.profile.buses.get(hw.bus or "", "serial:///dev/ttyUSB0?baud=1000000")
        _, baud, _ = parse_bus_url(url)
        ids = {j.name: i for i, j in servo_ids(ctx.profile, hw).items()}
        bus = DynamixelBus([Servo(i, model=_model_of(hw, j))
                            for i, j in servo_ids(ctx.profile, hw).items()], baud=baud)
        bus.faults.missing |= {ids[j.name] for j in ctx.named("missing", hw) if j.name in ids}
        for joint in ctx.named("wrong_baud", hw):
            if joint.name in ids:  # 57600 (or 115200 on a 57600 bus)
                bus.servos[ids[joint.name]].memory[8] = 1 if baud != 57600 else 2
        server = ctx.stack.enter_context(DynamixelPtyServer(bus, pace=o.pace))
        query = url.split("?", 1)[1] if "?" in url else f"baud={baud}"
        buses[hw.bus or hw.name] = f"serial://{server.port}?{query}"
    return buses
