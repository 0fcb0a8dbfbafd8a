"""Emulated CiA 402 drives: real CANopen slaves on a local hub.

Each node talks through the node side of deltoctl's CANopen conversation
(``session.Device``: its SDO server, NMT state, boot-up, heartbeat from 0x1017 and guarding
replies) over the object dictionary of the node's EDS, kept by canopen's ``LocalNode`` with
its EMCY producer and PDO maps, and a ``Drive402`` behind the objects a drive computes
(statusword, positions, velocities, error code). RPDOs are applied when they come (types
254/255) or at the next SYNC (0-240); TPDOs go out on SYNC (types 1-240) or when their data
change (254/255), in OPERATIONAL only. A node can be missing, report another product code, stall
(its following error faults it: EMCY 0x8611) or fall silent after a while (no heartbeat,
no reply).

Each drive is an LSS slave too (``session.LssSlave``, CiA 305), its LSS address its EDS's
identity with a serial of its own: served factory-new it has no node ID, and is a CANopen node
only once LSS gives it one. A drive can be connected and disconnected while served (power on:
it comes up at the node ID it stored).

The nodes of a bus and deltoctl meet on a ``HubServer`` (loopback only): ``--sim`` serves it in
the command's process, ``deltoctl sim serve`` in a process of its own.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from deltoctl_canopen import (
    quiet,  # noqa: F401  (the libraries' log records)
    session,
)
from deltoctl_canopen.codec import Frame
from deltoctl_canopen.drive import Drive402
from deltoctl_canopen.session import UNCONFIGURED, Abort

if TYPE_CHECKING:
    from deltoctl.core.emulator_contract import ServeContext
    from deltoctl.profile.model import Hardware


TICK = 0.005  # s: event TPDOs, the following error, a node falling silent
SAVE_SIGNATURE = 0x65766173  # "save", written to 0x1010
OVER_CURRENT = 0x2310  # the error code of --drive-fault


@dataclass
class NodeFaults:
    product_code: int | None = None  # report another product than the EDS's
    stall: bool = False  # the axis cannot move: a move faults on its following error
    silent_after: float | None = None  # s after start: the node stops (no heartbeat, no reply)
    fault_at_start: int | None = None  # an error code the drive boots into Fault with


class EmulatedDrive:
    def __init__(self, network: Any, node_id: int, od: Any, faults: NodeFaults,
                 serial: int | None = None) -> None:
        from canopen import LocalNode

        self.network, self.faults, self.serial = network, faults, serial
        self.on_reset: Any = None  # called after an NMT reset communication or node
        self.lock = threading.RLock()
        self.node = LocalNode(node_id, od)
        self.silent = False
        self.drive = self._new_drive()
        self.started = time.monotonic()
        self.saved = 0  # how many times 0x1010 was written
        self._sync_rpdo: list[tuple[Any, bytes]] = []
        self._sent: dict[int, bytes] = {}
        self._pdo_dirty = True
        self.session = session.Device(node_id, self._read_object, self._write_object)
        self._beat_ms = 0  # 0x1017, the heartbeat's period
        self._beat_at = 0.0
        self.node.add_read_callback(self._on_read)
        self.node.add_write_callback(self._on_write)
        network.add_node(self.node)
        # the conversation is the session's: canopen's own SDO server and NMT slave stay off
        network.unsubscribe(0x600 + node_id, self.node.sdo.on_request)
        network.unsubscribe(0x000, self.node.nmt.on_command)
        for can_id in (0x000, 0x080, 0x600 + node_id):
            network.subscribe(can_id, self._on_frame)
        self._set_identity()

    def _set_identity(self) -> None:
        """0x1018 as this drive reports it: another product code (a fault), its own serial."""
        for sub, value in ((2, self.faults.product_code), (4, self.serial)):
            if value is not None:
                self.node.data_store.setdefault(0x1018, {})[sub] = value.to_bytes(4, "little")

    def detach(self) -> None:
        """Off the bus for good (powered off, or restarted at another node ID)."""
        self.silent = True
        node_id = self.node.id
        for can_id in (0x000, 0x080, 0x600 + node_id):
            with contextlib.suppress(KeyError, ValueError):
                self.network.unsubscribe(can_id, self._on_frame)
        if self.network.nodes.get(node_id) is self.node:
            del self.network.nodes[node_id]

    def _new_drive(self) -> Drive402:
        drive = Drive402(time.monotonic(), on_fault=self._emcy)
        od = self.node.object_dictionary
        for index, sub in drive.params:
            with contextlib.suppress(KeyError):
                obj = od[index] if sub == 0 and not hasattr(od[index], "subindices") \
                    else od[index][sub]
                if obj.default is not None:
                    drive.params[index, sub] = int(obj.default)
        drive.stalled = self.faults.stall
        if self.faults.fault_at_start:
            drive.fault(self.faults.fault_at_start, time.monotonic())
        return drive

    def boot(self) -> None:
        """Power on: boot-up message, then PRE-OPERATIONAL (heartbeat as 0x1017 says)."""
        self._send(self.session.boot())
        self._heartbeat_from_od()

    def _send(self, frame: Frame) -> None:
        with contextlib.suppress(Exception):  # a hub gone: the bus is closing
            self.network.send_message(frame.can_id, frame.data)

    def _heartbeat_from_od(self) -> None:
        with contextlib.suppress(Exception):
            self._beat_ms = int.from_bytes(self.node.get_data(0x1017, 0), "little")
        self._beat_at = time.monotonic()

    # -- the object dictionary ---------------------------------------------------------------
    def _on_read(self, index: int, subindex: int, od: Any) -> Any:
        with self.lock:
            return self.drive.read(index, subindex, time.monotonic()) \
                if self._live(index) else None

    @staticmethod
    def _live(index: int) -> bool:
        return index >= 0x6000 or index in (0x1001,)

    def _read_object(self, index: int, sub: int) -> bytes:
        from canopen.sdo import SdoAbortedError

        try:
            return bytes(self.node.get_data(index, sub, check_readable=True))
        except SdoAbortedError as exc:
            raise Abort(exc.code) from None

    def _write_object(self, index: int, sub: int, data: bytes) -> None:
        """An SDO download: the object there and writable, its length its type's, then the
        drive's own checks (``_on_write``), then stored."""
        obj = self.node.object_dictionary[index]  # KeyError: no such object
        if hasattr(obj, "subindices"):
            if sub not in obj:
                raise Abort(0x06090011)
            obj = obj[sub]
        if not obj.writable:
            raise Abort(0x06010002)
        if obj.data_type in _NUMBERS and 8 * len(data) != len(obj):
            raise Abort(session.ABORT_LENGTH)
        self._on_write(index, sub, obj, data)
        self.node.data_store.setdefault(index, {})[sub] = bytes(data)
        if index == 0x1017:
            self._beat_ms = int.from_bytes(data, "little")

    def _on_write(self, index: int, subindex: int, od: Any, data: bytes) -> None:
        if index == 0x1010:
            if int.from_bytes(data[:4], "little") != SAVE_SIGNATURE:
                raise Abort(0x08000020)
            self.saved += 1
            return
        if 0x1400 <= index <= 0x1BFF:
            self._pdo_dirty = True
            return
        if od.data_type in _NUMBERS and index >= 0x6000:
            value = od.decode_raw(data)
            low, high = od.min, od.max
            if (low is not None and value < low) or (high is not None and value > high):
                raise Abort(0x06090030)
            with self.lock:
                self.drive.write(index, subindex, int(value), time.monotonic())
            if index == 0x6040:
                self.send_event_pdos()

    def _emcy(self, code: int) -> None:
        if self.silent:
            return
        with contextlib.suppress(Exception):
            self.node.emcy.send(code, 0x01)

    # -- SDO, NMT, node guarding ---------------------------------------------------------------
    def _on_frame(self, can_id: int, data: bytes, timestamp: float = 0.0,
                  remote: bool = False) -> None:
        """An SDO request, an NMT command, a SYNC or a guarding request (a remote frame,
        which canopen hands no subscriber: the bus's ``_on_remote`` brings it), through the
        session."""
        if self.silent:
            return
        try:
            events = self.session.receive(Frame(can_id, bytes(data), remote=remote))
        except Exception:  # a frame no node understands: ignored, as a node does
            return
        for event in events:
            if isinstance(event, session.Send):
                self._send(event.frame)
            elif isinstance(event, session.NmtCommand):
                self._after_nmt(event.command)
            elif isinstance(event, session.Sync):
                self._on_sync()

    def _after_nmt(self, command: int) -> None:
        if command == 0x81:  # reset node: the application's values too
            self.node.data_store.clear()
            self._set_identity()
            with self.lock:
                self.drive = self._new_drive()
        if command in session.RESETS:
            self._pdo_dirty = True
            self._heartbeat_from_od()
            if self.on_reset is not None:
                self.on_reset(self)
        if command == 0x01:
            self._sent.clear()
            self.send_event_pdos()

    # -- PDOs -----------------------------------------------------------------------------------
    def _maps(self) -> tuple[list[Any], list[Any]]:
        """The enabled TPDO and RPDO maps, read again after their objects were written."""
        node = self.node
        if self._pdo_dirty:
            self._pdo_dirty = False
            for maps in (node.tpdo, node.rpdo):
                for pdo in maps.map.values():
                    with contextlib.suppress(Exception):
                        if pdo.enabled:
                            self.network.unsubscribe(pdo.cob_id, self._on_rpdo)
                    with contextlib.suppress(Exception):  # a PDO the EDS does not have
                        pdo.read(from_od=False)
            for pdo in node.rpdo.map.values():
                if pdo.enabled and pdo.cob_id:
                    self.network.subscribe(pdo.cob_id, self._on_rpdo)
        return ([p for p in node.tpdo.map.values() if p.enabled and p.cob_id and p.map],
                [p for p in node.rpdo.map.values() if p.enabled and p.cob_id and p.map])

    def _operational(self) -> bool:
        return self.session.operational and not self.silent

    def _on_rpdo(self, can_id: int, data: bytes, timestamp: float) -> None:
        if not self._operational():
            return
        for pdo in self._maps()[1]:
            if pdo.cob_id == can_id:
                if pdo.trans_type is not None and pdo.trans_type <= 240:
                    self._sync_rpdo.append((pdo, bytes(data)))
                else:
                    self._apply(pdo, bytes(data))

    def _apply(self, pdo: Any, data: bytes) -> None:
        from canopen.sdo import SdoAbortedError

        pdo.data = bytearray(data.ljust(len(pdo.data), b"\0"))
        for var in pdo.map:
            with contextlib.suppress(SdoAbortedError, Abort, KeyError):
                self.node.set_data(var.index, var.subindex, var.get_data())

    def _on_sync(self) -> None:
        if not self._operational():
            return
        pending, self._sync_rpdo = self._sync_rpdo, []
        for pdo, payload in pending:
            self._apply(pdo, payload)
        for pdo in self._maps()[0]:
            if pdo.trans_type is not None and 1 <= pdo.trans_type <= 240:
                self._transmit(pdo)

    def _pack(self, pdo: Any) -> bytes:
        for var in pdo.map:
            var.set_data(self.node.get_data(var.index, var.subindex))
        return bytes(pdo.data)

    def _transmit(self, pdo: Any) -> None:
        with contextlib.suppress(Exception):
            data = self._pack(pdo)
            self._sent[pdo.cob_id] = data
            self.network.send_message(pdo.cob_id, data)

    def send_event_pdos(self) -> None:
        """TPDOs of type 254/255 whose data changed since they were last sent."""
        if not self._operational():
            return
        for pdo in self._maps()[0]:
            if pdo.trans_type is not None and pdo.trans_type >= 254:
                with contextlib.suppress(Exception):
                    if self._pack(pdo) != self._sent.get(pdo.cob_id):
                        self._transmit(pdo)

    def tick(self, now: float) -> None:
        after = self.faults.silent_after
        if after is not None and not self.silent and now - self.started >= after:
            self.silent = True  # a dead node: no heartbeat, no reply, no PDO
            return
        if self.silent:
            return
        if self._beat_ms and now >= self._beat_at:
            self._beat_at = max(self._beat_at + self._beat_ms / 1000, now)
            self._send(self.session.heartbeat())
        with self.lock:
            self.drive.update(now)
        self.send_event_pdos()


