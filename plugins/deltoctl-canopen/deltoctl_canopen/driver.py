"""A CANopen bus of CiA 402 drives, one joint a node: deltoctl's master on canopen's client.

canopen's SDO client carries every SDO read and write (expedited, segmented and block
transfers, its tries and timeouts set from ``POLICY``), and its PDO maps the TPDOs and RPDOs;
the rest of the conversation is deltoctl's own master side (``session.Host``): NMT commands,
SYNC, the heartbeats and boot-ups heard, and detect's scan, whose SDO requests to every node
ID are matched to their replies there.

configure: the bus opened by its ``can://`` URL, each node's EDS read, an SDO read of 0x1000 and
0x1018 per node (the roll call), then the start-up of ros2_canopen: the node's ``sdo:`` writes,
its PDO mappings from the bus file (or those the drive has), its heartbeat, NMT start. Each
cycle sends a SYNC; the TPDOs it triggers carry the state interfaces (SDO polling for a value
no TPDO maps). Heartbeats give each node's NMT state; one that stops makes the link read as
lost; EMCYs are kept for ``/diagnostics`` and the warnings.

Moves run the drive's profile position mode (0x607A, 0x6081, controlword bit 4), homing its
homing mode (0x6098 and the offset and speeds the start-up wrote). ``stop`` sends a quick stop
to every axis that was enabled — one RPDO frame each where the controlword is mapped — and
``deactivate`` leaves every axis in Switch On Disabled.
"""

from __future__ import annotations

import contextlib
import struct
import threading
import time
from typing import Any

from deltoctl import trace
from deltoctl.core.driver import Block, Driver, HomeProgress, MoveResult, Progress
from deltoctl.core.exchange import ExchangePolicy
from deltoctl.core.loop import CommLoop
from deltoctl.errors import (
    DeltoctlError,
    DeviceError,
    DeviceFault,
    InvalidInput,
    LinkLost,
    NoAnswer,
    ProtocolError,
    Refused,
    Unreachable,
)

from deltoctl_canopen import (
    codec,
    quiet,  # noqa: F401  (the libraries' log records)
    session,
)
from deltoctl_canopen.busconfig import NodeConfig
from deltoctl_canopen.transport import parse_can_url

# an SDO request: two tries of 0.15 s, 0.1 s apart (canopen's client runs them)
POLICY = ExchangePolicy(tries=2, timeout=0.15, pause=0.1)
SCAN_WINDOW = 0.3  # s detect listens for the nodes' replies and heartbeats
STATE_TIMEOUT = 0.5  # s for each 402 transition
TPDO_WAIT = 0.005  # s a cycle waits for the TPDOs its SYNC asked for
POLL_PERIOD = 0.1  # s between two SDO reads of a value no TPDO carries
DEFAULT_HEARTBEAT_MS = 100
NAN = float("nan")
NMT_CODES = {"INITIALISING": 0, "STOPPED": 4, "OPERATIONAL": 5, "PRE-OPERATIONAL": 127}
STATE_INTERFACES = {"position": 0x6064, "velocity": 0x606C, "effort": 0x6077}


class Axis:
    """One node: its configuration, canopen's remote node, and what it last sent."""

    def __init__(self, joint: str, config: NodeConfig, node: Any) -> None:
        self.joint, self.config, self.node = joint, config, node
        self.id = config.node_id
        self.values: dict[int, int] = {}  # index → the last value a TPDO or SDO gave
        self.tpdo_mapped: set[int] = set()
        self.controlword_pdo: Any = None  # the RPDO variable of 0x6040, when mapped
        self.commands: dict[int, Any] = {}  # each RPDO-mapped object's value, as last set
        self.heartbeat_at: float | None = None
        self.nmt_state = 0
        self.enabled = False  # driven to Operation Enabled by this driver
        self.identity: dict[str, Any] = {}


