"""A Dynamixel bus of X-series servos: Protocol 2.0 answered from each servo's control table,
behind a pseudo-terminal that pyserial (and so dynamixel-sdk) opens as a serial port.

Each servo is one model (models.py): it keeps that model's control table (EEPROM and RAM,
access rights, EEPROM refused while torque is on), runs the operating modes the model has (a
mode it lacks is a data range error; position mode keeps goals within the position limits,
extended and current-based position do not; velocity mode turns at the goal velocity, within
the velocity limit), moves to a goal with a time-based or velocity-based profile, reports its
current in its own unit (or its load, without a current sensor), temperature and voltage, and
honours REG_WRITE and ACTION, reboot and factory reset, Homing Offset (present = the shaft's
position + offset), a hand turning it while its torque is off (``hand``, ``sweep``: the kit's
deltoctl.servo.hand), and answers only at its Baud Rate (the
rate the host set on the pty). Who answers what (Status Return Level, broadcast, sync, fast
sync and bulk reads) is the device session's (deltoctl.servo.session), the pty and its pacing
the kit's server (deltoctl.servo.pty_server). Faults: a missing servo, a corrupted CRC, no
reply, a servo at another baud rate, a stalled servo (held where it is, Moving stays 1). Paced,
the bus takes the wire time of every byte.
"""

from __future__ import annotations

import struct
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from deltoctl.core.emulator_contract import ServeContext
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
from deltoctl.servo.hand import Hand, add_controls
from deltoctl.servo.pty_server import Bus, PtyServer, Replies
from deltoctl.servo.session import Request

if TYPE_CHECKING:
    from deltoctl.profile.model import Component, Hardware