_NUMBERS: set[int] = set()


def _number_types() -> set[int]:
    from canopen.objectdictionary import datatypes

    return set(datatypes.INTEGER_TYPES) | set(datatypes.FLOAT_TYPES)


@dataclass
class Part:
    """One drive as it sits on a bus: its joint, EDS, faults and LSS address (vendor, product
    and revision its EDS's, its own serial), the node ID it stored (``UNCONFIGURED``: as it
    leaves the factory), whether it is connected (powered, on the wire), and while it is, its
    LSS slave and, once it has a node ID, its CANopen node."""

    name: str
    eds: Path
    faults: NodeFaults
    identity: tuple[int, int, int, int]
    node: int = UNCONFIGURED
    bit_timing: int = 0
    connected: bool = True
    lss: session.LssSlave | None = None
    drive: EmulatedDrive | None = None


def part_of(name: str, eds_path: Path, faults: NodeFaults, node: int = UNCONFIGURED,
            serial: int | None = None) -> Part:
    """A part whose LSS address is its EDS's 0x1018 (the product code a fault gives), with
    ``serial`` (default: one of its own, from its name)."""
    import zlib

    from deltoctl_canopen import eds

    od = eds.load(eds_path, 1)
    vendor, product, revision = (_default(od, sub) for sub in (1, 2, 3))
    if faults.product_code is not None:
        product = faults.product_code
    serial = zlib.crc32(name.encode()) if serial is None else serial
    return Part(name, eds_path, faults, (vendor, product, revision, serial), node)


