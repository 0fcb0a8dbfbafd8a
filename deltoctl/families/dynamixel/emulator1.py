"""A Dynamixel Protocol 1.0 bus (AX, RX, MX servos): each servo keeps its model's control table
(models1.py), answers at its Baud Rate only and in Protocol 1.0 only, moves to a Goal Position
within its angle limits at its Moving Speed, reports its position, speed, load (sign in bit
10), voltage and temperature, and turns by hand while its torque is off (``hand``). Who
answers what is the Protocol 1.0 device session's; the pty and its pacing are the kit's server
(deltoctl.servo.pty_server).
"""

from __future__ import annotations

import time
from functools import partial

from deltoctl.families.dynamixel import protocol1 as p1
from deltoctl.families.dynamixel.models1 import (
    AX_12A,
    BAUD_CODES,
    GOAL_POSITION,
    TORQUE_ENABLE,
    Model1,
    baud_of,
)
from deltoctl.servo.collision import overlap
from deltoctl.servo.frames import Frames
from deltoctl.servo.hand import Hand
from deltoctl.servo.items import item_at
from deltoctl.servo.pty_server import Replies
from deltoctl.servo.session import Request

INPUT_VOLTAGE, ANGLE_LIMIT, OVERHEATING, RANGE, CHECKSUM, OVERLOAD, INSTRUCTION = (
    1 << bit for bit in range(7))
LOCK = 47


class Servo1:
    def __init__(self, device_id: int, model: Model1 = AX_12A, firmware: int = 24) -> None:
        self.model = model
        self.items = model.by_name
        self.memory = bytearray(model.table_size)
        self.reset()
        self.memory[3] = device_id
        self.set("Firmware Version", firmware)
        self.position = float(model.center)
        self.set("Present Voltage", 120)
        self.set("Present Temperature", 30)
        self.registered: tuple[int, bytes] | None = None
        self._move: tuple[float, float, float, float] | None = None  # start, goal, t0, s
        self.connected = True  # on the wire (the ``connect`` control line unplugs it)
        self.hand: Hand | None = None  # a hand turning the shaft while the torque is off

    # -- a hand on the shaft (deltoctl.servo.hand) -----------------------------------------------
    def limp(self) -> bool:
        return self.memory[TORQUE_ENABLE] == 0

    def steps(self, degrees: float) -> float:
        return self.model.center + degrees * self.model.resolution / self.model.degrees

    def here(self) -> float:
        return self.position

    @property
    def id(self) -> int:
        return self.memory[3]

    def get(self, name: str) -> int:
        return self.items[name].of_table(self.memory)

    def set(self, name: str, value: int) -> None:
        item = self.items[name]
        self.memory[item.address:item.address + item.size] = item.encode(value)

    def reset(self) -> None:
        """RESET: every item to its factory default, the ID to 1 and the Baud Rate to the
        model's factory rate (an AX's 1 Mbps, an RX's or MX's 57,600 bps)."""
        for item in self.model.table:
            self.set(item.name, item.default)
        self.set("Model Number", self.model.number)

    def read(self, address: int, length: int) -> tuple[int, bytes]:
        self.update()
        if length == 0 or address + length > len(self.memory):
            return RANGE, b""
        return 0, bytes(self.memory[address:address + length])

    def write(self, address: int, data: bytes) -> int:
        if not data or address + len(data) > len(self.memory):
            return RANGE
        for offset in range(len(data)):
            item = item_at(address + offset, self.model.table)
            if item is None or item.access != "RW" or (item.address < 24 and self.memory[LOCK]):
                return RANGE
        self.update()
        before = bytes(self.memory)
        self.memory[address:address + len(data)] = data
        for item in {item_at(address + k, self.model.table) for k in range(len(data))}:
            value = item.of_table(self.memory) if item else 0
            if item is not None and item.high is not None and not (
                    (-item.high if item.low is None else item.low) <= value <= item.high):
                self.memory[:] = before
                return RANGE
        if address <= GOAL_POSITION < address + len(data):
            goal = self.get("Goal Position")
            low, high = self.get("CW Angle Limit"), self.get("CCW Angle Limit")
            if (low or high) and not low <= goal <= high:
                self.memory[:] = before  # the servo stays where it is
                return ANGLE_LIMIT
        if address <= GOAL_POSITION + 3 and address + len(data) > TORQUE_ENABLE:
            self._start_move()
        return 0

    # -- motion ------------------------------------------------------------------------------
    def _start_move(self) -> None:
        if not self.memory[TORQUE_ENABLE]:
            self._move = None
            return
        goal = float(self.get("Goal Position"))
        speed = self.get("Moving Speed") & 0x3FF or 1023  # 0: the fastest it can
        steps_per_s = speed * self.model.rpm_per_unit / 60 * self.model.resolution * (
            360.0 / self.model.degrees)
        self._move = (self.position, goal, time.monotonic(), abs(goal - self.position)
                      / steps_per_s)

    def update(self) -> None:
        if self.hand is not None:
            self.position, done = self.hand.now()
            self.position = max(0.0, min(self.model.resolution - 1.0, self.position))
            if done or self.memory[TORQUE_ENABLE]:
                self.hand = None
        if self._move is not None and self.memory[TORQUE_ENABLE]:
            start, goal, t0, duration = self._move
            fraction = 1.0 if duration <= 0 else min(1.0, (time.monotonic() - t0) / duration)
            self.position = start + (goal - start) * fraction
            moving = fraction < 1.0
            speed = self.get("Moving Speed") & 0x3FF if moving else 0
            self.set("Present Speed", speed if goal >= start else -speed)
            self.set("Present Load", 40 if moving else 0)
            self.memory[46] = int(moving)
            if not moving:
                self._move = None
        else:
            self.set("Present Speed", 0)
            self.memory[46] = 0
        self.set("Present Position", max(0, round(self.position)))