ACCESS_ERROR, DATA_LENGTH_ERROR, INSTRUCTION_ERROR, RESULT_FAIL = 7, 5, 2, 1
DATA_RANGE_ERROR, DATA_LIMIT_ERROR = 4, 6
RAW_PER_REV = 4096
RPM_PER_UNIT = 0.229
MOVING_CURRENT_MA = 120.0  # what a servo draws while it moves (no load model)
POSE_STEP = 25  # steps between the poses of factory-new servos (within an AX's 0-1023)


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
        self.stalled = False  # fault: held where it is, its goal never reached (Moving stays 1)
        self.connected = True  # on the wire (the ``connect`` control line unplugs it)
        self.hand: Hand | None = None  # a hand turning the shaft while the torque is off

    # -- a hand on the shaft (deltoctl.servo.hand) -----------------------------------------------
    def limp(self) -> bool:
        return self.memory[64] == 0

    def steps(self, degrees: float) -> float:
        return 2047 + degrees * RAW_PER_REV / 360

    def here(self) -> float:
        return self.position

    def _offset(self) -> int:
        """Present Position = the shaft's position + Homing Offset (e-manual)."""
        return self.get("Homing Offset")

    # -- the table ---------------------------------------------------------------------------
    def get(self, name: str) -> int:
        return self.items[name].of_table(self.memory)

    def set(self, name: str, value: int) -> None:
        item = self.items[name]
        self.memory[item.address:item.address + item.size] = item.encode(value)

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
        self.set("Goal Position", round(self.position) + self._offset())
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
        goal = float(self.get("Goal Position") - self._offset())
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
        self.set("Moving", 1)  # from the goal's write until the profile ends, however short

    def update(self) -> None:
        now = time.monotonic()
        turned, self._turned_at = self._turned_at, now
        if self.hand is not None:
            self.position, done = self.hand.now()
            if done or self.memory[64]:
                self.hand = None
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
            if self.stalled:  # held: the shaft stays, the error never closes
                fraction, duration = min(fraction, 0.5), 0.0
            else:
                self.position = start + (goal - start) * fraction
            velocity = 0.0 if duration <= 0 else (goal - start) / duration  # raw/s
            self.set("Present Velocity", round(velocity * 60 / RAW_PER_REV / 0.229)
                     if fraction < 1.0 else 0)
            self.set("Moving", 1 if fraction < 1.0 else 0)
            if fraction >= 1.0:
                self._move = None
            self._effort(self.stalled or previous != self.position)
        present = round(self.position) + self._offset()
        self.memory[self._at:self._at + 4] = present.to_bytes(4, "little", signed=True)

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
    """The servos on one bus: request bytes in (read by the bus's device session, which also
    says who answers), the servos' statuses out."""

    def __init__(self, servos: list[Servo], baud: int | None = None) -> None:
        """With ``baud``, every servo's Baud Rate item is set to it and a servo answers only
        a host speaking its own rate (a wrong rate is one Baud Rate write away)."""
        self.servos = {s.id: s for s in servos}
        self.faults = BusFaults()
        self.baud = baud
        self.line_baud: int | None = None  # what the host speaks, told by the transport
        self.session = codec.session(codec.DEVICE)
        if baud is not None:
            code = next((c for c, b in BAUD_RATES.items() if b == baud), None)
            if code is None:
                raise ValueError(f"{baud} is not an XL430 baud rate")
            for servo in servos:
                servo.memory[8] = code

    def _present(self, device_id: int) -> Servo | None:
        servo = self.servos.get(device_id)
        if servo is None or device_id in self.faults.missing or not servo.connected:
            return None
        if self.baud is not None and BAUD_RATES.get(servo.memory[8]) != self.line_baud:
            return None  # it hears only noise
        return servo

    def _status(self, servo: Servo, error: int = 0, params: bytes = b"",
                at: int | None = None) -> tuple[float, bytes]:
        """A servo's status (from ``at``, the ID it was addressed at, when a write just gave
        it another), and its Return Delay Time (2 µs a step) before it."""
        data = self.session.reply(servo.memory[7] if at is None else at, error, params)
        if self.faults.corrupt_crc and servo.id in self.faults.corrupt_crc:
            data = data[:-1] + bytes([data[-1] ^ 0xFF])
        return servo.memory[9] * 2e-6, data

    def serve(self, data: bytes) -> list[tuple[int, Replies]]:
        return [(r.size, self.handle(r.id, r.instruction, r.params))
                for r in self.session.receive_requests(data)]

    def handle(self, device_id: int, instruction: int, params: bytes) -> Replies:
        """One request: what the servos do, and their statuses (with their return delays)."""
        if self.faults.no_reply:
            return []
        request = Request(device_id, instruction, params, 0)
        if instruction in (codec.PING, codec.SYNC_READ, codec.FAST_SYNC_READ, codec.BULK_READ):
            return self._reads(request)
        if instruction in (codec.SYNC_WRITE, codec.BULK_WRITE):
            self._group_write(instruction, params)
            return []
        broadcast = request.id == codec.BROADCAST_ID
        replies = []
        for i in list(self.servos) if broadcast else [request.id]:
            servo = self._present(i)
            if servo is None:
                continue
            at = servo.id
            error, data = self._single(servo, instruction, params)
            if self.session.answers(request, at, servo.memory[68]):
                replies.append(self._status(servo, error, data, at))
            self._moved(servo, at)
        return replies

    def _moved(self, servo: Servo, at: int) -> None:
        """A servo given another ID (a write, a factory reset) answered from the old one; it
        is found at the new one from now on (at its new Baud Rate, its memory says). The bus
        holds one servo per ID: onto an ID another holds, it stays where it was (servos
        sharing an ID are buses sharing a wire, a MixedBus)."""
        if servo.id != at and self.servos.get(at) is servo and servo.id not in self.servos:
            del self.servos[at]
            self.servos[servo.id] = servo

    def _reads(self, request: Request) -> Replies:
        """A PING's and a Sync, Fast Sync or Bulk Read's: data from the servos the session
        says are asked, in the order they answer."""
        instruction, params = request.instruction, request.params
        ids = self.session.addressed(request, self.servos)
        if not ids:
            return []
        if instruction == codec.PING:
            return [self._status(s, 0, struct.pack("<HB", s.get("Model Number"),
                                                   s.get("Firmware Version")))
                    for i in ids if (s := self._present(i))]
        if instruction == codec.BULK_READ:
            where = {params[k]: struct.unpack_from("<HH", params, k + 1)
                     for k in range(0, len(params) - 4, 5)}
        else:
            where = dict.fromkeys(ids, struct.unpack_from("<HH", params))
        if instruction == codec.FAST_SYNC_READ:  # every servo's data in one status packet
            blocks = []
            for i in ids:
                servo = self._present(i)
                if servo is not None:
                    error, data = servo.read(*where[i])
                    blocks.append((error, servo.id, data))
            return [(0.0, codec.fast_sync_status(blocks))] if blocks else []
        return [self._status(s, *s.read(*where[i])) for i in ids if (s := self._present(i))]

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

    def _group_write(self, instruction: int, params: bytes) -> None:
        """A Sync or Bulk Write: each servo named takes its data; none answers."""
        if instruction == codec.SYNC_WRITE:
            if len(params) < 4:
                return
            address, length = struct.unpack_from("<HH", params)
            body = params[4:]
            for k in range(0, len(body), length + 1):
                servo = self._present(body[k])
                if servo is not None:
                    servo.write(address, bytes(body[k + 1:k + 1 + length]))
            return
        k = 0
        while k + 5 <= len(params):
            device_id, address, length = struct.unpack_from("<BHH", params, k)
            servo = self._present(device_id)
            if servo is not None:
                servo.write(address, bytes(params[k + 5:k + 5 + length]))
            k += 5 + length


