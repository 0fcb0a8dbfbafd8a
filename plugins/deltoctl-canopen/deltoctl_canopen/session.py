"""The CANopen conversation, sans-I/O: frames in, events out, for the master (``Host``) and a
node (``Device``).

SDO (CiA 301 §7.2.4): expedited and segmented upload and download, one transfer a node at a
time, each reply matched to its node's open request by index and subindex, segments by their
toggle bit. A node's abort is a ``DeviceFault`` carrying the abort code; a reply nobody asked
for, one about another object or a segment out of turn is a ``ProtocolError``. NMT commands,
boot-up and heartbeat, node guarding, SYNC and PDO frames are named here too, so the driver
and the emulator read the bus alike. A node's LSS slave (CiA 305: switch state, node ID and
bit timing configured and stored, inquiries, identify, fast scan) answers the LSS master, which
is canopen's ``LssMaster``. No sockets, no clocks: the caller sends what an event says to send
and keeps its own time.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from deltoctl.errors import DeviceFault, ProtocolError

from deltoctl_canopen.codec import SDO_ABORTS, Frame

SDO_TX, SDO_RX, HEARTBEAT, SYNC_ID, NMT_ID = 0x580, 0x600, 0x700, 0x080, 0x000
BOOT_UP, STOPPED, OPERATIONAL, PRE_OPERATIONAL = 0x00, 0x04, 0x05, 0x7F
# the state an NMT command leaves a node in (a reset passes through boot-up)
NMT_NEXT = {0x01: OPERATIONAL, 0x02: STOPPED, 0x80: PRE_OPERATIONAL, 0x81: PRE_OPERATIONAL,
            0x82: PRE_OPERATIONAL}
RESETS = (0x81, 0x82)
ABORT_TOGGLE, ABORT_COMMAND, ABORT_NO_OBJECT, ABORT_LENGTH, ABORT_GENERAL = (
    0x05030000, 0x05040001, 0x06020000, 0x06070010, 0x08000000)
MAX_SDO_BYTES = 1 << 16  # the longest value a segmented transfer carries here


# -- events ------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Send:
    """A frame to put on the bus now."""
    frame: Frame


@dataclass(frozen=True)
class SdoDone:
    """A transfer ended: an upload's value, or b"" for a download."""
    node: int
    index: int
    sub: int
    data: bytes = b""


@dataclass(frozen=True)
class SdoPending:
    """A segment went by; more replies are expected for this node's transfer."""
    node: int


@dataclass(frozen=True)
class NmtCommand:
    command: int
    node: int  # 0: every node


@dataclass(frozen=True)
class Heartbeat:
    """A heartbeat or a guarding reply (state 0: a boot-up message)."""
    node: int
    state: int

    @property
    def boot_up(self) -> bool:
        return self.state == BOOT_UP


@dataclass(frozen=True)
class Sync:
    counter: int | None = None


@dataclass(frozen=True)
class Pdo:
    cob_id: int
    data: bytes
    remote: bool = False


@dataclass(frozen=True)
class Other:
    """A frame this conversation does not hold (EMCY, TIME, LSS, another master's SDO …)."""
    frame: Frame


Event = Send | SdoDone | SdoPending | NmtCommand | Heartbeat | Sync | Pdo | Other


# -- frames both roles build -------------------------------------------------------------------

def nmt_frame(command: int, node: int = 0) -> Frame:
    if command not in NMT_NEXT or not 0 <= node <= 127:
        raise ValueError(f"not an NMT command: {command:#04x} to node {node}")
    return Frame(NMT_ID, bytes([command, node]))


def sync_frame(counter: int | None = None) -> Frame:
    return Frame(SYNC_ID, b"" if counter is None else bytes([counter]))


def abort_frame(node: int, index: int, sub: int, code: int, cob: int = SDO_TX) -> Frame:
    return Frame(cob + node, _head(0x80, index, sub) + code.to_bytes(4, "little"))


def abort_text(code: int) -> str:
    return f"{SDO_ABORTS.get(code, 'abort')} ({code:#010x})"


def _head(command: int, index: int, sub: int) -> bytes:
    return bytes([command]) + index.to_bytes(2, "little") + bytes([sub])


def _where(data: bytes) -> tuple[int, int]:
    return int.from_bytes(data[1:3], "little"), data[3]


