"""A Feetech bus: each servo its model (models.py) — its control table in its byte order,
sign-magnitude items, EEPROM kept only while Lock is 0 (a write with Lock 1 holds until the
power is cycled, then the saved value is back), Phase bit 4 (clear: positions wrap to one
turn; set: the full angle), Homing_Offset (present = actual − offset), a goal written turns
the torque on and moves the servo at its goal speed within its position limits, Torque_Enable
128 centres the offset, a hand turns it while its torque is off (``hand``, ``sweep``) — and
its status error byte: an overload latched (torque off, goals ignored) until ``power_cycle``,
a supply outside the voltage limits. Behind a pseudo-terminal
(the kit's PtyServer) that pyserial, and so scservo_sdk, opens as a serial port; a servo
answers only at its Baud_Rate, and servos sharing an ID answer at once: their bytes collide
(the kit's ``collide``). Who answers what is the device session's.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

from deltoctl.core.emulator_contract import ServeContext
from deltoctl.families.feetech import codec
from deltoctl.families.feetech.models import BAUD_RATES, BY_NUMBER, Model, expected_model
from deltoctl.servo.collision import collide
from deltoctl.servo.hand import Hand, add_controls
from deltoctl.servo.items import item_at
from deltoctl.servo.pty_server import PtyServer, Replies
from deltoctl.servo.session import Request

if TYPE_CHECKING:
    from deltoctl.profile.model import Component, Hardware

VOLTAGE, OVERHEAT, OVERLOAD = 0x01, 0x04, 0x20
DEFAULT_SPEED = 3400  # steps/s when Goal_Velocity is 0 (the STS3215's top speed)
STS3215 = BY_NUMBER[777]


class Servo:
    def __init__(self, device_id: int, model: Model = STS3215, firmware: tuple[int, int] = (3, 10),
                 volts: float = 12.0) -> None:
        self.model = model
        self.items = model.by_name
        self.memory = bytearray(model.table_size)
        for item in model.table:
            self.set(item.name, item.default)
        self.set("ID", device_id)
        self.memory[0], self.memory[1] = firmware
        self.saved = bytes(self.memory[:40])  # the EEPROM as it survives a power cycle
        self.volts = volts
        self.latched = 0  # protection bits held until the power is cycled
        self.registered: tuple[int, bytes] | None = None
        self.actual = model.resolution / 2  # the shaft's angle, steps
        self._move: tuple[float, float, float, float] | None = None  # from, to, t0, seconds
        self.connected = True  # on the wire (the ``connect`` control line unplugs it)
        self.hand: Hand | None = None  # a hand turning the shaft while the torque is off
        self.joint: str | None = None  # the profile's joint it serves, for a hand to find
        self.power_cycle()

    # -- a hand on the shaft (deltoctl.servo.hand) -----------------------------------------------
    def limp(self) -> bool:
        return self.get("Torque_Enable") == 0

    def steps(self, degrees: float) -> float:
        return self.model.resolution / 2 + degrees * self.model.resolution / 360

    def here(self) -> float:
        return self.actual

    # -- the table -------------------------------------------------------------------------------
    def get(self, name: str) -> int:
        return self.items[name].of_table(self.memory)

    def set(self, name: str, value: int) -> None:
        item = self.items[name]
        self.memory[item.address:item.address + item.size] = item.encode(value)

    def has(self, name: str) -> bool:
        return name in self.items

    @property
    def id(self) -> int:
        return self.memory[5]

    @property
    def baud(self) -> int | None:
        return BAUD_RATES.get(self.memory[6])

    def power_cycle(self) -> None:
        """Power off and on: the EEPROM as saved, RAM at its defaults, protection cleared."""
        self.memory[:40] = self.saved
        for item in self.model.table:
            if not item.eeprom and item.access == "RW":
                self.set(item.name, item.default)
        self.latched = 0
        self._move = None
        self.registered = None
        self.set("Present_Voltage", round(self.volts * 10))
        self.set("Present_Temperature", 30)
        self.update()
        self.set("Goal_Position", self.get("Present_Position"))

    def error(self) -> int:
        """The status error byte: what is wrong now, and what protection latched."""
        bits = self.latched
        volts = self.memory[self.items["Present_Voltage"].address]
        if not self.get("Min_Voltage_Limit") <= volts <= self.get("Max_Voltage_Limit"):
            bits |= VOLTAGE
        if self.get("Present_Temperature") > self.get("Max_Temperature_Limit"):
            bits |= OVERHEAT
        return bits

    def latch_overload(self) -> None:
        self.latched |= OVERLOAD
        self.set("Torque_Enable", 0)
        self._move = None

    # -- the instructions ------------------------------------------------------------------------
    def read(self, address: int, length: int) -> bytes | None:
        self.update()
        if address + length > len(self.memory) or length == 0:
            return None  # no answer, as a servo asked beyond its table
        self.set("Status", self.error())
        return bytes(self.memory[address:address + length])

    def write(self, address: int, data: bytes) -> None:
        """A write as the servo takes it: read-only bytes are left alone; EEPROM is saved
        only while Lock is 0."""
        if address + len(data) > len(self.memory):
            return
        self.update()
        goal = self.items["Goal_Position"].address
        for offset, byte in enumerate(data):
            item = item_at(address + offset, self.model.table)
            if item is not None and item.access == "RW":
                self.memory[address + offset] = byte
        if self.memory[self.model.lock] == 0 and address < 40:
            self.saved = bytes(self.memory[:40])
        torque = self.items["Torque_Enable"].address
        if address <= torque < address + len(data):
            if data[torque - address] == 128:
                self._centre()
            elif self.latched & OVERLOAD:
                self.memory[torque] = 0  # limp until the power is cycled
            else:
                self.memory[torque] = min(1, self.memory[torque])
        if address <= goal < address + len(data) and not self.latched & OVERLOAD:
            self.memory[torque] = 1  # a goal turns the torque on
            self._start_move()
        if self.memory[torque] == 0:
            self._move = None

    def _centre(self) -> None:
        """Torque_Enable 128: Homing_Offset set so that the present pose reads mid-turn."""
        half = self.model.resolution // 2
        if self.has("Homing_Offset"):
            self.set("Homing_Offset", max(-2047, min(2047, round(self.actual) - half)))
            if self.memory[self.model.lock] == 0:
                self.saved = bytes(self.memory[:40])
        self.set("Torque_Enable", 0)

    # -- motion ----------------------------------------------------------------------------------
    def _offset(self) -> int:
        return self.get("Homing_Offset") if self.has("Homing_Offset") else 0

    def _start_move(self) -> None:
        goal = self.get("Goal_Position")
        low, high = self.get("Min_Position_Limit"), self.get("Max_Position_Limit")
        if low or high:  # 0 and 0: multi-turn, no limits
            goal = max(low, min(high, goal))
        target = goal + self._offset()
        speed = abs(self.get("Goal_Velocity")) or DEFAULT_SPEED
        self._move = (self.actual, float(target), time.monotonic(),
                      abs(target - self.actual) / speed)

    def update(self) -> None:
        velocity = 0
        if self.hand is not None:
            self.actual, done = self.hand.now()
            if done or self.get("Torque_Enable"):
                self.hand = None
        if self._move is not None:
            start, goal, t0, seconds = self._move
            fraction = 1.0 if seconds <= 0 else min(1.0, (time.monotonic() - t0) / seconds)
            self.actual = start + (goal - start) * fraction
            if fraction < 1.0:
                velocity = round((goal - start) / seconds)
            else:
                self._move = None
        self.set("Present_Velocity", max(-32767, min(32767, velocity)))
        self.set("Moving", int(velocity != 0))
        if self.has("Present_Load"):
            self.set("Present_Load", 80 if velocity else 0)
        if self.has("Present_Current"):
            self.set("Present_Current", 20 if velocity else 0)
        present = round(self.actual) - self._offset()
        full_angle = self.get("Phase") & 0x10
        if not full_angle:
            present %= self.model.resolution
        self.set("Present_Position", max(-32767, min(32767, present)))


class FeetechBus:
    """The servos on one bus: request bytes in (read by the bus's device session, which also
    says who answers), the servos' statuses out. ``baud``: the rate the servos listen at
    (each servo's own Baud_Rate code); None: they hear any."""

    def __init__(self, servos: list[Servo], baud: int | None = None) -> None:
        self.servos = list(servos)
        self.baud = baud
        self.line_baud: int | None = None
        self.missing: set[int] = set()
        self.session = codec.session(codec.DEVICE)
        if baud is not None:
            code = next((c for c, b in BAUD_RATES.items() if b == baud), None)
            if code is None:
                raise ValueError(f"{baud} is not a Feetech baud rate")
            for servo in servos:
                servo.memory[6] = code
                servo.saved = bytes(servo.memory[:40])

    def at(self, device_id: int) -> list[Servo]:
        """The servos that hear a request to ``device_id`` (every one for broadcast)."""
        return [s for s in self.servos
                if (device_id == codec.BROADCAST_ID or s.id == device_id)
                and s.id not in self.missing and s.connected
                and (self.baud is None or s.baud == self.line_baud)]

    def serve(self, data: bytes) -> list[tuple[int, Replies]]:
        return [(r.size, self.handle(r)) for r in self.session.receive_requests(data)]

    def _status(self, servos: list[Servo], data: list[bytes | None],
                at: int | None = None) -> Replies:
        """The statuses of servos that answer at once (one ID): collided when several; from
        ``at``, the ID they were addressed at (a write of ID answers from the old one)."""
        packets = [self.session.reply(s.id if at is None else at, s.error(), d)
                   for s, d in zip(servos, data) if d is not None]
        if not packets:
            return []
        return [(servos[0].memory[7] * 2e-6, collide(packets))]

    def handle(self, request: Request) -> Replies:
        inst, params = request.instruction, request.params
        if inst == codec.PING:
            present = self.at(request.id)
            if request.id == codec.BROADCAST_ID:  # each answers: the SDK collects them
                by_id: dict[int, list[Servo]] = {}
                for s in present:
                    by_id.setdefault(s.id, []).append(s)
                return [r for i in sorted(by_id) for r in self._status(by_id[i], [b""] *
                                                                        len(by_id[i]))]
            return self._status(present, [b""] * len(present))
        if inst == codec.SYNC_READ and len(params) >= 2:
            replies: Replies = []
            for i in self.session.addressed(request, {s.id for s in self.servos}):
                here = [s for s in self.at(i) if s.model.sync_read]  # an SCS does not answer
                replies += self._status(here, [s.read(params[0], params[1]) for s in here])
            return replies
        if inst == codec.SYNC_WRITE and len(params) >= 2:
            address, length = params[0], params[1]
            body = params[2:]
            for k in range(0, len(body) - length, length + 1):
                for s in self.at(body[k]):
                    s.write(address, bytes(body[k + 1:k + 1 + length]))
            return []
        present = self.at(request.id)
        data = [self._single(s, inst, params) for s in present]
        answering = [(s, d) for s, d in zip(present, data)
                     if self.session.answers(request, request.id, s.memory[8])]
        return self._status([s for s, _ in answering], [d for _, d in answering], request.id)

    @staticmethod
    def _single(servo: Servo, inst: int, params: bytes) -> bytes | None:
        if inst == codec.READ and len(params) == 2:
            return servo.read(params[0], params[1])
        if inst == codec.WRITE and len(params) > 1:
            servo.write(params[0], bytes(params[1:]))
        elif inst == codec.REG_WRITE and len(params) > 1:
            servo.registered = (params[0], bytes(params[1:]))
        elif inst == codec.ACTION and servo.registered is not None:
            servo.write(*servo.registered)
            servo.registered = None
        elif inst not in (codec.WRITE, codec.REG_WRITE, codec.ACTION):
            return None  # an instruction it does not know: no answer
        return b""


class FeetechPtyServer(PtyServer):
    """A Feetech bus on a pseudo-terminal (the kit's server): ``port`` is the path a serial
    client opens; with ``pace``, the bus takes the wire time of every byte."""

    def __init__(self, bus: FeetechBus, pace: bool = False, latency: float = 0.0) -> None:
        super().__init__(bus, pace, name="feetech-sim", latency=latency)


def _model_of(hw: Hardware, joint: Component) -> Model:
    number = expected_model(hw.params, joint.params, joint.name)
    return (BY_NUMBER.get(number) if number is not None else None) or STS3215


def bus_of(ctx: ServeContext, hw: Hardware, baud: int) -> FeetechBus:
    """A block's servos at their joints' IDs, with the faults ``ctx`` names."""
    from deltoctl.families.feetech.ros2_control import servo_ids

    joints = servo_ids(ctx.profile, hw)
    ids = {j.name: i for i, j in joints.items()}
    old = {j.name for j in ctx.named("old_firmware", hw)}
    volts = {j.name for j in ctx.named("voltage", hw)}
    servos = [Servo(i, _model_of(hw, j), (3, 9) if j.name in old else (3, 10),
                    16.0 if j.name in volts else 12.0) for i, j in joints.items()]
    for servo, joint in zip(servos, joints.values(), strict=True):
        servo.joint = joint.name
    if ctx.options.factory_new:  # each at ID 1, 1 Mbps: their replies collide
        missing = {ids[j.name] for j in ctx.named("missing", hw) if j.name in ids}
        present = [s for s in servos if s.id not in missing]
        for k, servo in enumerate(present):
            servo.set("ID", 1)
            servo.actual += 300 * k  # poses of their own: their replies differ
        return FeetechBus(present, baud=1_000_000)
    bus = FeetechBus(servos, baud=baud)
    by_id = {s.id: s for s in servos}
    bus.missing |= {ids[j.name] for j in ctx.named("missing", hw) if j.name in ids}
    for joint in ctx.named("wrong_baud", hw):
        if joint.name in ids:  # 500 kbps (1 Mbps on a 500 kbps bus)
            by_id[ids[joint.name]].memory[6] = 1 if baud != 500_000 else 0
    for joint in ctx.named("overload", hw):
        if joint.name in ids:
            by_id[ids[joint.name]].latch_overload()
    for joint in ctx.named("duplicate", hw):
        if joint.name in ids:
            twin = Servo(ids[joint.name], by_id[ids[joint.name]].model)
            twin.memory[6] = by_id[ids[joint.name]].memory[6]
            twin.actual += 300  # another pose: the replies differ, so they garble
            bus.servos.append(twin)
    return bus


def serve(ctx: ServeContext, blocks: list[Hardware]) -> dict[str, str]:
    """One pseudo-terminal per bus block, its servos at the joints' IDs, listening at the bus
    URL's baud rate."""
    from deltoctl.families.feetech import parse_bus_url

    buses = {}
    shafts = {}  # joint → its emulated servo, for a hand to turn
    for hw in blocks:
        url = ctx.profile.buses.get(hw.bus or "", "serial:///dev/ttyACM0?baud=1000000")
        _, baud, _ = parse_bus_url(url)
        bus = bus_of(ctx, hw, baud)
        shafts.update((s.joint, s) for s in bus.servos if s.joint is not None)
        server = ctx.stack.enter_context(FeetechPtyServer(bus, pace=ctx.options.pace))
        query = url.split("?", 1)[1] if "?" in url else f"baud={baud}"
        buses[hw.bus or hw.name] = f"serial://{server.port}?{query}"
    add_controls(ctx.control, shafts)
    if ctx.options.factory_new:
        from deltoctl.servo import wiring

        wiring.add_controls(ctx, shafts)
    return buses