class Protocol1Bus:
    """Protocol 1.0 servos on one bus: request bytes in, the servos' statuses out."""

    def __init__(self, servos: list[Servo1], baud: int | None = None) -> None:
        self.servos = {s.id: s for s in servos}
        self.missing: set[int] = set()
        self.baud = baud
        self.line_baud: int | None = None
        self.session = p1.session(p1.DEVICE)
        if baud is not None:
            if baud not in BAUD_CODES:
                raise ValueError(f"{baud} is not a Protocol 1.0 baud rate")
            for servo in servos:
                servo.memory[4] = BAUD_CODES[baud]

    def _present(self, device_id: int) -> Servo1 | None:
        servo = self.servos.get(device_id)
        if servo is None or device_id in self.missing or not servo.connected:
            return None
        if self.baud is not None and self.line_baud and abs(
                baud_of(servo.memory[4]) - self.line_baud) > 0.03 * self.line_baud:
            return None  # it hears only noise
        return servo

    def _status(self, servo: Servo1, error: int = 0, data: bytes = b"",
                at: int | None = None) -> tuple[float, bytes]:
        """A servo's status, from ``at`` (the ID it was addressed at) when given."""
        return servo.memory[5] * 2e-6, self.session.reply(servo.id if at is None else at,
                                                          error, data)

    def _moved(self, servo: Servo1, at: int) -> None:
        """A servo given another ID (a write, a RESET) answered from the old one; it is
        found at the new one from now on (onto an ID another holds, it stays where it was:
        the bus holds one servo per ID)."""
        if servo.id != at and self.servos.get(at) is servo and servo.id not in self.servos:
            del self.servos[at]
            self.servos[servo.id] = servo

    def serve(self, data: bytes) -> list[tuple[int, Replies]]:
        return [(r.size, self.handle(r)) for r in self.session.receive_requests(data)]

    def handle(self, request: Request) -> Replies:
        instruction, params = request.instruction, request.params
        if instruction == p1.SYNC_WRITE:
            self._sync_write(params)
            return []
        if instruction == p1.BULK_READ:
            return self._bulk_read(request)
        if request.id == p1.BROADCAST_ID:
            if instruction in (p1.WRITE, p1.REG_WRITE, p1.ACTION):
                for device_id in list(self.servos):
                    servo = self._present(device_id)
                    if servo is not None:
                        self._single(servo, instruction, params)
                        self._moved(servo, device_id)
            return []  # no status to a broadcast, a PING's neither
        servo = self._present(request.id)
        if servo is None:
            return []
        error, data = self._single(servo, instruction, params)
        self._moved(servo, request.id)
        if not self.session.answers(request, request.id, servo.memory[16]):
            return []
        return [self._status(servo, error, data, request.id)]

    def _single(self, servo: Servo1, instruction: int, params: bytes) -> tuple[int, bytes]:
        if instruction == p1.PING:
            return 0, b""
        if instruction == p1.READ and len(params) == 2:
            return servo.read(params[0], params[1])
        if instruction in (p1.WRITE, p1.REG_WRITE) and len(params) > 1:
            if instruction == p1.REG_WRITE:
                servo.registered, servo.memory[44] = (params[0], bytes(params[1:])), 1
                return 0, b""
            return servo.write(params[0], bytes(params[1:])), b""
        if instruction == p1.ACTION:
            if servo.registered is None:
                return INSTRUCTION, b""
            (address, data), servo.registered = servo.registered, None
            servo.memory[44] = 0
            return servo.write(address, data), b""
        if instruction == p1.RESET:
            servo.reset()
            return 0, b""
        return INSTRUCTION, b""

    def _sync_write(self, params: bytes) -> None:
        if len(params) < 2:
            return
        address, length = params[0], params[1]
        body = params[2:]
        for k in range(0, len(body) - length, length + 1):
            servo = self._present(body[k])
            if servo is not None:
                servo.write(address, bytes(body[k + 1:k + 1 + length]))

    def _bulk_read(self, request: Request) -> Replies:
        """MX servos answer in the order listed, each its own range."""
        params = request.params
        where = {params[k + 1]: (params[k + 2], params[k]) for k in range(1, len(params) - 2, 3)}
        out = []
        for device_id in self.session.addressed(request, self.servos):
            servo = self._present(device_id)
            if servo is not None and servo.model.bulk_read:
                out.append(self._status(servo, *servo.read(*where[device_id])))
        return out


class MixedBus:
    """Buses on one wire (a servo set to the other protocol than its bus's; factory-new
    servos, each at ID 1): every request's bytes go to each, and the statuses that buses of
    one protocol send to one request from one ID go at once, so they collide."""

    def __init__(self, *buses) -> None:
        self.buses = buses
        self.baud = buses[0].baud

    @property
    def line_baud(self) -> int | None:
        return self.buses[0].line_baud

    @line_baud.setter
    def line_baud(self, value: int | None) -> None:
        for bus in self.buses:
            bus.line_baud = value

    def serve(self, data: bytes) -> list[tuple[int, Replies]]:
        heard: dict[type, list[list[tuple[int, Replies]]]] = {}
        frames = {}
        for bus in self.buses:
            heard.setdefault(type(bus), []).append(bus.serve(data))
            frames[type(bus)] = bus.session.frames
        return [answer for kind, answers in heard.items()
                for answer in overlap(answers, partial(_sender, frames[kind]))]


def _sender(frames: Frames, packet: bytes) -> int | None:
    """The ID a status is from (None: it does not check)."""
    statuses = frames.split(packet)
    return statuses[0][0] if statuses else None