class CanopenDriver(Driver):
    extra_states = ("statusword", "nmt_state")

    def __init__(self, block: Block) -> None:
        super().__init__(block)
        from deltoctl_canopen.nodes import block_nodes

        self.target = parse_can_url(self.url)  # a wrong URL: exit 2 before the bus opens
        self.configs = block_nodes(self.profile, self.hw)
        self.axes: dict[str, Axis] = {}
        self.network: Any = None
        self.emcy: list[dict[str, Any]] = []
        self.lost: str | None = None  # why the bus is lost
        self._sync_seen = threading.Event()
        self._expected = 0  # TPDO frames a SYNC triggers
        self._arrived = 0
        self._lock = threading.Lock()
        self.loop = _BusLoop(f"{self.hw.name}_sync", self)
        self._polls: list[tuple[Axis, int]] = []
        self.session = session.Host()
        self._poll_at = 0.0

    def comm_loops(self) -> list[CommLoop]:
        return [self.loop]

    # -- the bus ---------------------------------------------------------------------------
    def _open(self) -> None:
        import canopen
        from deltoctl import registry

        bus = registry.open_link(self.url)
        network = canopen.Network(bus)
        if trace.PACKETS:
            self._trace(network)
        network.connect()
        network.notifier.add_listener(_LostBus(self))
        self.network = network
        trace.link("%s: %s opened", self.hw.name, self.url)

    def _trace(self, network: Any) -> None:
        label = self.url
        send = network.send_message

        def traced_send(can_id: int, data: Any, remote: bool = False) -> None:
            frame = codec.Frame(can_id, bytes(data), False, remote)
            trace.packet(label, "tx", _wire(frame), codec.describe(frame))
            send(can_id, data, remote)

        network.send_message = traced_send
        network.listeners.append(_Tracer(label))

    def _add_axes(self) -> None:
        import canopen

        from deltoctl_canopen import eds

        for joint, config in self.configs.items():
            assert config.dcf is not None
            od = eds.load(config.dcf, config.node_id)
            node = canopen.RemoteNode(config.node_id, od)
            node.sdo.RESPONSE_TIMEOUT, node.sdo.MAX_RETRIES, node.sdo.RETRY_DELAY = (
                POLICY.timeout, POLICY.tries - 1, POLICY.pause)
            self.network.add_node(node)
            axis = Axis(joint, config, node)
            self.network.subscribe(0x700 + axis.id, self._heartbeat(axis))
            node.emcy.add_callback(self._on_emcy(axis))
            self.axes[joint] = axis

    def _heartbeat(self, axis: Axis) -> Any:
        def on_heartbeat(can_id: int, data: bytes, timestamp: float) -> None:
            try:
                events = self.session.receive(codec.Frame(can_id, bytes(data)))
            except ProtocolError:  # not a heartbeat: a guarding request, a bad frame
                return
            for event in events:
                if isinstance(event, session.Heartbeat):
                    axis.heartbeat_at = time.monotonic()
                    axis.nmt_state = event.state
        return on_heartbeat

    def _send(self, frame: codec.Frame) -> None:
        self.network.send_message(frame.can_id, frame.data, frame.remote)

    def _nmt(self, axis: Axis, command: int) -> None:
        self._send(session.nmt_frame(command, axis.id))

    def _on_emcy(self, axis: Axis) -> Any:
        def on_emcy(error: Any) -> None:
            entry = {"joint": axis.joint, "node": axis.id, "code": f"{error.code:#06x}",
                     "register": error.register, "text": error.get_desc() or "",
                     "t": time.time_ns()}
            with self._lock:
                self.emcy.append(entry)
                del self.emcy[:-32]
            if error.code:
                self.warnings.append(f"{axis.joint} (node {axis.id}): EMCY {entry['code']} "
                                     f"{entry['text']}".rstrip())
        return on_emcy

    # -- SDO ---------------------------------------------------------------------------------
    def sdo_read(self, axis: Axis, index: int, sub: int = 0) -> Any:
        from can import CanError
        from canopen.sdo import SdoAbortedError, SdoCommunicationError

        self.stats["packets"] += 1
        try:
            return _decode(axis.node, index, sub, axis.node.sdo.upload(index, sub))
        except SdoAbortedError as exc:
            self.stats["errors"] += 1
            raise DeviceFault(f"{axis.joint} (node {axis.id}) refused to read "
                              f"{index:#06x}:{sub:02x}: {_abort(exc)}", exc.code) from None
        except SdoCommunicationError as exc:
            self.stats["errors"] += 1
            raise NoAnswer(f"{axis.joint} (node {axis.id}) did not answer a read of "
                           f"{index:#06x}:{sub:02x} ({exc})") from None
        except (CanError, OSError) as exc:
            self.stats["errors"] += 1
            raise LinkLost(f"{axis.joint} (node {axis.id}) did not answer a read of "
                           f"{index:#06x}:{sub:02x} ({exc})") from None

    def sdo_write(self, axis: Axis, index: int, sub: int, value: Any) -> None:
        from can import CanError
        from canopen.sdo import SdoAbortedError, SdoCommunicationError

        self.stats["packets"] += 1
        try:
            var = _variable(axis.node, index, sub)
            axis.node.sdo.download(index, sub, var.encode_raw(value))
            if index in axis.commands:
                axis.commands[index] = value
        except SdoAbortedError as exc:
            self.stats["errors"] += 1
            raise DeviceFault(f"{axis.joint} (node {axis.id}) refused to write {value!r} to "
                              f"{index:#06x}:{sub:02x}: {_abort(exc)}", exc.code) from None
        except SdoCommunicationError as exc:
            self.stats["errors"] += 1
            raise NoAnswer(f"{axis.joint} (node {axis.id}) did not answer a write of "
                           f"{index:#06x}:{sub:02x} ({exc})") from None
        except (CanError, OSError) as exc:
            self.stats["errors"] += 1
            raise LinkLost(f"{axis.joint} (node {axis.id}) did not answer a write of "
                           f"{index:#06x}:{sub:02x} ({exc})") from None
        except (KeyError, TypeError, ValueError, OverflowError, struct.error):
            raise InvalidInput(f"{value!r} does not fit {index:#06x}:{sub:02x} of "
                               f"{axis.joint}'s EDS") from None

    # -- lifecycle ---------------------------------------------------------------------------
    def configure(self) -> None:
        if not self.configs:
            raise InvalidInput(f"{self.hw.name}: no joint has a CANopen node ID (param "
                               "node_id, address, or device_name with bus_config)")
        self._open()
        self._add_axes()
        for axis in self.axes.values():
            with contextlib.suppress(DeviceError):
                self._identify(axis)
        present = [a for a in self.axes.values() if a.identity]
        self.roll_call([f"{a.joint} (node {a.id})" for a in self.axes.values() if not a.identity],
                       bool(present), "CANopen node",
                       "check the bus (bitrate, termination, can0 up) and the node IDs "
                       "(deltoctl detect scans 1-127)")
        if not self.probe:
            for axis in present:
                self._start_up(axis)
        self.connected = bool(present)

    def _identify(self, axis: Axis) -> None:
        device_type = self.sdo_read(axis, 0x1000)
        ident = {"node": axis.id, "device_type": f"{device_type:#010x}",
                 "cia402": device_type & 0xFFFF == 402}
        for sub, key in ((1, "vendor_id"), (2, "product_code"), (3, "revision"),
                         (4, "serial")):
            with contextlib.suppress(DeviceError):
                ident[key] = self.sdo_read(axis, 0x1018, sub)
        for index, key in ((0x1008, "device_name"), (0x1009, "hardware_version"),
                           (0x100A, "software_version")):
            if index in axis.node.object_dictionary:
                with contextlib.suppress(DeviceError):
                    ident[key] = str(self.sdo_read(axis, index)).rstrip("\0")
        axis.identity = ident

    def _start_up(self, axis: Axis) -> None:
        """ros2_canopen's start-up of a node: pre-operational, its sdo: list, its PDOs,
        its heartbeat, then operational."""
        config = axis.config
        self._nmt(axis, 0x80)
        for write in config.sdo:
            self.sdo_write(axis, write.index, write.subindex, write.value)
        self._pdos(axis)
        producer = config.heartbeat_producer or DEFAULT_HEARTBEAT_MS
        with contextlib.suppress(DeviceError):
            self.sdo_write(axis, 0x1017, 0, producer)
        axis.heartbeat_ms = producer  # type: ignore[attr-defined]
        self._nmt(axis, 0x01)
        axis.nmt_state = 5
        axis.heartbeat_at = time.monotonic()

    def _pdos(self, axis: Axis) -> None:
        """The bus file's mappings written (disabled, mapped, enabled), else the drive's
        read; the TPDOs subscribed, the controlword's RPDO found."""
        node, config = axis.node, axis.config
        try:
            node.tpdo.read()
            node.rpdo.read()
            for kind, maps in (("tpdo", node.tpdo), ("rpdo", node.rpdo)):
                for pdo_config in getattr(config, kind):
                    if pdo_config.number not in maps.map:
                        continue
                    pdo = maps.map[pdo_config.number]
                    pdo.clear()
                    for index, sub in pdo_config.mapping:
                        pdo.add_variable(index, sub)
                    pdo.enabled = pdo_config.enabled and bool(pdo_config.mapping)
                    if pdo_config.transmission is not None:
                        pdo.trans_type = pdo_config.transmission
                    pdo.save()
        except DeltoctlError:
            raise
        except Exception as exc:
            raise DeviceError(f"{axis.joint} (node {axis.id}): its PDOs could not be set up "
                              f"({exc})") from None
        for pdo in node.tpdo.map.values():
            if pdo.enabled and pdo.map:
                axis.tpdo_mapped.update(v.index for v in pdo.map)
                pdo.add_callback(self._on_tpdo(axis, pdo))
                if pdo.trans_type is not None and 1 <= pdo.trans_type <= 240:
                    self._expected += 1
        for pdo in node.rpdo.map.values():
            if pdo.enabled:
                for var in pdo.map:  # an RPDO carries all its objects: each as it is now
                    axis.commands[var.index] = self.sdo_read(axis, var.index, var.subindex)
                    if var.index == 0x6040 and axis.controlword_pdo is None:
                        axis.controlword_pdo = var

    def _on_tpdo(self, axis: Axis, pdo: Any) -> Any:
        def on_tpdo(message: Any) -> None:
            for var in message:
                axis.values[var.index] = var.raw
            if pdo.trans_type is not None and pdo.trans_type <= 240:
                self._arrived += 1
                if self._arrived >= self._expected:
                    self._sync_seen.set()
        return on_tpdo

    def activate(self) -> None:
        self.connected = bool(self.axes) and any(a.identity for a in self.axes.values())

    # -- the cycle ---------------------------------------------------------------------------
    def start_read(self) -> None:
        if self.network is None or self.lost:
            return
        self._arrived = 0
        self._sync_seen.clear()
        try:
            self._send(session.sync_frame())
        except Exception as exc:  # python-can's errors: the bus went away
            self._lose(f"{exc}")

    def read(self) -> dict[str, float]:
        if self.network is not None and not self.lost:
            if self._expected:
                got = self._sync_seen.wait(TPDO_WAIT)
                self.loop.count(got)
            self._poll()
        self._store()
        return self.values

    def _poll(self) -> None:
        """One SDO read a cycle, at most, of what no TPDO carries (round robin, each value
        every POLL_PERIOD at most): a cycle never waits for more than one round trip."""
        now = time.monotonic()
        if now < self._poll_at:
            return
        if not self._polls:
            self._polls = [(a, i) for a in self.axes.values() if a.identity
                           for i in sorted(self._wanted(a) - a.tpdo_mapped)
                           if i in a.node.object_dictionary]
            self._poll_at = now + POLL_PERIOD
            if not self._polls:
                return
        axis, index = self._polls.pop()
        with contextlib.suppress(DeviceError):
            axis.values[index] = self.sdo_read(axis, index)

    def _wanted(self, axis: Axis) -> set[int]:
        joint = next(j for j in self.hw.joints if j.name == axis.joint)
        return {0x6041, *(STATE_INTERFACES[i.name] for i in joint.state_interfaces
                          if i.name in STATE_INTERFACES)}

    def _store(self) -> None:
        now = time.monotonic()
        values, up = self.values, not self.lost
        for axis in self.axes.values():
            config, raw = axis.config, axis.values
            name = axis.joint
            if 0x6064 in raw:
                values[f"{name}/position"] = config.from_dev(raw[0x6064])
            if 0x606C in raw:
                values[f"{name}/velocity"] = config.vel_from_dev(raw[0x606C])
            if 0x6077 in raw:
                values[f"{name}/effort"] = raw[0x6077] * config.scales["scale_eff_from_dev"]
            values[f"{name}/statusword"] = float(raw.get(0x6041, NAN))
            period = getattr(axis, "heartbeat_ms", DEFAULT_HEARTBEAT_MS) / 1000
            fresh = axis.heartbeat_at is not None and now - axis.heartbeat_at < 3 * period + 0.1
            values[f"{name}/nmt_state"] = float(axis.nmt_state if fresh else 0)
            if axis.identity and not fresh and not self.probe:
                up = False
        if self.connected and not up:
            self.warnings.append(f"{self.hw.name}: {self.lost or 'a node stopped its heartbeat'}")
        self.connected = up and any(a.identity for a in self.axes.values())

    def _lose(self, why: str) -> None:
        if self.lost is None:
            self.lost = f"{self.url} lost ({why})"
            self.stats["errors"] += 1
            self.connected = False

    def round_trip(self) -> None:
        axis = next(a for a in self.axes.values() if a.identity)
        self.sdo_read(axis, 0x1000)

    # -- the 402 state machine ---------------------------------------------------------------
    def statusword(self, axis: Axis) -> int:
        word = self.sdo_read(axis, 0x6041)
        axis.values[0x6041] = word
        return int(word)

    def controlword(self, axis: Axis, value: int) -> None:
        """By RPDO when it is mapped (one frame, no reply), else by SDO."""
        var = axis.controlword_pdo
        if var is not None and axis.nmt_state == 5 and not self.lost:
            try:
                axis.commands[0x6040] = value
                for other in var.pdo_parent.map:
                    other.raw = axis.commands.get(other.index, 0)
                var.pdo_parent.transmit()
                self.stats["packets"] += 1
                return
            except Exception as exc:
                self._lose(str(exc))
                raise LinkLost(f"{self.url} lost ({exc})") from None
        self.sdo_write(axis, 0x6040, 0, value)

    def enable(self, axis: Axis) -> None:
        """Fault reset when in Fault, then shutdown, switch on, enable operation: each
        transition confirmed by the statusword."""
        state = codec.state_of(self.statusword(axis))
        if state in ("FAULT", "FAULT REACTION ACTIVE"):
            self.controlword(axis, 0x00)
            self.controlword(axis, codec.CW_FAULT_RESET)
            state = self._await(axis, ("SWITCH ON DISABLED",), "reset its fault")
        if state == "OPERATION ENABLED":
            axis.enabled = True
            return
        steps = [(codec.CW_SHUTDOWN, "READY TO SWITCH ON"),
                 (codec.CW_SWITCH_ON, "SWITCHED ON"), (codec.CW_ENABLE, "OPERATION ENABLED")]
        if state == "QUICK STOP ACTIVE" or state == "SWITCHED ON":
            steps = steps[2:]
        elif state == "READY TO SWITCH ON":
            steps = steps[1:]
        for word, wanted in steps:
            self.controlword(axis, word)
            self._await(axis, (wanted,), f"reach {wanted.title()}")
        axis.enabled = True

    def _await(self, axis: Axis, states: tuple[str, ...], what: str) -> str:
        deadline = time.monotonic() + STATE_TIMEOUT
        state = "UNKNOWN"
        while time.monotonic() < deadline:
            state = codec.state_of(self.statusword(axis))
            if state in states:
                return state
            time.sleep(0.002)
        code = self._error_code(axis)
        raise DeviceError(f"{axis.joint} (node {axis.id}) did not {what}: it is in {state}"
                          + (f", error code {code:#06x}" if code else ""))

    def _error_code(self, axis: Axis) -> int:
        if 0x603F not in axis.node.object_dictionary:
            return 0
        try:
            return int(self.sdo_read(axis, 0x603F))
        except DeviceError:
            return 0

    def quick_stop(self, axis: Axis) -> None:
        self.controlword(axis, codec.CW_QUICK_STOP)
        axis.enabled = False

    # -- motion ------------------------------------------------------------------------------
    def _axis(self, joint: str) -> Axis:
        axis = self.axes.get(joint)
        if axis is None:
            raise InvalidInput(f"{joint!r} is not a CANopen joint of {self.hw.name}")
        if not axis.identity:
            raise NoAnswer(f"{joint} (node {axis.id}) does not answer on {self.url}")
        return axis

    def check_motion(self, joints: list[str]) -> None:
        if self.lost:
            raise Unreachable(self.lost)
        for joint in joints:
            axis = self._axis(joint)
            if axis.nmt_state not in (5, 127):
                raise Refused(f"{joint} (node {axis.id}) is not operational "
                              f"(NMT state {axis.nmt_state})")

    def move(self, targets: dict[str, float], velocity: float | None = None,
             progress: Progress | None = None) -> MoveResult:
        """Profile position: mode 1, enabled, the profile velocity and target written, a new
        set-point (controlword bit 4) acknowledged (statusword bit 12); then done when each
        drive says target reached (bit 10), read back by SDO so a word sent before the
        set-point cannot end it, and its position read then. The move's time is its ramp's
        own (the trapezoid of the profile velocity and the drive's acceleration) and the
        profile's ``home_timeout`` (else 5 s); when it runs out, or the System halts the move,
        the joints not there are unsettled."""
        from deltoctl.core.envelope import DEFAULT_VELOCITY

        speed = velocity or DEFAULT_VELOCITY
        values = self.read()
        distance = max((abs(t - values.get(f"{j}/position", t)) for j, t in targets.items()),
                       default=0.0)
        pending = set(targets)
        try:
            seconds = 0.0
            for joint, target in targets.items():
                here = values.get(f"{joint}/position", target)
                seconds = max(seconds, self._start_move(self._axis(joint), here, target, speed))
            start = time.monotonic()
            limit = seconds + (self.profile.safety.home_timeout or 5.0)
            while pending and time.monotonic() - start < limit and not self.halted.is_set():
                self.start_read()
                values = self.read()
                self._check_faults(list(targets))
                if self.on_cycle is not None:
                    self.on_cycle(time.time_ns(), values,
                                  {j: (t, speed, NAN) for j, t in targets.items()})
                pending -= {j for j in pending if self._reached(self.axes[j])}
                if progress:
                    worst = max(abs(t - values.get(f"{j}/position", t))
                                for j, t in targets.items())
                    progress(max(0.0, 1.0 - worst / (distance or 1.0)))
                if pending:
                    time.sleep(0.01)
        except BaseException:
            self.stop()
            raise
        self._store()
        errors = {j: abs(t - self.values.get(f"{j}/position", float("inf")))
                  for j, t in targets.items()}
        return MoveResult(not pending, time.monotonic() - start, errors,
                          [j for j in targets if j in pending])

    def _reached(self, axis: Axis) -> bool:
        """Target reached, as the drive says it now: the last word a TPDO brought says so,
        and a word read by SDO (an answer to a request sent now) agrees, its set-point
        acknowledge cleared (the handshake of bit 4 done: the word is about the new
        set-point); then the position it stopped at is read."""
        if not int(axis.values.get(0x6041, 0)) & codec.SW_TARGET_REACHED:
            return False
        word = self.statusword(axis)
        if word & (codec.SW_TARGET_REACHED | codec.SW_SETPOINT_ACK) != codec.SW_TARGET_REACHED:
            return False
        if 0x6064 in axis.node.object_dictionary:
            axis.values[0x6064] = self.sdo_read(axis, 0x6064)
        return True

    def _start_move(self, axis: Axis, here: float, target: float, speed: float) -> float:
        """The set-point given and acknowledged; how long the drive's ramp to it from
        ``here`` takes (s)."""
        from deltoctl_canopen.ramp import Ramp

        self.sdo_write(axis, 0x6060, 0, codec.MODE_PROFILE_POSITION)
        self.enable(axis)
        velocity = max(1, abs(axis.config.vel_to_dev(speed)))
        self.sdo_write(axis, 0x6081, 0, velocity)
        self.sdo_write(axis, 0x607A, 0, axis.config.to_dev(target))
        accel, decel = (int(self.sdo_read(axis, index)) if index in axis.node.object_dictionary
                        else 0 for index in (0x6083, 0x6084))
        self.controlword(axis, codec.CW_ENABLE | codec.CW_CHANGE_IMMEDIATELY)
        self.controlword(axis, codec.CW_ENABLE | codec.CW_NEW_SETPOINT |
                         codec.CW_CHANGE_IMMEDIATELY)
        deadline = time.monotonic() + STATE_TIMEOUT
        while not self.statusword(axis) & codec.SW_SETPOINT_ACK:
            if time.monotonic() > deadline:
                raise DeviceError(f"{axis.joint} (node {axis.id}) did not acknowledge its "
                                  "set-point")
            time.sleep(0.002)
        self.controlword(axis, codec.CW_ENABLE | codec.CW_CHANGE_IMMEDIATELY)
        return Ramp.plan(axis.config.to_dev(here), 0.0, axis.config.to_dev(target), velocity,
                         accel or velocity, decel or accel or velocity, 0.0).seconds

    def _check_faults(self, joints: list[str]) -> None:
        if self.lost:
            raise Unreachable(self.lost)
        for joint in joints:
            axis = self.axes[joint]
            word = axis.values.get(0x6041)
            if word is not None and codec.state_of(int(word)) in ("FAULT",
                                                                   "FAULT REACTION ACTIVE"):
                code = self._error_code(axis)
                raise DeviceError(f"{joint} (node {axis.id}) faulted during the move"
                                  + (f": error code {code:#06x}" if code else ""),
                                  hint="deltoctl resets the fault at the next move")

    def home(self, joints: list[str], force: bool = False,
             progress: HomeProgress | None = None) -> dict[str, str]:
        """Homing mode (6) with the method, offset and speeds the start-up wrote (0x6098,
        0x607C, 0x6099), one axis at a time, as ros2_canopen's init runs it: controlword bit
        4 starts it, statusword bits 12 and 10 say home is attained, bit 13 a homing error;
        then back to profile position. Method 0 ("no homing") leaves the axis as it is."""
        outcome = {}
        for joint in joints:
            axis = self._axis(joint)
            timeout = axis.config.homing_timeout or self.profile.safety.home_timeout or 30.0
            if progress:
                progress(joint, "homing", 0.0)
            try:
                outcome[joint] = self._home_one(axis, timeout)
            except BaseException:
                self.stop()
                raise
            if progress:
                progress(joint, outcome[joint], 1.0)
        return outcome

    def _home_one(self, axis: Axis, timeout: float) -> str:
        method = self.sdo_read(axis, 0x6098)
        if method == 0:
            return "not homed: method 0 (no homing)"
        self.sdo_write(axis, 0x6060, 0, codec.MODE_HOMING)
        self.enable(axis)
        self.controlword(axis, codec.CW_ENABLE)
        self.controlword(axis, codec.CW_ENABLE | codec.CW_NEW_SETPOINT)
        deadline = time.monotonic() + timeout
        try:
            while time.monotonic() < deadline and not self.halted.is_set():
                word = self.statusword(axis)
                if word & codec.SW_HOMING_ERROR:
                    raise DeviceError(f"{axis.joint} (node {axis.id}): homing error "
                                      f"(method {method})")
                if codec.state_of(word) == "FAULT":
                    raise DeviceError(f"{axis.joint} (node {axis.id}) faulted while homing: "
                                      f"error code {self._error_code(axis):#06x}")
                if word & codec.SW_HOMING_ATTAINED and word & codec.SW_TARGET_REACHED:
                    return "homed"
                time.sleep(0.01)
        finally:
            self.controlword(axis, codec.CW_ENABLE)
            self.sdo_write(axis, 0x6060, 0, codec.MODE_PROFILE_POSITION)
        if self.halted.is_set():
            return "halted"
        raise DeviceError(f"{axis.joint} (node {axis.id}) did not attain home within "
                          f"{timeout:g} s (homing method {method})")

    def stop(self) -> None:
        """Quick stop to every axis this driver enabled: one frame each by RPDO."""
        for axis in self.axes.values():
            if axis.enabled and not self.lost:
                try:
                    self.quick_stop(axis)
                except DeltoctlError as exc:
                    self.warnings.append(f"{axis.joint}: no quick stop ({exc.message})")

    def make_safe(self) -> None:
        """Quick stop to every configured axis that answers, whatever this session enabled:
        a drive a killed process left enabled stops too."""
        for axis in self.axes.values():
            if axis.identity and not self.lost:
                try:
                    self.quick_stop(axis)
                except DeltoctlError as exc:
                    self.warnings.append(f"{axis.joint}: no quick stop ({exc.message})")

    def deactivate(self) -> None:
        """Every axis left in Switch On Disabled (a quick stop first where it was enabled)."""
        was = [a for a in self.axes.values() if a.enabled]
        self.stop()
        for axis in was:
            with contextlib.suppress(DeltoctlError):
                self.controlword(axis, codec.CW_DISABLE_VOLTAGE)

    def cleanup(self) -> None:
        if self.network is not None:
            with contextlib.suppress(Exception):
                self.network.disconnect()
            self.network = None
        self.connected = False

    # -- identify, detect --------------------------------------------------------------------
    def identify(self) -> dict[str, Any]:
        nodes = {a.joint: {**a.identity, "eds": str(a.config.dcf),
                           **self._against_eds(a)} for a in self.axes.values() if a.identity}
        return {"bus": self.url, "nodes": nodes}

    @staticmethod
    def _against_eds(axis: Axis) -> dict[str, Any]:
        info = axis.node.object_dictionary.device_information
        expected = {"vendor_id": info.vendor_number, "product_code": info.product_number}
        identity = dict(axis.config.identity)
        expected.update({k: identity[k] for k in ("vendor_id", "product_code") if k in identity})
        if "revision_number" in identity:
            expected["revision"] = identity["revision_number"]
        mismatch = [k for k, v in expected.items()
                    if v is not None and axis.identity.get(k) is not None
                    and axis.identity[k] != v]
        return {"expected": {k: v for k, v in expected.items() if v is not None},
                "identity_match": not mismatch, "mismatch": mismatch}

    def detect(self) -> dict[str, Any]:
        """An SDO scan of node IDs 1-127 (0x1000 read; heartbeats and boot-ups heard count
        too), against the profile: missing, unexpected, wrong identity."""
        found = self._scan()
        expected = {a.id: a for a in self.axes.values()}
        checks = []
        for node_id, axis in sorted(expected.items()):
            ident = self._against_eds(axis) if axis.identity else {}
            ok = node_id in found and ident.get("identity_match", False)
            device = "missing" if node_id not in found else (
                "ok" if ok else "wrong identity: " + ", ".join(
                    f"{k} {axis.identity.get(k):#x}" for k in ident.get("mismatch", [])))
            checks.append({"what": f"node {node_id} ({axis.joint})", "profile": "CiA 402 drive",
                           "device": device, "match": ok, "part": axis.joint,
                           "missing": node_id not in found})
        for node_id in sorted(set(found) - set(expected)):
            checks.append({"what": f"node {node_id}", "profile": "absent",
                           "device": "unexpected node", "match": False})
        bad = [c for c in checks if not c["match"]]
        return {"checks": checks, "found": sorted(found),
                "summary": f"{len(found)} node(s) on {self.url}"
                           + (f", {len(bad)} problem(s)" if bad else ", as the profile says")}

    def _scan(self) -> set[int]:
        """The node IDs that answer an SDO read of 0x1000 (a value or an abort: a node is
        there), or whose heartbeat or boot-up is heard, within SCAN_WINDOW."""
        heard: set[int] = set()
        scan, lock = session.Host(), threading.Lock()
        requests = [scan.upload(node_id, 0x1000) for node_id in range(1, 128)]

        def listen(can_id: int, data: bytes, timestamp: float) -> None:
            with lock:
                try:
                    events = scan.receive(codec.Frame(can_id, bytes(data)))
                except DeviceFault:  # it refused the read: it is there
                    heard.add(can_id & 0x7F)
                    return
                except ProtocolError:  # another master's reply, a node's second one
                    return
            heard.update(e.node for e in events
                         if isinstance(e, (session.SdoDone, session.SdoPending,
                                           session.Heartbeat)))

        for base in (0x580, 0x700):
            for node_id in range(1, 128):
                self.network.subscribe(base + node_id, listen)
        try:
            for request in requests:
                self._send(request)
            time.sleep(SCAN_WINDOW)
        finally:
            for base in (0x580, 0x700):
                for node_id in range(1, 128):
                    self.network.unsubscribe(base + node_id, listen)
        return heard

    # -- registers ---------------------------------------------------------------------------
    def read_registers(self, joint: str, items: list[str]) -> dict[str, Any]:
        from deltoctl_canopen.objects import find, item_name, variables

        axis = self._axis(joint)
        od = axis.node.object_dictionary
        chosen = [find(od, i) for i in items] if items else \
            [v for v in variables(od) if v.readable]
        rows = []
        for var in chosen:
            value = self.sdo_read(axis, var.index, var.subindex)
            rows.append({"address": f"{var.index:#06x}:{var.subindex:02x}",
                         "item": item_name(var).split(" ", 1)[1], "value": _plain(value),
                         "access": var.access_type})
        return {"joint": joint, "id": axis.id, "items": rows}

    def write_register(self, joint: str, item: str, value: int) -> int:
        from deltoctl_canopen.objects import find

        axis = self._axis(joint)
        var = find(axis.node.object_dictionary, item)
        if not var.writable:
            raise InvalidInput(f"{var.name} ({var.index:#06x}:{var.subindex:02x}) is "
                               f"{var.access_type}: not writable")
        self.sdo_write(axis, var.index, var.subindex, value)
        return self.sdo_read(axis, var.index, var.subindex) if var.readable else value

    # -- configuration -----------------------------------------------------------------------
    def config_read(self) -> dict[str, dict[str, dict[str, Any]]]:
        from deltoctl_canopen import objects

        parts = {}
        for axis in self.axes.values():
            if not axis.identity:
                continue
            entries = {}
            for var in objects.variables(axis.node.object_dictionary):
                if not var.readable:
                    continue
                try:
                    value = self.sdo_read(axis, var.index, var.subindex)
                except DeviceError:
                    continue
                entries[objects.item_name(var)] = self._entry(var, value)
            parts[axis.joint] = entries
        return parts

    @staticmethod
    def _entry(var: Any, value: Any) -> dict[str, Any]:
        from deltoctl_canopen import objects

        entry: dict[str, Any] = {"value": _plain(value), "access": "RW" if var.writable else "R",
                                 "address": f"{var.index:#06x}:{var.subindex:02x}"}
        low, high = objects.value_range(var)
        if low is not None:
            entry["min"], entry["max"] = low, high
        if var.unit:
            entry["unit"] = var.unit
        if var.index in objects.COMMANDS or (not var.writable and var.pdo_mappable):
            entry["state"] = True
        return entry

    def config_write(self, changes: dict[str, dict[str, Any]],
                     allow: frozenset[str] = frozenset()) -> dict[str, dict[str, Any]]:
        """Per node, in pre-operational: communication objects, each PDO disabled, mapped
        and enabled again, then the application objects in index order; 0x1010 (save) only
        with --allow save. Returns what each reads back."""
        from deltoctl_canopen import objects

        plan = {}
        for part, items in changes.items():
            axis = self._axis(part)
            od = axis.node.object_dictionary
            writes = []
            for name, value in items.items():
                var = objects.find(od, name)
                if not var.writable or var.index in objects.COMMANDS:
                    raise InvalidInput(f"{part}: {name!r} is not an object a restore writes")
                guard = objects.GUARDED.get(var.index)
                if guard and guard not in allow:
                    raise Refused(f"{part}: {name} is written only with --allow {guard}")
                writes.append((var, value))
            plan[axis] = sorted(writes, key=lambda w: _restore_order(w[0]))
        read_back: dict[str, dict[str, Any]] = {}
        for axis, writes in plan.items():
            self._nmt(axis, 0x80)
            try:
                for var, value in writes:
                    self.sdo_write(axis, var.index, var.subindex, value)
                if "save" in allow and 0x1010 in axis.node.object_dictionary:
                    self.sdo_write(axis, 0x1010, 1, 0x65766173)
            finally:
                self._nmt(axis, 0x01)
            read_back[axis.joint] = {objects.item_name(v): _plain(self.sdo_read(
                axis, v.index, v.subindex)) for v, _ in writes if v.readable}
        return read_back