def _default(od: Any, sub: int) -> int:
    with contextlib.suppress(KeyError, TypeError, ValueError):
        return int(od[0x1018][sub].default)
    return 0


@dataclass
class EmulatedBus:
    """One CAN bus at ``bitrate``: its hub, a network for its nodes, and the drives on it.
    A drive answers LSS (CiA 305) from power-on; a CANopen node once it has a node ID. The
    LSS replies of several drives that are the same frame are one frame, as on a CAN bus."""

    hub: Any
    network: Any
    bitrate: int = 1_000_000
    parts: dict[str, Part] = field(default_factory=dict)
    lock: threading.RLock = field(default_factory=threading.RLock)
    _stop: threading.Event = field(default_factory=threading.Event)
    _thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        return f"can://localhub/{self.hub.channel}"

    @property
    def drives(self) -> dict[int, EmulatedDrive]:
        """The CANopen nodes on the bus now, by node ID."""
        with self.lock:
            return {p.drive.node.id: p.drive for p in self.parts.values() if p.drive}

    def add(self, part: Part) -> None:
        part.bit_timing = _bit_timing(self.bitrate)
        self.parts[part.name] = part

    def _on_remote(self, msg: Any) -> None:
        """A remote frame, as python-can's notifier hands it: a node guarding request."""
        drive = self.drives.get(msg.arbitration_id - 0x700)
        if msg.is_remote_frame and not msg.is_extended_id and drive is not None:
            drive._on_frame(msg.arbitration_id, b"", remote=True)

    def _on_lss(self, can_id: int, data: bytes, timestamp: float = 0.0) -> None:
        replies: list[Frame] = []
        with self.lock:
            for part in self.parts.values():
                if part.lss is None or not self._hears(part):
                    continue
                for event in part.lss.receive(Frame(can_id, bytes(data))):
                    if isinstance(event, session.Send) and event.frame not in replies:
                        replies.append(event.frame)
                    elif isinstance(event, session.LssStart):
                        self._start_node(part, event.node)
                    elif isinstance(event, session.LssBitRate) and part.drive is not None:
                        part.drive.silent = not self._hears(part)
        for frame in replies:
            with contextlib.suppress(Exception):  # a hub gone: the bus is closing
                self.network.send_message(frame.can_id, frame.data)

    def _hears(self, part: Part) -> bool:
        """A drive at another bit rate than the bus's neither hears nor is heard."""
        return part.lss is not None and \
            session.LSS_BITRATES[part.lss.bit_timing] == self.bitrate

    def _start_node(self, part: Part, node_id: int) -> None:
        from deltoctl_canopen import eds

        if part.drive is not None:
            part.drive.detach()
            part.drive = None
        if node_id == UNCONFIGURED or not self._hears(part):
            return
        drive = EmulatedDrive(self.network, node_id, eds.load(part.eds, node_id), part.faults,
                              serial=part.identity[3])
        drive.on_reset = lambda d, part=part: self._after_reset(part, d)
        part.drive = drive
        drive.boot()

    def _after_reset(self, part: Part, drive: EmulatedDrive) -> None:
        """An NMT reset: the node ID LSS gave it (pending) becomes its own."""
        with self.lock:
            if part.lss is not None and part.drive is drive and \
                    part.lss.pending != part.lss.node:
                self._start_node(part, part.lss.reset_communication())

    def connect(self, part: Part, on: bool = True) -> None:
        """Power a drive on (it comes up at the node ID and bit timing it stored) or off."""
        with self.lock:
            if part.lss is not None:  # what it stored survives the power cycle
                part.node, part.bit_timing = part.lss.stored, part.lss.stored_bit_timing
            if part.drive is not None:
                part.drive.detach()
            part.lss = part.drive = None
            part.connected = on
            if on:
                part.lss = session.LssSlave(part.identity, part.node, part.bit_timing)
                self._start_node(part, part.node)

    def start(self) -> EmulatedBus:
        self.network.notifier.add_listener(self._on_remote)
        self.network.subscribe(session.LSS_FROM_MASTER, self._on_lss)
        for part in self.parts.values():
            self.connect(part, part.connected)
        self._thread = threading.Thread(target=self._run, name="canopen-drives", daemon=True)
        self._thread.start()
        return self

    def _run(self) -> None:
        while not self._stop.wait(TICK):
            now = time.monotonic()
            for drive in self.drives.values():
                drive.tick(now)

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1)
        with contextlib.suppress(Exception):
            self.network.disconnect()
        self.hub.close()

    def __enter__(self) -> EmulatedBus:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _bit_timing(bitrate: int) -> int:
    """The LSS bit timing index of a rate (1 Mbit/s's when the table has no such rate)."""
    return next((i for i, rate in session.LSS_BITRATES.items() if rate == bitrate), 0)


