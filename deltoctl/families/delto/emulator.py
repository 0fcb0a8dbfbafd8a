"""A Delto gripper emulator: the developer-mode protocol on a real loopback TCP server.

The firmware model answers GET_VERSION and GET_DATA and obeys SET_DUTY, SET_GPIO and
SET_FT_SENSOR_OFFSET. Joints are driven by duty through simple dynamics (URDF limits stop
them), temperatures follow current, fingertip F/T read gravity plus noise plus a drifting
offset that the tare removes; tactile fingertips read a pressure blob that grows with the
torque a finger's motors push against a stop or an object (a stalled joint), and nothing while
the finger moves freely. Faults: dropped connection, stalled joint, delay, truncated frame.
"""

from __future__ import annotations

import contextlib
import heapq
import math
import random
import selectors
import socket
import socketserver
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from operator import add, sub
from typing import TYPE_CHECKING, Any

from deltoctl.core.emulator_contract import ServeContext
from deltoctl.errors import InvalidInput, ProtocolError
from deltoctl.families.delto import codec
from deltoctl.families.delto.models import (
    FT_6AXIS,
    FT_TYPES,
    KT,
    MAX_VOLTAGE,
    MODEL_SENSORS,
    MODELS,
    RM,
    SENSOR_NONE,
    TACTILE_GRIDS,
    DeltoModel,
    TactileGrid,
)
from deltoctl.families.delto.session import NEED_DATA, Role, Session

if TYPE_CHECKING:
    from deltoctl.profile.model import Hardware, Profile

INERTIA = 0.01  # kg·m², seen at the joint
DAMPING = 0.5  # N·m·s/rad
FRICTION = 0.01  # N·m
FT_NOISE = 0.02  # N (torques: 1/10 of it in N·m)
FT_DRIFT = 0.005  # N/s, random walk of the sensor offset (torques: 1/10 of it in N·m/s)
GRAVITY = (0.0, 0.0, -0.49)  # N on each fingertip (50 g)
FT_OFFSET_FROM = (2, 3)  # firmware that added SET_FT_SENSOR_OFFSET
TICK = 0.001  # s: the model moves in 1 ms steps, however often it is asked
# Tactile contact: a finger pressing with this much torque (summed over its blocked joints)
# fills its blob's peak; the peak's full scale per cell type (uint8; a 12-bit reading in uint16)
TACTILE_FULL_TORQUE = 0.5  # N·m
TACTILE_FULL_SCALE = {"B": 255, "H": 4095}
MAX_STEPS = 1000


@dataclass
class Faults:
    delay: float = 0.0  # s added before every reply
    truncate_next: bool = False  # cut the next reply short
    stalled: set[int] = field(default_factory=set)  # motor indexes (0-based) that cannot move