def _segments(data: bytes) -> list[bytes]:
    return [data[i:i + 7] for i in range(0, len(data), 7)] or [b""]


def _segment(command: int, toggle: int, chunk: bytes, last: bool) -> bytes:
    return bytes([command | toggle << 4 | (7 - len(chunk)) << 1 | last]) + chunk.ljust(7, b"\0")


def _expedited(data: bytes) -> bytes:
    """An expedited frame's value: its size given (bits 2-3 the bytes unused) or all four."""
    size = 4 - (data[0] >> 2 & 3) if data[0] & 1 else 4
    return bytes(data[4:4 + size])


def _nmt_or_frame(frame: Frame) -> Event:
    """A frame that is no SDO of this conversation: what it is."""
    cid, data = frame.can_id, frame.data
    if frame.extended:
        return Other(frame)
    if cid == NMT_ID:
        if len(data) != 2 or data[0] not in NMT_NEXT or data[1] > 127:
            raise ProtocolError(f"not an NMT command: {data.hex() or 'empty'}")
        return NmtCommand(data[0], data[1])
    if cid == SYNC_ID:
        if len(data) > 1:
            raise ProtocolError(f"a SYNC has at most a counter byte, got {data.hex()}")
        return Sync(data[0] if data else None)
    node, function = cid & 0x7F, cid & 0x780
    if function == HEARTBEAT and node and not frame.remote:
        if len(data) != 1:
            raise ProtocolError(f"a heartbeat of node {node} is 1 byte, got {len(data)}")
        return Heartbeat(node, data[0] & 0x7F)
    if 0x180 <= function <= 0x500 and node:
        return Pdo(cid, bytes(data), frame.remote)
    return Other(frame)


# -- the master --------------------------------------------------------------------------------

@dataclass
class _Transfer:
    index: int
    sub: int
    upload: bool
    toggle: int = 0
    started: bool = False  # the initiate reply came
    size: int | None = None
    got: bytearray = field(default_factory=bytearray)
    left: list[bytes] = field(default_factory=list)  # a download's segments still to send