def start_bus(nodes: dict[int, tuple[Path, NodeFaults]], host: str = "127.0.0.1",
              port: int = 0, parts: Sequence[Part] = (),
              bitrate: int = 1_000_000) -> EmulatedBus:
    """A hub on loopback, a drive for each node ID (EDS file, faults) and each of ``parts``;
    started."""
    import canopen

    from deltoctl_canopen.hub import HubBus, HubServer

    _NUMBERS.update(_number_types())
    hub = HubServer(host, port).start()
    try:
        network = canopen.Network(HubBus(channel=hub.channel))
        network.connect()
        bus = EmulatedBus(hub, network, bitrate)
        for node_id, (eds_path, faults) in nodes.items():
            bus.add(part_of(f"node {node_id}", eds_path, faults, node_id))
        for part in parts:
            bus.add(part)
        return bus.start()
    except BaseException:
        hub.close()
        raise


def serve(ctx: ServeContext, blocks: list[Hardware]) -> dict[str, str]:
    """Every CANopen block's drives on one hub per bus: ``{bus: can://localhub/…}``; with
    ``factory_new``, each drive unconfigured (LSS gives it its node ID). The control lines
    ``connect`` and ``disconnect`` power a joint's drive on and off."""
    from deltoctl_canopen.nodes import block_nodes, bus_bitrate, joint_serial

    o = ctx.options
    named = {option: {j.name for hw in blocks for j in ctx.named(option, hw)}
             for option in ("missing", "stall", "drive_fault", "heartbeat_stops")}
    by_bus: dict[str, list[Part]] = {}
    for hw in blocks:
        parts: list[Part] = []
        joints = {j.name: j for j in hw.joints}
        for joint, node in block_nodes(ctx.profile, hw).items():
            if joint in named["missing"]:
                continue
            faults = NodeFaults(
                product_code=o.wrong_identity, stall=joint in named["stall"],
                silent_after=o.heartbeat_stops_after if joint in named["heartbeat_stops"]
                else None, fault_at_start=OVER_CURRENT if joint in named["drive_fault"] else None)
            parts.append(part_of(joint, node.dcf, faults,
                                 UNCONFIGURED if o.factory_new else node.node_id,
                                 joint_serial(ctx.profile, joints[joint])))
        ctx.blocks[hw.name] = {"nodes": sorted(p.node for p in parts if p.node != UNCONFIGURED),
                               "lss_serials": {p.name: p.identity[3] for p in parts}}
        by_bus.setdefault(hw.bus or hw.name, []).extend(parts)
    buses, served = {}, []
    for name, on_bus in by_bus.items():
        bus = ctx.stack.enter_context(start_bus({}, host=_loopback(o.host), parts=on_bus,
                                                bitrate=bus_bitrate(ctx.profile, name)))
        buses[name] = bus.url
        served.append(bus)
    _controls(ctx, served)
    return buses