class DeltoFirmware:
    """The device: state and protocol handling, stepped in simulated time."""

    def __init__(self, model: DeltoModel, firmware: tuple[int, int] = (3, 0),
                 sensor_type: int | None = None, short_version: bool = False,
                 limits: list[tuple[float, float]] | None = None, seed: int = 0) -> None:
        self.model = model
        self.firmware = firmware
        if sensor_type is None:  # what the model ships with
            sensor_type = SENSOR_NONE if model.legacy else MODEL_SENSORS.get(
                model.id, (FT_6AXIS,))[0]
        self.sensor_type = sensor_type
        self.short_version = short_version
        n = model.motors
        self.limits = limits or [(-math.pi / 2, math.pi / 2)] * n
        self.position = [0.0] * n
        self.velocity = [0.0] * n
        self.current = [0.0] * n  # mA
        self.temperature = [28.0] * n
        self.duty = [0] * n  # as received, 0.1 %
        self.pressing = [0.0] * n  # N·m a blocked joint pushes against its stop or object
        self.finger_of = finger_of_motors(model)
        self.gpio_out = [False, False, False]
        self.input_1 = False
        self.rng = random.Random(seed)
        self.ft_offset = [[self.rng.uniform(-2, 2) for _ in range(6)] for _ in range(model.fingers)]
        self.ft_tare = [[0.0] * 6 for _ in range(model.fingers)]
        # what a test puts on a fingertip (N, from ``put_mass``) and a steady offset creep per
        # axis (N/s, N·m/s: sim serve --ft-creep)
        self.ft_load = [[0.0, 0.0, 0.0] for _ in range(model.fingers)]
        self.ft_creep = (0.0, 0.0, 0.0)
        self.faults = Faults()
        self.direction = model.direction(firmware)  # the motors' wiring for this firmware
        self.lock = threading.Lock()
        self.last_step = time.monotonic()
        self._drift_dt = 0.0
        gauss = [self.rng.gauss(0.0, 1.0) for _ in range(4099)]  # a prime-length cycle
        scale = (FT_NOISE,) * 3 + (FT_NOISE / 10,) * 3
        self._noise = [tuple(gauss[(at + k) % len(gauss)] * scale[k] for k in range(6))
                       for at in range(len(gauss))]  # the six axes' noise from each start
        self._noise_at = 0
        self._replies: dict[bytes, bytes] = {}  # this tick's GET_DATA replies, by request

    # -- simulated time ----------------------------------------------------------------------
    def advance(self, now: float | None = None) -> None:
        """Bring the model up to ``now`` in whole ticks; a long gap is covered in at most
        MAX_STEPS steps (at most 5 s of it)."""
        now = time.monotonic() if now is None else now
        elapsed = now - self.last_step
        if elapsed < TICK:
            return
        steps = int(elapsed / TICK)
        if steps > MAX_STEPS:
            steps, dt = MAX_STEPS, min(elapsed, 5.0) / MAX_STEPS
            self.last_step = now
        else:
            dt = TICK
            self.last_step += steps * TICK
        for _ in range(steps):
            self.step(dt)
        self._replies.clear()  # a new sample

    def step(self, dt: float) -> None:
        for i in range(self.model.motors):
            self.pressing[i] = 0.0
            if not self.duty[i] and not self.velocity[i]:
                self.current[i] = 0.0
                self.temperature[i] -= 0.01 * (self.temperature[i] - 25.0) * dt
                continue
            duty_pct = self.duty[i] / 10.0 * self.direction[i]
            torque = duty_pct / 100.0 * MAX_VOLTAGE * KT / RM
            self.current[i] = torque / KT * 1000.0
            if i in self.faults.stalled:  # held by an object: it takes the whole torque
                self.velocity[i] = 0.0
                self.pressing[i] = abs(torque)
            else:
                v = self.velocity[i]
                drag = DAMPING * v + (math.copysign(FRICTION, v) if v else 0.0)
                if not v and abs(torque) <= FRICTION:
                    drag = torque
                self.velocity[i] = v + (torque - drag) / INERTIA * dt
                self.position[i] += self.velocity[i] * dt
                lo, hi = self.limits[i]
                if self.position[i] <= lo or self.position[i] >= hi:
                    self.position[i] = min(hi, max(lo, self.position[i]))
                    self.velocity[i] = 0.0
                    if (torque > 0) == (self.position[i] >= hi):  # pushing into the stop
                        self.pressing[i] = abs(torque)
            amps = self.current[i] / 1000.0
            self.temperature[i] += (2.0 * amps * amps - 0.01 * (self.temperature[i] - 25.0)) * dt
        self._drift_dt += dt
        if self._drift_dt >= 0.01:  # the offsets wander slowly: a step each 10 ms is enough
            sigma = FT_DRIFT * math.sqrt(self._drift_dt)
            for offset in self.ft_offset:
                for k in range(6):
                    offset[k] += self.rng.gauss(0.0, sigma if k < 3 else sigma / 10)
                for k, creep in enumerate(self.ft_creep):
                    offset[k] += creep * self._drift_dt
            self._drift_dt = 0.0

    # -- the protocol ------------------------------------------------------------------------
    def handle(self, data: bytes) -> bytes | None:
        """One request frame in, the reply frame (or None) out."""
        with self.lock:
            self.advance()
            cmd = data[2]
            if cmd == codec.GET_VERSION:
                sensor = None if self.short_version else self.sensor_type
                mask = (1 << self.model.fingers) - 1
                return codec.encode_version_reply(codec.VersionInfo(
                    self.model.id, self.firmware, sensor, mask))
            if cmd == codec.GET_DATA:  # sampled once a tick: polled faster, the same sample
                reply = self._replies.get(data)
                if reply is None:
                    codes = codec.decode_data_request(data)
                    reply = self._replies[data] = codec.encode_data_reply(
                        self.record(), self.model, codes, self.sensor_type)
                return reply
            if cmd == codec.SET_DUTY:
                for motor, duty in codec.decode_duty(data).items():
                    if 1 <= motor <= self.model.motors:
                        self.duty[motor - 1] = duty
                return None
            self._replies.clear()  # a command may change what the next reply says
            if cmd == codec.SET_GPIO:
                if self.model.gpio:
                    self.gpio_out = list(codec.decode_gpio(data))
                return None
            if cmd == codec.SET_FT_SENSOR_OFFSET:
                if self.firmware < FT_OFFSET_FROM:
                    return None  # firmware before 2.3 has no OFFSET command
                self.ft_tare = [list(self._ft_raw(f, noise=False)) for f in
                                range(self.model.fingers)]
                return None
            raise ProtocolError(f"unknown command {cmd:#04x}")

    def put_mass(self, finger: int, kg: float) -> None:
        """A mass on fingertip ``finger`` (0-based), its weight along the sensor's −z."""
        with self.lock:
            self.ft_load[finger] = [0.0, 0.0, -kg * 9.80665]

    def _ft_raw(self, finger: int, noise: bool = True) -> tuple[float, ...]:
        o, load = self.ft_offset[finger], self.ft_load[finger]
        base = (GRAVITY[0] + o[0] + load[0], GRAVITY[1] + o[1] + load[1],
                GRAVITY[2] + o[2] + load[2], o[3], o[4], o[5])
        if not noise:
            return base
        at = self._noise_at
        self._noise_at = (at + 7) % len(self._noise)
        return tuple(map(add, base, self._noise[at]))

    def record(self) -> codec.DataRecord:
        fingers = range(self.model.fingers)
        ft, tactile = [], []
        if self.sensor_type in FT_TYPES:
            ft = [tuple(map(sub, self._ft_raw(f), self.ft_tare[f])) for f in fingers]
        elif self.sensor_type in TACTILE_GRIDS:
            grid = TACTILE_GRIDS[self.sensor_type]
            press = [0.0] * self.model.fingers
            for i, torque in enumerate(self.pressing):
                press[self.finger_of[i]] += torque
            tactile = [contact_cells(grid, f, press[f]) for f in fingers]
        return codec.DataRecord(
            position=list(self.position), current=list(self.current),
            temperature=list(self.temperature), velocity=list(self.velocity), ft=ft,
            tactile=tactile, gpio=(*self.gpio_out, self.input_1))