class Host:
    """The master's side: its SDO requests to nodes, their replies matched; every other
    frame named. ``upload``/``download`` give the first frame; ``receive`` the events each
    frame brings (the next segment to send, the transfer done, a heartbeat …)."""

    def __init__(self) -> None:
        self._open: dict[int, _Transfer] = {}

    def busy(self, node: int) -> bool:
        return node in self._open

    def upload(self, node: int, index: int, sub: int = 0) -> Frame:
        self._begin(node, _Transfer(index, sub, upload=True))
        return Frame(SDO_RX + node, _head(0x40, index, sub) + bytes(4))

    def download(self, node: int, index: int, sub: int, data: bytes) -> Frame:
        if len(data) > MAX_SDO_BYTES:
            raise ValueError(f"{len(data)} bytes: an SDO download here is at most "
                             f"{MAX_SDO_BYTES}")
        transfer = _Transfer(index, sub, upload=False)
        if 0 < len(data) <= 4:
            self._begin(node, transfer)
            command = 0x23 | (4 - len(data)) << 2
            return Frame(SDO_RX + node, _head(command, index, sub) + data.ljust(4, b"\0"))
        transfer.left = _segments(data)
        self._begin(node, transfer)
        return Frame(SDO_RX + node, _head(0x21, index, sub) + len(data).to_bytes(4, "little"))

    def cancel(self, node: int, code: int = 0x05040000) -> Frame | None:
        """The node's open transfer given up (timed out, by default): the abort to send."""
        transfer = self._open.pop(node, None)
        if transfer is None:
            return None
        return abort_frame(node, transfer.index, transfer.sub, code, cob=SDO_RX)

    def _begin(self, node: int, transfer: _Transfer) -> None:
        if not 1 <= node <= 127:
            raise ValueError(f"node ID {node} is not 1-127")
        if node in self._open:
            raise ValueError(f"node {node} has an SDO transfer open already")
        self._open[node] = transfer

    def receive(self, frame: Frame) -> list[Event]:
        if frame.extended or frame.remote or frame.can_id & 0x780 != SDO_TX or \
                not frame.can_id & 0x7F:
            return [_nmt_or_frame(frame)]
        node, data = frame.can_id & 0x7F, frame.data
        transfer = self._open.get(node)
        if transfer is None:
            raise ProtocolError(f"node {node} sent an SDO reply nobody asked for: {data.hex()}")
        try:
            return self._reply(node, transfer, data)
        except (ProtocolError, DeviceFault):
            self._open.pop(node, None)
            raise

    def _reply(self, node: int, t: _Transfer, data: bytes) -> list[Event]:
        if len(data) != 8:
            raise ProtocolError(f"node {node}: an SDO reply is 8 bytes, got {len(data)}")
        scs = data[0] >> 5
        if scs == 4:
            code = int.from_bytes(data[4:8], "little")
            if _where(data) != (t.index, t.sub):
                raise ProtocolError(f"node {node} aborted {_where(data)[0]:#06x}:"
                                    f"{data[3]:02x}, not the {t.index:#06x}:{t.sub:02x} asked")
            raise DeviceFault(f"node {node} refused {t.index:#06x}:{t.sub:02x}: "
                              f"{abort_text(code)}", code)
        if not t.started:
            expected = 2 if t.upload else 3
            if scs != expected:
                raise ProtocolError(f"node {node}: SDO reply {data[0]:#04x} to an initiate "
                                    f"{'upload' if t.upload else 'download'}")
            if _where(data) != (t.index, t.sub):
                raise ProtocolError(f"node {node} answered {_where(data)[0]:#06x}:{data[3]:02x}"
                                    f", not the {t.index:#06x}:{t.sub:02x} asked")
            t.started = True
            return self._upload_start(node, t, data) if t.upload else self._next_down(node, t)
        if t.upload and scs == 0:
            return self._upload_segment(node, t, data)
        if not t.upload and scs == 1:
            self._check_toggle(node, t, data)
            return self._next_down(node, t)
        raise ProtocolError(f"node {node}: SDO reply {data[0]:#04x} out of turn")

    def _check_toggle(self, node: int, t: _Transfer, data: bytes) -> None:
        if data[0] >> 4 & 1 != t.toggle:
            raise ProtocolError(f"node {node}: SDO segment toggle bit not alternated")
        t.toggle ^= 1

    def _upload_start(self, node: int, t: _Transfer, data: bytes) -> list[Event]:
        if data[0] & 0x02:
            del self._open[node]
            return [SdoDone(node, t.index, t.sub, _expedited(data))]
        t.size = int.from_bytes(data[4:8], "little") if data[0] & 1 else None
        if t.size is not None and t.size > MAX_SDO_BYTES:
            raise ProtocolError(f"node {node}: {t.size} bytes is more than an upload here "
                                f"takes ({MAX_SDO_BYTES})")
        return [Send(Frame(SDO_RX + node, bytes([0x60]) + bytes(7))), SdoPending(node)]

    def _upload_segment(self, node: int, t: _Transfer, data: bytes) -> list[Event]:
        self._check_toggle(node, t, data)
        t.got += data[1:8 - (data[0] >> 1 & 7)]
        if len(t.got) > (t.size if t.size is not None else MAX_SDO_BYTES):
            raise ProtocolError(f"node {node}: more data than the {t.size} bytes announced")
        if data[0] & 1:
            if t.size is not None and len(t.got) != t.size:
                raise ProtocolError(f"node {node}: {len(t.got)} bytes of the {t.size} "
                                    "announced")
            del self._open[node]
            return [SdoDone(node, t.index, t.sub, bytes(t.got))]
        request = bytes([0x60 | t.toggle << 4]) + bytes(7)
        return [Send(Frame(SDO_RX + node, request)), SdoPending(node)]

    def _next_down(self, node: int, t: _Transfer) -> list[Event]:
        if not t.left:
            del self._open[node]
            return [SdoDone(node, t.index, t.sub)]
        chunk = t.left.pop(0)
        frame = Frame(SDO_RX + node, _segment(0x00, t.toggle, chunk, last=not t.left))
        return [Send(frame), SdoPending(node)]


# -- a node ------------------------------------------------------------------------------------

class Abort(Exception):
    """What a node's object dictionary raises to refuse an access: its SDO abort code."""

    def __init__(self, code: int) -> None:
        super().__init__(abort_text(code))
        self.code = code


Read = Callable[[int, int], bytes]
Write = Callable[[int, int, bytes], None]