class _BusLoop(CommLoop):
    """The SYNC loop's statistics, with each node's NMT state and the last EMCYs: what
    /diagnostics carries of the bus once a second."""

    def __init__(self, name: str, driver: CanopenDriver) -> None:
        super().__init__(name, 0.0)
        self.driver = driver

    def report(self) -> dict[str, Any]:
        report: dict[str, Any] = dict(super().report())
        driver = self.driver
        for axis in driver.axes.values():
            state = driver.values.get(f"{axis.joint}/nmt_state", 0.0)
            report[f"{axis.joint}_nmt"] = _NMT_NAMES.get(int(state), "silent")
        with driver._lock:
            for entry in driver.emcy[-4:]:
                report[f"emcy_{entry['joint']}"] = f"{entry['code']} {entry['text']}".rstrip()
        return report


_NMT_NAMES = {0: "silent", 4: "STOPPED", 5: "OPERATIONAL", 127: "PRE-OPERATIONAL"}


def _restore_order(var: Any) -> tuple[int, int, int]:
    """Communication objects first; a PDO's mapping count after its entries; application
    objects last, in index order."""
    index, sub = var.index, var.subindex
    if 0x1600 <= index <= 0x17FF or 0x1A00 <= index <= 0x1BFF:
        return (1, index, 256 if sub == 0 else sub)
    return (0 if index < 0x2000 else 2, index, sub)