class DynamixelPtyServer(PtyServer):
    """A Dynamixel bus on a pseudo-terminal (the kit's server): ``port`` is the path a serial
    client opens; with ``pace``, the bus takes the wire time of every byte; ``latency`` holds
    each reply as a USB adapter's latency timer does."""

    def __init__(self, bus: Bus, pace: bool = False, latency: float = 0.0) -> None:
        super().__init__(bus, pace, name="dxl-sim", latency=latency)


def _model_of(hw: Hardware, joint: Component) -> Model:
    """The model the profile names for a joint's servo (the XL430-W250 when it names none,
    or one deltoctl has no table for)."""
    number = expected_model(hw.params, joint.params, joint.name)
    model = by_number(number) if number is not None else None
    return model if isinstance(model, Model) else XL430_W250


def serve(ctx: ServeContext, blocks: list[Hardware]) -> dict[str, str]:
    """One pseudo-terminal per bus block, its servos at the joints' IDs, listening at the bus
    URL's baud rate in the block's protocol (a servo named by ``other_protocol`` in the other
    one, on the same wire)."""
    from deltoctl.families.dynamixel import parse_bus_url, protocol_of
    from deltoctl.families.dynamixel.ros2_control import servo_ids

    o = ctx.options
    buses: dict[str, str] = {}
    shafts: dict[str, Any] = {}  # joint → its emulated servo, for a hand to turn
    for hw in blocks:
        url = ctx.profile.buses.get(hw.bus or "", "serial:///dev/ttyUSB0?baud=1000000")
        protocol = protocol_of(hw.params, hw.name)
        _, baud, _ = parse_bus_url(url, protocol)
        joints = servo_ids(ctx.profile, hw)
        if o.factory_new:
            bus = _factory_new(ctx, hw, joints, shafts)
            server = ctx.stack.enter_context(DynamixelPtyServer(bus, pace=o.pace))
            buses[hw.bus or hw.name] = f"serial://{server.port}?baud={baud}"
            continue
        ids = {j.name: i for i, j in joints.items()}
        other = {ids[j.name] for j in ctx.named("other_protocol", hw) if j.name in ids}
        mine = {i: j for i, j in joints.items() if i not in other}
        theirs = {i: j for i, j in joints.items() if i in other}
        bus = _bus(hw, mine, baud, protocol)
        if theirs:
            from deltoctl.families.dynamixel.emulator1 import MixedBus

            bus = MixedBus(bus, _bus(hw, theirs, baud, 3.0 - protocol))
        for part in getattr(bus, "buses", (bus,)):
            shafts.update((joints[i].name, s) for i, s in part.servos.items())
            part_missing = {ids[j.name] for j in ctx.named("missing", hw) if j.name in ids}
            if isinstance(part, DynamixelBus):
                part.faults.missing |= part_missing
            else:
                part.missing |= part_missing
            for joint in ctx.named("wrong_baud", hw):
                servo = part.servos.get(ids.get(joint.name, -1))
                if servo is not None and isinstance(part, DynamixelBus):
                    servo.memory[8] = 1 if baud != 57600 else 2  # 57600 (or 115200)
                elif servo is not None:
                    servo.memory[4] = 34 if baud != 57600 else 16
            for joint in ctx.named("stall", hw):
                servo = part.servos.get(ids.get(joint.name, -1))
                if servo is not None and isinstance(part, DynamixelBus):
                    servo.stalled = True
        server = ctx.stack.enter_context(DynamixelPtyServer(bus, pace=o.pace))
        query = url.split("?", 1)[1] if "?" in url else f"baud={baud}"
        buses[hw.bus or hw.name] = f"serial://{server.port}?{query}"
    add_controls(ctx.control, shafts)
    if o.factory_new:
        from deltoctl.servo import wiring

        wiring.add_controls(ctx, shafts)
    return buses