class Device:
    """A node's side: its SDO server over ``read``/``write`` of its object dictionary (which
    raise ``Abort``; a KeyError is an object that does not exist), its NMT state, boot-up,
    heartbeat and guarding replies. ``receive`` gives the events a frame brings; an SDO
    request's reply, a boot-up after a reset and a guarding reply come as ``Send``."""

    def __init__(self, node: int, read: Read, write: Write) -> None:
        if not 1 <= node <= 127:
            raise ValueError(f"node ID {node} is not 1-127")
        self.node, self._read, self._write = node, read, write
        self.state = BOOT_UP
        self._guard_toggle = 0
        self._transfer: _Transfer | None = None
        self._out = b""  # a segmented upload's bytes still to send

    def boot(self) -> Frame:
        """Power on: the boot-up message; then PRE-OPERATIONAL."""
        self.state = PRE_OPERATIONAL
        return Frame(HEARTBEAT + self.node, bytes([BOOT_UP]))

    def heartbeat(self) -> Frame:
        return Frame(HEARTBEAT + self.node, bytes([self.state]))

    @property
    def operational(self) -> bool:
        return self.state == OPERATIONAL

    def receive(self, frame: Frame) -> list[Event]:
        cid = frame.can_id
        if not frame.extended and cid == SDO_RX + self.node and not frame.remote:
            if frame.data[:1] and frame.data[0] >> 5 == 4:  # the master gave up: no reply
                self._transfer = None
                return []
            return [Send(self._sdo(frame.data))]
        if not frame.extended and cid == HEARTBEAT + self.node and frame.remote:
            reply = bytes([self.state | self._guard_toggle])
            self._guard_toggle ^= 0x80
            return [Send(Frame(cid, reply))]
        event = _nmt_or_frame(frame)
        if isinstance(event, NmtCommand):
            if event.node not in (0, self.node):
                return []
            self.state = NMT_NEXT[event.command]
            if event.command in RESETS:
                self._transfer = None
                return [event, Send(Frame(HEARTBEAT + self.node, bytes([BOOT_UP])))]
        return [event]

    def _sdo(self, data: bytes) -> Frame:
        if len(data) != 8:
            return abort_frame(self.node, 0, 0, ABORT_COMMAND)
        index, sub = _where(data)
        try:
            return Frame(SDO_TX + self.node, self._serve(data))
        except Abort as exc:
            code = exc.code
        except KeyError:
            code = ABORT_NO_OBJECT
        except Exception:  # the object dictionary failed: a general error, as a node says
            code = ABORT_GENERAL
        t, self._transfer = self._transfer, None
        if t is not None and data[0] >> 5 in (0, 3):  # a segment: the transfer's object
            index, sub = t.index, t.sub
        return abort_frame(self.node, index, sub, code)

    def _serve(self, data: bytes) -> bytes:
        ccs = data[0] >> 5
        if ccs == 2:
            return self._upload(data)
        if ccs == 1:
            return self._download(data)
        t = self._transfer
        if t is None or (ccs == 3) != t.upload or ccs not in (0, 3):
            raise Abort(ABORT_COMMAND)
        if data[0] >> 4 & 1 != t.toggle:
            raise Abort(ABORT_TOGGLE)
        return self._upload_next(t) if t.upload else self._download_segment(t, data)

    def _upload(self, data: bytes) -> bytes:
        index, sub = _where(data)
        self._transfer = None
        value = self._read(index, sub)
        if len(value) <= 4 and value:
            command = 0x43 | (4 - len(value)) << 2
            return _head(command, index, sub) + value.ljust(4, b"\0")
        self._transfer, self._out = _Transfer(index, sub, upload=True), bytes(value)
        return _head(0x41, index, sub) + len(value).to_bytes(4, "little")

    def _upload_next(self, t: _Transfer) -> bytes:
        chunk, self._out = self._out[:7], self._out[7:]
        last = not self._out
        reply = _segment(0x00, t.toggle, chunk, last)
        t.toggle ^= 1
        if last:
            self._transfer = None
        return reply

    def _download(self, data: bytes) -> bytes:
        index, sub = _where(data)
        self._transfer = None
        if data[0] & 0x02:
            self._write(index, sub, _expedited(data))
            return _head(0x60, index, sub) + bytes(4)
        size = int.from_bytes(data[4:8], "little") if data[0] & 1 else None
        if size is not None and size > MAX_SDO_BYTES:
            raise Abort(ABORT_LENGTH)
        self._transfer = _Transfer(index, sub, upload=False, size=size)
        return _head(0x60, index, sub) + bytes(4)

    def _download_segment(self, t: _Transfer, data: bytes) -> bytes:
        t.got += data[1:8 - (data[0] >> 1 & 7)]
        if len(t.got) > (t.size if t.size is not None else MAX_SDO_BYTES):
            raise Abort(ABORT_LENGTH)
        reply = bytes([0x20 | t.toggle << 4]) + bytes(7)
        t.toggle ^= 1
        if data[0] & 1:
            self._transfer = None
            if t.size is not None and len(t.got) != t.size:
                raise Abort(ABORT_LENGTH)
            self._write(t.index, t.sub, bytes(t.got))
        return reply