def _variable(node: Any, index: int, sub: int) -> Any:
    obj = node.object_dictionary[index]
    return obj[sub] if hasattr(obj, "subindices") else obj


def _decode(node: Any, index: int, sub: int, data: bytes) -> Any:
    try:
        return _variable(node, index, sub).decode_raw(data)
    except KeyError:
        return int.from_bytes(data, "little")


def _plain(value: Any) -> Any:
    if isinstance(value, (bytes, bytearray)):
        return value.hex()
    return value


def _abort(exc: Any) -> str:
    code = getattr(exc, "code", 0)
    return f"{codec.SDO_ABORTS.get(code, 'abort')} ({code:#010x})"


def _wire(frame: codec.Frame) -> bytes:
    """A traced frame's bytes: the identifier (2 bytes, big-endian) and the data."""
    return frame.can_id.to_bytes(2, "big") + frame.data


def _listener_base() -> type:
    import can

    return can.Listener


class _Tracer(_listener_base()):  # type: ignore[misc]
    """Every received frame in the -vv trace."""

    def __init__(self, label: str) -> None:
        self.label = label

    def on_message_received(self, msg: Any) -> None:
        frame = codec.Frame(msg.arbitration_id, bytes(msg.data), msg.is_extended_id,
                            msg.is_remote_frame)
        trace.packet(self.label, "rx", _wire(frame), codec.describe(frame))


class _LostBus(_listener_base()):  # type: ignore[misc]
    """python-can's notifier tells its listeners when the bus fails: the link is lost."""

    def __init__(self, driver: CanopenDriver) -> None:
        self.driver = driver

    def on_message_received(self, msg: Any) -> None:
        pass

    def on_error(self, exc: Exception) -> None:
        self.driver._lose(str(exc))
