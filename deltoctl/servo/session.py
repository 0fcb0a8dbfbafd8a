"""The conversation on a servo bus, sans-I/O, once for both ends (as h11's ``Connection``):
which request gets how many status packets, from whom, and how they are told apart.

A :class:`Session` has a role. The **host** (a driver) says what it sends — ``send`` returns
the bytes and remembers what answers to expect: a unicast request one status from its ID (as
its Status Return Level allows), a broadcast none but a PING's (every servo's), a Sync Read one
per listed ID in order, a Fast Sync Read one combined status, a Bulk Read one per entry — then
``receive``\\ s the bytes as they come and gets :data:`NEED_DATA` (``waiting`` names the IDs still
expected) until :class:`Done` holds the replies matched by ID (and length); ``give_up`` when the
time is up. The **device** (an emulated bus) ``receive``\\ s request bytes and gets
:class:`Request`\\ s; ``answers`` says whether a servo answers one, by the same rules. The frame
variant (``frames``) and the instruction set (:class:`Instructions`) are parameters: a Dynamixel
Protocol 1.0 or Feetech session is this class with other tables.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import NamedTuple

from deltoctl.errors import ProtocolError
from deltoctl.servo.frames import Frames, Reply, SyncCheck

HOST, DEVICE = "host", "device"


@dataclass(frozen=True)
class Instructions:
    """The instruction codes a session's rules name. ``answered_at[level]`` is what a servo
    answers at that Status Return Level (None: everything), PING always; a bulk read's params
    are ``bulk_prefix`` bytes, then per servo ``bulk_entry`` bytes holding its ID at
    ``bulk_id_at`` and its length (of ``address_size`` bytes) at ``bulk_length_at``."""

    ping: int
    read: int
    answered_at: tuple[frozenset[int] | None, ...]
    ping_length: int | None = None  # the data of a PING's status (None: any)
    sync_read: int | None = None
    fast_sync_read: int | None = None
    bulk_read: int | None = None
    bulk_prefix: int = 0
    bulk_entry: int = 5
    bulk_id_at: int = 0
    bulk_length_at: int = 3

    @property
    def top_level(self) -> int:
        return len(self.answered_at) - 1


class Request(NamedTuple):
    """A request as a device reads it; ``size`` is its bytes on the wire."""

    id: int
    instruction: int
    params: bytes
    size: int


class NeedData:
    """More replies are expected: ``Session.waiting`` names them."""

    def __repr__(self) -> str:
        return "NEED_DATA"


NEED_DATA = NeedData()


class Done:
    """The replies of an exchange, ``(id, error, data)`` each, in the order they came, every
    one from an ID expected (once) with the data length asked for (a status with an error may
    have none); ``expected`` the IDs asked (empty: any that answer, a broadcast PING)."""

    __slots__ = ("expected", "replies")

    def __init__(self, replies: list[Reply], expected: list[int]) -> None:
        self.replies, self.expected = replies, expected

    @property
    def complete(self) -> bool:
        return len(self.replies) >= len(self.expected)

    @property
    def missing(self) -> list[int]:
        got = {r[0] for r in self.replies}
        return [i for i in self.expected if i not in got]

    def __repr__(self) -> str:
        return f"Done({self.replies!r}, expected={self.expected!r})"


NONE, SINGLE, ANY, SYNC, FAST, BULK = range(6)  # what a request is answered with


class Expect(NamedTuple):
    """What answers a request: its kind, the IDs in the order they answer, the data length
    of each (None: any)."""

    kind: int
    ids: list[int]
    lengths: list[int | None]


_NOTHING = Expect(NONE, [], [])


class Session:
    """One end of the conversation on one bus (see the module's docstring)."""

    def __init__(self, frames: Frames, instructions: Instructions, role: str = HOST,
                 level: int | None = None) -> None:
        if role not in (HOST, DEVICE):
            raise ValueError(f"a session's role is {HOST!r} or {DEVICE!r}, not {role!r}")
        self.frames, self.instructions, self.role = frames, instructions, role
        self.level = instructions.top_level if level is None else level  # the host's servos'
        self.garbled = 0  # frames dropped for a bad checksum or CRC
        self._reader = frames.reader()
        self._cache: dict[tuple, tuple[bytes, Expect, int]] = {}  # a read loop's requests
        self._expect = _NOTHING
        self.expected_bytes = 0  # of the replies to the request sent (0: unknown)
        self._data = b""
        self._sync: SyncCheck | None = None  # a Sync Read's replies, checked in place

    # -- the rules, for both roles -------------------------------------------------------------
    def expected(self, device_id: int, instruction: int, params: bytes,
                 level: int | None = None) -> Expect:
        """Who answers a request, and with how many bytes of data each."""
        ins = self.instructions
        size = self.frames.address_size
        if instruction == ins.ping:
            return Expect(ANY, [], [ins.ping_length]) if device_id == self.frames.broadcast_id \
                else Expect(SINGLE, [device_id], [ins.ping_length])
        if instruction in (ins.sync_read, ins.fast_sync_read) and instruction is not None:
            if len(params) < 2 * size:
                return _NOTHING
            length = int.from_bytes(params[size:2 * size], "little")
            ids = list(params[2 * size:])
            return Expect(SYNC if instruction == ins.sync_read else FAST, ids, [length] * len(ids))
        if instruction == ins.bulk_read and instruction is not None:
            ids, lengths = [], []
            at, step = ins.bulk_prefix, ins.bulk_entry
            while at + step <= len(params):
                ids.append(params[at + ins.bulk_id_at])
                lengths.append(int.from_bytes(
                    params[at + ins.bulk_length_at:at + ins.bulk_length_at + size], "little"))
                at += step
            return Expect(BULK, ids, lengths)
        if device_id == self.frames.broadcast_id:
            return _NOTHING
        level = self.level if level is None else level
        answered = ins.answered_at[max(0, min(level, ins.top_level))]
        if answered is not None and instruction not in answered:
            return _NOTHING
        length = int.from_bytes(params[size:2 * size], "little") \
            if instruction == ins.read and len(params) == 2 * size else None
        return Expect(SINGLE, [device_id], [length])

    # -- host ------------------------------------------------------------------------------------
    def send(self, device_id: int, instruction: int, params: bytes = b"") -> bytes:
        """The request's bytes; the session now expects its replies (those of any request
        before are forgotten). Requests sent again (a sync loop's) are built once."""
        key = (device_id, instruction, params)
        cached = self._cache.get(key)
        if cached is None:
            expect = self.expected(device_id, instruction, params)
            cached = (self.frames.request(device_id, instruction, params), expect,
                      self._size(expect))
            if expect.kind in (SYNC, FAST, BULK) and len(self._cache) < 256:
                self._cache[key] = cached
        packet, self._expect, self.expected_bytes = cached
        self._data = b""
        kind, ids, lengths = self._expect
        self._sync = self.frames.sync_replies(lengths[0] or 0, ids) if kind == SYNC else None
        return packet

    def _size(self, expect: Expect) -> int:
        """The bytes of every reply expected, when each is as short as it can be (0 when
        unknown: a broadcast PING's)."""
        kind, ids, lengths = expect
        if kind == FAST:
            return self.frames.combined_size(len(ids), lengths[0] or 0)
        if kind == ANY or None in lengths:
            return 0
        return sum(self.frames.status_size(n or 0) for n in lengths)

    @property
    def expecting(self) -> bool:
        """Whether the request sent has replies to wait for."""
        return self._expect.kind != NONE

    @property
    def received(self) -> int:
        """The reply bytes received since the request."""
        return len(self._data)

    @property
    def waiting(self) -> list[int]:
        """The IDs still expected."""
        found = {r[0] for r in self._matched()}
        return [i for i in self._expect.ids if i not in found]

    def receive(self, data: bytes) -> NeedData | Done:
        """Reply bytes as they came: :data:`NEED_DATA` until every reply expected is in."""
        if self.role != HOST:
            raise ProtocolError("a device session receives requests: use receive_requests")
        self._data += data
        sync = self._sync
        if sync is not None:  # the sync loops' common case, checked in place as it arrives
            sync.feed(self._data)
            if sync.in_shape:
                if len(sync.found) == len(sync.ids):
                    return Done([r for r in sync.found if r], self._expect.ids)
                return NEED_DATA
        kind = self._expect.kind
        if kind == NONE:
            return Done([], [])
        if kind == ANY or (kind != SINGLE and len(self._data) < self.expected_bytes):
            return NEED_DATA  # (a single status may be short: an error with no data)
        replies = self._matched()
        return Done(replies, self._expect.ids) if len(replies) == len(self._expect.ids) \
            else NEED_DATA

    def give_up(self) -> Done:
        """The time is up: the replies that came."""
        if self._sync is not None and self._sync.in_shape:
            self._sync.feed(self._data)
            if self._sync.in_shape and len(self._sync.found) == len(self._sync.ids):
                return Done([r for r in self._sync.found if r], self._expect.ids)
        return Done(self._matched(), self._expect.ids)

    def _matched(self) -> list[Reply]:
        kind, ids, lengths = self._expect
        if kind == NONE or not self._data:
            return []
        if kind == FAST:
            return self.frames.split_combined(self._data, lengths[0] or 0, ids)
        found = self.frames.split(self._data)
        if kind == ANY:
            length = lengths[0]
            return [r for r in found if length is None or len(r[2]) == length]
        want = dict(zip(ids, lengths))
        out = []
        for reply in found:
            device_id, error, data = reply
            if device_id in want and (want[device_id] in (None, len(data)) or error):
                del want[device_id]
                out.append(reply)
        return out

    # -- device ----------------------------------------------------------------------------------
    def receive_requests(self, data: bytes) -> list[Request]:
        """The requests in the bytes heard; a frame that does not check is dropped (counted
        in ``garbled``), as a servo ignores it, and the search goes on after it."""
        if self.role != DEVICE:
            raise ProtocolError("a host session receives replies: use receive")
        out: list[Request] = []
        size = self.frames.request_size
        while True:
            try:
                found = self._reader.feed(data)
            except ProtocolError:
                self.garbled += 1
                data = b""
                continue
            if not found:
                return out
            data = b""
            out += [Request(i, inst, params, size(len(params))) for i, inst, params in found]

    def answers(self, request: Request, device_id: int, level: int | None = None) -> bool:
        """Whether servo ``device_id`` at Status Return Level ``level`` answers ``request``
        with a status of its own (a Fast Sync Read is answered by one status for all)."""
        expect = self.expected(request.id, request.instruction, request.params, level)
        return expect.kind == ANY or (expect.kind != FAST and device_id in expect.ids)

    def addressed(self, request: Request, present: Iterable[int]) -> list[int]:
        """The servos among ``present`` a request asks for data, in the order they answer
        (a Sync, Fast Sync or Bulk Read's list; every one for a broadcast PING)."""
        expect = self.expected(request.id, request.instruction, request.params)
        if expect.kind == ANY:
            return sorted(present)
        here = set(present)
        return [i for i in expect.ids if i in here]

    def reply(self, device_id: int, error: int = 0, data: bytes = b"") -> bytes:
        """A servo's status."""
        return self.frames.status(device_id, error, data)