def _factory_new(ctx: ServeContext, hw: Hardware, joints: dict[int, Component],
                 shafts: dict[str, Any]) -> Any:
    """Servos as they leave the factory: each at ID 1 and its model's factory rate (an
    X-series at 57,600 bps in Protocol 2.0; an AX at 1 Mbps, an RX or MX at 57,600 in 1.0, as
    its table's Baud Rate default says), each in a pose of its own; all on one wire, so several
    answer at ID 1 and their replies collide (each servo added to ``shafts`` by joint, all
    connected)."""
    from deltoctl.families.dynamixel.emulator1 import MixedBus

    missing = {j.name for j in ctx.named("missing", hw)}
    present = [j for j in joints.values() if j.name not in missing]
    buses = [_bus(hw, {1: j}, *_factory_rate(hw, j)) for j in present]
    for k, bus in enumerate(buses):
        bus.servos[1].position += POSE_STEP * k  # poses of their own: their replies differ
    shafts.update((j.name, b.servos[1]) for j, b in zip(present, buses, strict=True))
    return MixedBus(*buses) if buses else DynamixelBus([], 57_600)


def _factory_rate(hw: Hardware, joint: Component) -> tuple[int, float]:
    """The rate and protocol a joint's servo leaves the factory at."""
    from deltoctl.families.dynamixel.models1 import BAUD_CODES, Model1

    model = _listed_model(hw, joint)
    if not isinstance(model, Model1):
        return 57_600, 2.0
    code = model.by_name["Baud Rate"].default
    return next(b for b, c in BAUD_CODES.items() if c == code), 1.0


def _listed_model(hw: Hardware, joint: Component) -> Any:
    number = expected_model(hw.params, joint.params, joint.name)
    return by_number(number) if number is not None else None


def _bus(hw: Hardware, joints: dict[int, Component], baud: int, protocol: float) -> Any:
    """The emulated servos of ``joints`` speaking ``protocol``."""
    if protocol == 1.0:
        from deltoctl.families.dynamixel.emulator1 import Protocol1Bus, Servo1
        from deltoctl.families.dynamixel.models1 import AX_12A, Model1

        def model1(joint: Component) -> Model1:
            number = expected_model(hw.params, joint.params, joint.name)
            found = by_number(number) if number is not None else None
            return found if isinstance(found, Model1) else AX_12A

        return Protocol1Bus([Servo1(i, model1(j)) for i, j in joints.items()],
                            baud=baud if baud in _protocol1_bauds() else None)
    return DynamixelBus([Servo(i, model=_model_of(hw, j)) for i, j in joints.items()],
                        baud=baud if baud in BAUD_RATES.values() else None)


def _protocol1_bauds() -> dict[int, int]:
    from deltoctl.families.dynamixel.models1 import BAUD_CODES

    return BAUD_CODES
