"""The Delto developer-mode conversation, sans-I/O: one :class:`Session` per connection, run by
the driver as the host and by the emulator as the device.

Bytes go in (``receive_data``, or ``room`` then ``received`` to receive straight into the
session's buffer), events come out of ``next_event``: a :class:`Request` on the device's side, a
:class:`Reply` on the host's, or :data:`NEED_DATA`. Frames in both directions are
``[LEN_HI][LEN_LO][CMD] payload``, at most ``max_frame`` bytes; only GET_VERSION and GET_DATA
are answered, in the order they were asked (``expected`` counts the replies still due).

The protocol has no start marker and no checksum, so a stream that breaks it cannot be
resynchronised: the first bad frame raises :class:`~deltoctl.errors.ProtocolError`, and so does
every later call, until the connection is closed (a new connection gets a new session).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from enum import Enum
from typing import NoReturn

from deltoctl.errors import ProtocolError
from deltoctl.families.delto.codec import COMMANDS, GET_DATA, GET_VERSION, MAX_FRAME

ANSWERED = frozenset({GET_DATA, GET_VERSION})  # the requests a reply follows


class Role(Enum):
    HOST = "host"  # the driver: sends requests, receives replies
    DEVICE = "device"  # the gripper (its emulator): receives requests, sends replies


class _NeedData:
    def __repr__(self) -> str:
        return "NEED_DATA"


NEED_DATA = _NeedData()
"""``next_event``'s answer until a whole frame has arrived."""


@dataclass(slots=True)
class Request:
    """A request frame, as the device receives it."""

    cmd: int
    frame: bytes

    @property
    def answered(self) -> bool:
        """Whether the device owes a reply to it."""
        return self.cmd in ANSWERED


@dataclass(slots=True)
class Reply:
    """A reply frame, as the host receives it: the one to its oldest open request."""

    cmd: int
    frame: bytes


class Session:
    """One side of one connection: frames what it receives, checks what it sends against the
    conversation so far."""

    def __init__(self, role: Role, max_frame: int = MAX_FRAME) -> None:
        if max_frame < 3:
            raise ValueError(f"a frame is at least 3 bytes, not {max_frame}")
        self.role, self.max_frame = role, max_frame
        self._host = role is Role.HOST
        self._buf = bytearray(4 * max_frame)  # received, not yet taken: [_start:_end]
        self._view = memoryview(self._buf)
        self._start = self._end = 0
        self._open: deque[int] = deque()  # the answered commands whose reply is still due
        self._broken: str | None = None  # why the stream broke the protocol

    @property
    def expected(self) -> int:
        """Replies still due: the host's to receive, the device's to send."""
        return len(self._open)

    @property
    def buffered(self) -> int:
        """Bytes received and not yet part of an event (a frame still arriving)."""
        return self._end - self._start

    # -- sending -------------------------------------------------------------------------------
    def send(self, frame: bytes) -> bytes:
        """The frame to write, once checked against the conversation: any request from the
        host (an answered one opens a reply), only the reply due next from the device."""
        if self._broken is not None:
            raise ProtocolError(self._broken)
        cmd = frame[2]  # the codec's frames: the conversation is what is checked here
        if self._host:
            if cmd in ANSWERED:
                self._open.append(cmd)
        elif not self._open or self._open[0] != cmd:
            due = _name(self._open[0]) if self._open else "none"
            raise ProtocolError(f"a {_name(cmd)} reply is not due (due: {due})")
        else:
            self._open.popleft()
        return frame

    # -- receiving -----------------------------------------------------------------------------
    def room(self, at_least: int = 1) -> memoryview:
        """The free end of the buffer, to receive into (then ``received(count)``)."""
        if self._end == 0:
            if len(self._buf) >= at_least:
                return self._view  # the usual case: everything taken, the whole buffer free
        elif len(self._buf) - self._end < max(at_least, self.max_frame):
            unread = self._end - self._start  # the unread bytes to the front
            self._buf[:unread] = self._buf[self._start:self._end]
            self._start, self._end = 0, unread
        if len(self._buf) - self._end < at_least:  # more than the buffer holds at once
            grown = bytearray(self._end + at_least)
            grown[:self._end] = self._buf[:self._end]
            self._buf, self._view = grown, memoryview(grown)
        return self._view[self._end:]

    def received(self, count: int) -> None:
        """``count`` bytes were written at the start of the last ``room``."""
        self._end += count

    def receive_data(self, data: bytes) -> None:
        """Bytes as they came, copied in."""
        size = len(data)
        self.room(size)[:size] = data
        self._end += size

    def next_event(self) -> Request | Reply | _NeedData:
        """The next whole frame as an event, or NEED_DATA."""
        if self._broken is not None:
            raise ProtocolError(self._broken)
        start, end, buf = self._start, self._end, self._buf
        if end - start < 2:
            return NEED_DATA
        length = buf[start] << 8 | buf[start + 1]
        if length < 3 or length > self.max_frame:
            self._fail(f"frame length {length} is not possible (3..{self.max_frame})")
        if end - start < length:
            return NEED_DATA
        frame = bytes(self._view[start:start + length])
        start += length
        if start == end:
            self._start = self._end = 0
        else:
            self._start = start
        cmd = frame[2]
        if not self._host:
            if cmd in ANSWERED:
                self._open.append(cmd)
            return Request(cmd, frame)
        open_ = self._open
        if not open_ or open_[0] != cmd:
            due = _name(open_[0]) if open_ else "no reply"
            self._fail(f"a {_name(cmd)} reply arrived, {due} was due")
        open_.popleft()
        return Reply(cmd, frame)

    def _fail(self, message: str) -> NoReturn:
        self._start = self._end = 0
        self._broken = message
        raise ProtocolError(message)


def _name(cmd: int) -> str:
    return COMMANDS.get(cmd, f"command {cmd:#04x}")