# -- LSS, a node's side (CiA 305) --------------------------------------------------------------

LSS_FROM_MASTER, LSS_FROM_SLAVE = 0x7E5, 0x7E4
LSS_WAITING, LSS_CONFIGURATION = 0x00, 0x01
UNCONFIGURED = 0xFF  # the node ID of a node LSS has not configured
# the bit timing table (CiA 305, table 0): index → bit/s, as canopen's LssMaster lists it
LSS_BITRATES = {0: 1_000_000, 1: 800_000, 2: 500_000, 3: 250_000, 4: 125_000, 5: 100_000,
                6: 50_000, 7: 20_000, 8: 10_000}
FAST_SCAN_RESET = 0x80  # a fast scan's bit check that opens it: every candidate answers
(_SWITCH_GLOBAL, _CONFIGURE_NODE_ID, _CONFIGURE_BIT_TIMING, _ACTIVATE_BIT_TIMING,
 _STORE) = 0x04, 0x11, 0x13, 0x15, 0x17
_SELECTIVE, _SELECTIVE_DONE = range(0x40, 0x44), 0x44
_IDENTIFY_REMOTE, _IDENTIFY_NON_CONFIGURED = range(0x46, 0x4C), 0x4C
_IDENTIFY_SLAVE, _NON_CONFIGURED_SLAVE, _FAST_SCAN = 0x4F, 0x50, 0x51
_INQUIRE_IDENTITY, _INQUIRE_NODE_ID = range(0x5A, 0x5E), 0x5E


@dataclass(frozen=True)
class LssStart:
    """The node takes this node ID now: it boots (boot-up message) and runs NMT at it."""
    node: int


@dataclass(frozen=True)
class LssBitRate:
    """The node switches to this bit rate after ``delay_ms`` (activate bit timing)."""
    bitrate: int
    delay_ms: int