def finger_of_motors(model: DeltoModel) -> list[int]:
    """The finger (0-based) each motor moves: the motors go finger by finger; the DG-4F's two
    last ones are the inner joints of fingers 1 and 4."""
    per = max(1, model.motors // model.fingers)
    extra = {0x4F02: (0, 3)}.get(model.id, ())
    return [min(i // per, model.fingers - 1) if i < per * model.fingers
            else extra[i - per * model.fingers] if i - per * model.fingers < len(extra)
            else model.fingers - 1 for i in range(model.motors)]


def contact_cells(grid: TactileGrid, finger: int, torque: float) -> tuple[int, ...]:
    """One fingertip's cells (wire order) for a finger pressing with ``torque`` N·m: zero
    without contact, else a round blob whose peak and width grow with the torque. Its centre
    sits a row apart from finger to finger, so the fingers' maps differ."""
    level = min(1.0, torque / TACTILE_FULL_TORQUE)
    if level <= 0.0:
        return (0,) * grid.cells
    peak = TACTILE_FULL_SCALE[grid.code] * level
    sigma = 0.5 + 1.5 * level  # cells
    row0 = grid.rows // 2 + finger % 3 - 1  # on a cell: the peak is read whole
    col0 = grid.cols // 2
    return tuple(int(peak * math.exp(-((r - row0) ** 2 + (c - col0) ** 2) / (2 * sigma ** 2)))
                 for r in range(grid.rows) for c in range(grid.cols))


def profile_sensor_type(hw: Hardware) -> int | None:
    """The fingertip sensor a block's profile declares: tactile grids by their size, F/T, or
    None (the model's own)."""
    for sensor in hw.sensors:
        cells = [i.name for i in sensor.state_interfaces if i.name.startswith("cell_")]
        for kind, grid in TACTILE_GRIDS.items():
            if len(cells) == grid.cells and f"cell_{grid.rows - 1}_{grid.cols - 1}" in cells:
                return kind
        if sensor.state("force.x"):
            return FT_6AXIS
    return None


def _replies(session: Session, firmware: DeltoFirmware, data: bytes) -> Iterator[bytes]:
    """The replies due to the requests ``data`` completes, in turn; ProtocolError when the
    client's bytes break the protocol (its connection is then closed)."""
    session.receive_data(data)
    while (request := session.next_event()) is not NEED_DATA:
        reply = firmware.handle(request.frame)  # type: ignore[union-attr]
        if reply is not None:
            yield session.send(reply)


class _Handler(socketserver.BaseRequestHandler):
    server: DeltoServer

    def handle(self) -> None:
        sock: socket.socket = self.request
        self.server.track(sock, True)
        session = Session(Role.DEVICE)
        firmware = self.server.firmware
        try:
            while True:
                data = sock.recv(4096)
                if not data:
                    return
                for reply in _replies(session, firmware, data):
                    if firmware.faults.delay:
                        time.sleep(firmware.faults.delay)
                    if firmware.faults.truncate_next:
                        firmware.faults.truncate_next = False
                        reply = reply[: len(reply) // 2]
                    sock.sendall(reply)
        except (OSError, ProtocolError):
            return
        finally:
            self.server.track(sock, False)


class DeltoHub:
    """One thread serving the connections of several emulated grippers (``serve``): a
    wake-up answers every request that has arrived, so a controller asking four grippers at
    once wakes one thread, not four, and their replies go out together. A delayed reply
    (the delay fault) waits in a queue, not in a sleep that would hold the others'."""

    def __init__(self) -> None:
        self.selector = selectors.DefaultSelector()
        self._wake, self._waker = socket.socketpair()
        self._wake.setblocking(False)
        self.selector.register(self._wake, selectors.EVENT_READ)
        self._added: list[tuple[socket.socket, DeltoServer]] = []
        self._due: list[tuple[float, int, socket.socket, DeltoServer, bytes]] = []
        self._count = 0  # orders delayed replies due at the same time
        self._lock = threading.Lock()
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="delto-sim-hub", daemon=True)
        self._thread.start()

    def add(self, sock: socket.socket, server: DeltoServer) -> None:
        """A client's connection to ``server``, served by the hub's thread from now on."""
        with self._lock:
            self._added.append((sock, server))
        self._waker.send(b"\0")

    def close(self) -> None:
        self._closed = True
        with contextlib.suppress(OSError):
            self._waker.send(b"\0")
        self._thread.join(timeout=5)
        for key in list(self.selector.get_map().values()):
            key.fileobj.close()  # type: ignore[union-attr]
        self.selector.close()
        self._waker.close()

    def _run(self) -> None:
        while not self._closed:
            timeout = max(0.0, self._due[0][0] - time.monotonic()) if self._due else None
            replies: list[tuple[socket.socket, DeltoServer, bytes]] = []
            for key, _ in self.selector.select(timeout):
                if key.data is None:
                    self._take_added()
                else:
                    replies += self._answer(key.fileobj, *key.data)  # type: ignore[arg-type]
            while self._due and self._due[0][0] <= time.monotonic():
                replies.append(heapq.heappop(self._due)[2:])
            for sock, server, reply in replies:
                self._send(sock, server, reply)

    def _take_added(self) -> None:
        with contextlib.suppress(OSError):
            self._wake.recv(4096)
        with self._lock:
            added, self._added = self._added, []
        for sock, server in added:
            sock.setblocking(False)
            self.selector.register(sock, selectors.EVENT_READ, (server, Session(Role.DEVICE)))

    def _answer(self, sock: socket.socket, server: DeltoServer,
                session: Session) -> list[tuple[socket.socket, DeltoServer, bytes]]:
        """The replies due now to what the client sent; its connection closed when it
        closed it or sent what is not a frame (after the replies to the frames before)."""
        try:
            data = sock.recv(4096)
        except BlockingIOError:
            return []
        except OSError:
            data = b""
        replies, alive = [], bool(data)
        firmware = server.firmware
        try:
            for reply in _replies(session, firmware, data) if alive else ():
                if firmware.faults.delay:
                    self._count += 1
                    heapq.heappush(self._due, (time.monotonic() + firmware.faults.delay,
                                               self._count, sock, server, reply))
                else:
                    replies.append((sock, server, reply))
        except ProtocolError:
            alive = False
        if alive:
            return replies
        for reply in replies:
            self._send(*reply)
        self._drop(sock, server)
        return []

    def _send(self, sock: socket.socket, server: DeltoServer, reply: bytes) -> None:
        """A reply, whole in one call (a client that leaves its replies unread until the
        socket's buffer is full is cut off)."""
        if server.firmware.faults.truncate_next:
            server.firmware.faults.truncate_next = False
            reply = reply[: len(reply) // 2]
        try:
            if sock.send(reply) == len(reply):
                return
        except OSError:
            pass
        self._drop(sock, server)

    def _drop(self, sock: socket.socket, server: DeltoServer) -> None:
        with contextlib.suppress(KeyError, ValueError):
            self.selector.unregister(sock)
        sock.close()
        server.track(sock, False)


class DeltoServer(socketserver.ThreadingTCPServer):
    """``with DeltoServer(firmware) as server: server.endpoint``; serves until closed: each
    connection in a thread of its own, or by ``hub``'s thread."""

    daemon_threads = True
    allow_reuse_address = True

    def __init__(self, firmware: DeltoFirmware, host: str = "127.0.0.1", port: int = 0,
                 hub: DeltoHub | None = None) -> None:
        super().__init__((host, port), _Handler)
        self.firmware = firmware
        self.hub = hub
        self.clients: set[socket.socket] = set()
        self._clients_lock = threading.Lock()
        self._thread = threading.Thread(target=self.serve_forever, name="delto-sim",
                                        daemon=True)

    @property
    def endpoint(self) -> str:
        host, port = self.server_address[:2]
        return f"tcp://{host}:{port}"

    def start(self) -> DeltoServer:
        self._thread.start()
        return self

    def process_request(self, request: Any, client_address: Any) -> None:
        if self.hub is None:
            super().process_request(request, client_address)
            return
        self.track(request, True)
        self.hub.add(request, self)

    def track(self, sock: socket.socket, alive: bool) -> None:
        with self._clients_lock:
            (self.clients.add if alive else self.clients.discard)(sock)

    def drop_connections(self) -> None:
        """Fault: cut every open connection, as a pulled cable or a reboot would."""
        with self._clients_lock:
            for sock in list(self.clients):
                with contextlib.suppress(OSError):
                    sock.shutdown(socket.SHUT_RDWR)
                if self.hub is None:  # else the hub closes it, seeing it shut
                    sock.close()
            self.clients.clear()

    def close(self) -> None:
        self.shutdown()
        self.drop_connections()
        self.server_close()

    def __enter__(self) -> DeltoServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()


def firmware_for_block(hw: Hardware, model_id: int | None = None,
                       **kwargs: Any) -> DeltoFirmware:
    """An emulated gripper for a block: its model (unless another is asked for, to rehearse
    a mismatch) and its joint limits."""
    model = MODELS[model_id or int(hw.params.get("delto_model", "0"), 0)]
    limits = []
    for joint in hw.joints:
        lim = joint.limits
        lo = lim.lower if lim and lim.lower is not None else -math.pi
        hi = lim.upper if lim and lim.upper is not None else math.pi
        limits.append((lo, hi))
    limits += [(-math.pi, math.pi)] * (model.motors - len(limits))
    if kwargs.get("sensor_type") is None and not model.legacy:
        kwargs["sensor_type"] = profile_sensor_type(hw)
    return DeltoFirmware(model, limits=limits[: model.motors], **kwargs)


def firmware_for_profile(profile: Profile, model_id: int | None = None,
                         **kwargs: Any) -> DeltoFirmware:
    """The emulated gripper of a profile's first block."""
    return firmware_for_block(profile.hardware[0], model_id, **kwargs)


def serve(ctx: ServeContext, blocks: list[Hardware]) -> dict[str, str]:
    """One gripper on loopback TCP per block (the first on ``--port`` when one is given)."""
    o = ctx.options
    try:
        major, minor = (int(x) for x in o.firmware.split("."))
    except ValueError:
        raise InvalidInput(f"--firmware {o.firmware!r} is not MAJOR.MINOR (e.g. 2.8)") from None
    if o.model_id is not None and o.model_id not in MODELS:
        raise InvalidInput(f"--model-id {o.model_id:#06x} is not a Delto model "
                           f"({', '.join(f'{m:#06x}' for m in MODELS)})")
    buses = {}
    hub = None  # one gripper: a thread per connection; several: one thread answers all
    if len(blocks) > 1:
        hub = DeltoHub()
        ctx.stack.callback(hub.close)
    for n, hw in enumerate(blocks):
        device = firmware_for_block(hw, model_id=o.model_id, firmware=(major, minor),
                                    short_version=o.short_version)
        device.input_1 = o.input_1
        device.faults.delay = o.delay
        device.faults.stalled |= {hw.joints.index(j) for j in ctx.named("stall", hw)}
        if o.ft_creep:
            device.ft_creep = tuple(o.ft_creep)
        server = ctx.stack.enter_context(
            DeltoServer(device, host=o.host, port=o.port if n == 0 else 0, hub=hub))
        buses[hw.bus or hw.name] = server.endpoint
        ctx.blocks[hw.name] = {"endpoint": server.endpoint, "model": device.model.name,
                               "firmware": o.firmware}
    return buses