def _controls(ctx: ServeContext, buses: list[EmulatedBus]) -> None:
    """``connect JOINT|all`` and ``disconnect JOINT|all``: a drive plugged in (it powers on
    at the node ID it stored) or pulled out, as a technician does one drive at a time."""
    from deltoctl.errors import InvalidInput

    parts = {p.name: (bus, p) for bus in buses for p in bus.parts.values()}
    others = {j.name for hw in ctx.profile.hardware for j in hw.joints} - parts.keys()

    def switch(on: bool) -> Any:
        def handler(words: list[str]) -> str:
            if len(words) == 1 and words[0] in others:
                return ""  # another family's part: it answers for it
            if len(words) != 1 or (words[0] != "all" and words[0] not in parts):
                raise InvalidInput(f"takes one joint of a CANopen drive or all "
                                   f"({', '.join(parts)}), got {' '.join(words)!r}")
            chosen = list(parts) if words[0] == "all" else words
            for name in chosen:
                bus, part = parts[name]
                bus.connect(part, on)
            return f"canopen: {', '.join(chosen)} {'connected' if on else 'disconnected'}"
        return handler

    if parts:
        ctx.control("connect", "connect JOINT|all: that CANopen drive plugged in (powered on)",
                    switch(True))
        ctx.control("disconnect", "disconnect JOINT|all: that CANopen drive pulled out",
                    switch(False))


def _loopback(host: str) -> str:
    """The hub listens on loopback only: any other --host is served on 127.0.0.1."""
    import ipaddress

    with contextlib.suppress(ValueError):
        if ipaddress.ip_address(host).is_loopback:
            return host
    return "127.0.0.1"