class LssSlave:
    """A node's LSS slave: its LSS address (0x1018:1-4, ``identity``), its node ID and bit
    timing (active, pending, stored), its LSS state and its fast scan position. ``receive``
    gives the events an LSS request brings: a reply to send (``Send``), the node starting at
    a node ID it was given (``LssStart``), a bit rate to take (``LssBitRate``). Requests
    other than the switch and identify services are answered in the configuration state
    only; a fast scan, by a node in the waiting state that has no node ID."""

    def __init__(self, identity: tuple[int, int, int, int], node: int = UNCONFIGURED,
                 bit_timing: int = 0) -> None:
        if not (1 <= node <= 127 or node == UNCONFIGURED) or bit_timing not in LSS_BITRATES:
            raise ValueError(f"an LSS node starts at node ID 1-127 or {UNCONFIGURED:#x} and a "
                             f"bit timing index 0-8, got {node}, {bit_timing}")
        self.identity = tuple(identity)
        self.node = self.pending = self.stored = node
        self.bit_timing = self.pending_bit_timing = self.stored_bit_timing = bit_timing
        self.state = LSS_WAITING
        self._selective = 0  # how many parts of the address a selective switch matched
        self._remote = 0  # the same for an identify remote slave
        self._scan_at = 0  # the address part a fast scan checks next

    @property
    def configured(self) -> bool:
        return self.pending != UNCONFIGURED

    def reset_communication(self) -> int:
        """An NMT reset communication: the pending node ID becomes the active one."""
        self.node = self.pending
        return self.node

    def receive(self, frame: Frame) -> list[Event | LssStart | LssBitRate]:
        data = frame.data
        if frame.can_id != LSS_FROM_MASTER or frame.extended or frame.remote or len(data) != 8:
            return []
        cs, value = data[0], int.from_bytes(data[1:5], "little")
        if cs == _SWITCH_GLOBAL:
            return self._switch(data[1])
        if cs in _SELECTIVE:
            return self._match_selective(cs - _SELECTIVE.start, value)
        if cs in _IDENTIFY_REMOTE:
            return self._match_remote(cs - _IDENTIFY_REMOTE.start, value)
        if cs == _IDENTIFY_NON_CONFIGURED:
            return [] if self.configured else [self._reply(_NON_CONFIGURED_SLAVE)]
        if cs == _FAST_SCAN:
            return self._fast_scan(value, data[5], data[6], data[7])
        if self.state != LSS_CONFIGURATION:
            return []
        return self._configure(cs, data)

    def _configure(self, cs: int, data: bytes) -> list[Event | LssStart | LssBitRate]:
        if cs == _CONFIGURE_NODE_ID:
            ok = 1 <= data[1] <= 127 or data[1] == UNCONFIGURED
            if ok:
                self.pending = data[1]
            return [self._reply(cs, bytes([0 if ok else 1]))]
        if cs == _CONFIGURE_BIT_TIMING:
            ok = data[1] == 0 and data[2] in LSS_BITRATES
            if ok:
                self.pending_bit_timing = data[2]
            return [self._reply(cs, bytes([0 if ok else 1]))]
        if cs == _ACTIVATE_BIT_TIMING:
            self.bit_timing = self.pending_bit_timing
            return [LssBitRate(LSS_BITRATES[self.bit_timing],
                               int.from_bytes(data[1:3], "little"))]
        if cs == _STORE:
            self.stored, self.stored_bit_timing = self.pending, self.pending_bit_timing
            return [self._reply(cs, b"\0")]
        if cs in _INQUIRE_IDENTITY:
            part = self.identity[cs - _INQUIRE_IDENTITY.start]
            return [self._reply(cs, part.to_bytes(4, "little"))]
        if cs == _INQUIRE_NODE_ID:
            return [self._reply(cs, bytes([self.node]))]
        return []

    def _switch(self, mode: int) -> list[Event | LssStart | LssBitRate]:
        self._selective = 0
        if mode == LSS_CONFIGURATION:
            self.state = LSS_CONFIGURATION
        elif mode == LSS_WAITING and self.state == LSS_CONFIGURATION:
            self.state = LSS_WAITING
            if self.node == UNCONFIGURED and self.pending != UNCONFIGURED:
                return [LssStart(self.reset_communication())]
        return []

    def _match_selective(self, part: int, value: int) -> list[Event | LssStart | LssBitRate]:
        self._selective = self._selective + 1 if part == self._selective and \
            value == self.identity[part] else 0
        if self._selective < 4:
            return []
        self._selective, self.state = 0, LSS_CONFIGURATION
        return [self._reply(_SELECTIVE_DONE)]

    def _match_remote(self, step: int, value: int) -> list[Event | LssStart | LssBitRate]:
        """Vendor and product equal, revision and serial within [low, high] (six steps)."""
        vendor, product, revision, serial = self.identity
        ok = (vendor == value, product == value, revision >= value, revision <= value,
              serial >= value, serial <= value)[step]
        self._remote = self._remote + 1 if step == self._remote and ok else 0
        if self._remote < 6:
            return []
        self._remote = 0
        return [self._reply(_IDENTIFY_SLAVE)]

    def _fast_scan(self, value: int, bit: int, part: int,
                   following: int) -> list[Event | LssStart | LssBitRate]:
        if self.state != LSS_WAITING or self.configured:
            return []
        if bit == FAST_SCAN_RESET:
            self._scan_at = 0
            return [self._reply(_IDENTIFY_SLAVE)]
        if bit > 31 or part > 3 or following > 3 or part != self._scan_at:
            return []
        mask = (0xFFFFFFFF << bit) & 0xFFFFFFFF
        if (self.identity[part] ^ value) & mask:
            return []
        self._scan_at = following
        if bit == 0 and following < part:  # the whole address matched: this node is chosen
            self.state = LSS_CONFIGURATION
        return [self._reply(_IDENTIFY_SLAVE)]

    @staticmethod
    def _reply(cs: int, body: bytes = b"") -> Send:
        return Send(Frame(LSS_FROM_SLAVE, (bytes([cs]) + body).ljust(8, b"\0")))
