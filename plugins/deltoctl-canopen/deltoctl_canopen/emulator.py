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

The nodes of a bus and deltoctl meet on a ``HubServer`` (loopback only): ``--sim`` serves it in
the command's process, ``deltoctl sim serve`` in a process of its own.
"""

from __future__ import annotations

import contextlib
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from deltoctl_canopen import (
    quiet,  # noqa: F401  (the libraries' log records)
    session,
)
from deltoctl_canopen.codec import Frame
from deltoctl_canopen.drive import Drive402
from deltoctl_canopen.session import Abort

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
    def __init__(self, network: Any, node_id: int, od: Any, faults: NodeFaults) -> None:
        from canopen import LocalNode

        self.network, self.faults = network, faults
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
        if faults.product_code is not None:
            self.node.data_store.setdefault(0x1018, {})[2] = \
                faults.product_code.to_bytes(4, "little")

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
            if self.faults.product_code is not None:
                self.node.data_store[0x1018] = {2: self.faults.product_code.to_bytes(4,
                                                                                  "little")}
            with self.lock:
                self.drive = self._new_drive()
        if command in session.RESETS:
            self._pdo_dirty = True
            self._heartbeat_from_od()
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
class EmulatedBus:
    """One CAN bus: its hub, a network for its nodes, and their drives."""

    hub: Any
    network: Any
    drives: dict[int, EmulatedDrive] = field(default_factory=dict)
    _stop: threading.Event = field(default_factory=threading.Event)
    _thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        return f"can://localhub/{self.hub.channel}"

    def _on_remote(self, msg: Any) -> None:
        """A remote frame, as python-can's notifier hands it: a node guarding request."""
        drive = self.drives.get(msg.arbitration_id - 0x700)
        if msg.is_remote_frame and not msg.is_extended_id and drive is not None:
            drive._on_frame(msg.arbitration_id, b"", remote=True)

    def start(self) -> EmulatedBus:
        self.network.notifier.add_listener(self._on_remote)
        for drive in self.drives.values():
            drive.boot()
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


def start_bus(nodes: dict[int, tuple[Path, NodeFaults]], host: str = "127.0.0.1",
              port: int = 0) -> EmulatedBus:
    """A hub on loopback and a drive for each node ID (EDS file, faults); started."""
    import canopen

    from deltoctl_canopen import eds
    from deltoctl_canopen.hub import HubBus, HubServer

    _NUMBERS.update(_number_types())
    hub = HubServer(host, port).start()
    try:
        network = canopen.Network(HubBus(channel=hub.channel))
        network.connect()
        bus = EmulatedBus(hub, network)
        for node_id, (eds_path, faults) in nodes.items():
            od = eds.load(eds_path, node_id)
            bus.drives[node_id] = EmulatedDrive(network, node_id, od, faults)
        return bus.start()
    except BaseException:
        hub.close()
        raise


def serve(ctx: ServeContext, blocks: list[Hardware]) -> dict[str, str]:
    """Every CANopen block's drives on one hub per bus: ``{bus: can://localhub/…}``."""
    from deltoctl_canopen.nodes import block_nodes

    o = ctx.options
    named = {option: {j.name for hw in blocks for j in ctx.named(option, hw)}
             for option in ("missing", "stall", "drive_fault", "heartbeat_stops")}
    by_bus: dict[str, dict[int, tuple[Path, NodeFaults]]] = {}
    for hw in blocks:
        nodes = by_bus.setdefault(hw.bus or hw.name, {})
        for joint, node in block_nodes(ctx.profile, hw).items():
            if joint in named["missing"]:
                continue
            faults = NodeFaults(
                product_code=o.wrong_identity, stall=joint in named["stall"],
                silent_after=o.heartbeat_stops_after if joint in named["heartbeat_stops"]
                else None, fault_at_start=OVER_CURRENT if joint in named["drive_fault"] else None)
            nodes[node.node_id] = (node.dcf, faults)
        ctx.blocks[hw.name] = {"nodes": sorted(nodes)}
    buses = {}
    for name, nodes in by_bus.items():
        bus = ctx.stack.enter_context(start_bus(nodes, host=_loopback(o.host)))
        buses[name] = bus.url
    return buses


def _loopback(host: str) -> str:
    """The hub listens on loopback only: any other --host is served on 127.0.0.1."""
    import ipaddress

    with contextlib.suppress(ValueError):
        if ipaddress.ip_address(host).is_loopback:
            return host
    return "127.0.0.1"
