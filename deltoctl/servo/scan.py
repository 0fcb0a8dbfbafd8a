"""What a servo family's ``scan`` gives the ``scan`` verb: its probes, one per protocol and
baud rate, each a broadcast (one request every servo answers) or a sweep (a PING to each ID
in turn), and what a probe hears, on a serial port the verb has opened and set to the probe's
rate. Two servos at one ID answer at once: their bytes garble (or one ID answers twice), and
the probe says so rather than naming a servo."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

from deltoctl.servo.frames import Reply
from deltoctl.servo.session import Session


@dataclass(frozen=True)
class Found:
    """A servo that answered (``colliding``: several answered at its ID)."""

    id: int | None  # None: bytes that garbled, from no ID one can tell
    model: str
    firmware: str
    protocol: str
    baud: int
    colliding: bool = False

    def as_dict(self) -> dict[str, Any]:
        return {"id": self.id, "model": self.model, "firmware": self.firmware,
                "protocol": self.protocol, "baud": self.baud, "colliding": self.colliding}


BROADCAST, FACTORY_ID, SWEEP = range(3)


@dataclass(frozen=True)
class Probe:
    """One protocol at one rate: ``run(port, wait, first)`` → the servos that answered,
    ``wait`` the seconds it allows the host (the adapter's latency) beyond the wire's time of
    each exchange; ``first``: a sweep ends at the first servo that answers."""

    protocol: str
    baud: int
    stage: int  # the order probes run in: BROADCAST, FACTORY_ID (one ID), SWEEP (every ID)
    run: Callable[[Any, float, bool], list[Found]] = field(compare=False)


RETURN_DELAY = 254 * 2e-6  # s: the longest a servo waits before its status
GUARD = 0.001  # s between one ping's status and the next ping (a USB frame: writes may bunch)
BROADCAST_REPLIES = 30  # the statuses a broadcast listens for at most


def wire(port: Any, size: int) -> float:
    """Seconds ``size`` bytes take on the wire at the port's rate (10 bits a byte)."""
    return size * 10 / port.baudrate


def listen(port: Any, session: Session, device_id: int, instruction: int, params: bytes,
           wait: float, length: int = 0, more: int = 1) -> tuple[list[Reply], bool]:
    """One request's replies, every one heard (an ID answering twice is two servos at it),
    and whether bytes came that are no valid reply (replies that collided); ``hear`` says how
    long it listens."""
    replies, data = hear(port, session, device_id, instruction, params, wait, length, more)
    heard = sum(session.frames.status_size(len(r[2])) for r in replies)
    return replies, heard < len(data)


def alone(port: Any, session: Session, device_id: int, instruction: int, params: bytes,
          wait: float, length: int = 0) -> bool:
    """Whether at most one servo answers a request: servos of one model and firmware at one
    ID send byte-identical statuses to a PING or a model read, which superimpose cleanly,
    but their present positions differ, so a READ of it garbles (no reply says nothing)."""
    replies, garbled = listen(port, session, device_id, instruction, params, wait, length)
    return not garbled and len(replies) <= 1


def hear(port: Any, session: Session, device_id: int, instruction: int, params: bytes,
         wait: float, length: int = 0, more: int = 1) -> tuple[list[Reply], bytes]:
    """One request's valid replies, and every byte heard. It listens until the wire would have
    carried the request and a status of ``length`` data bytes after the longest return delay,
    and ``wait`` more (the host's own latency); once bytes come, on while they keep coming, up
    to ``more`` statuses later (a broadcast's further replies)."""
    frames = session.frames
    request = session.send(device_id, instruction, params)
    status = wire(port, frames.status_size(length)) + RETURN_DELAY
    port.reset_input_buffer()
    port.write(request)
    port.flush()
    deadline = time.monotonic() + wire(port, len(request)) + status + wait
    end = deadline + more * status
    data = b""
    while (chunk := _read(port, deadline)) is not None:
        if chunk:
            data += chunk
            deadline = min(end, max(deadline, time.monotonic() + status + wait))
    return frames.split(data), data


def pings(port: Any, session: Session, instruction: int, ids: Iterable[int], wait: float,
          first: bool) -> tuple[list[int], bool]:
    """``instruction`` (a PING) to each ID in turn, each sent once the wire has room for the
    one before and its status, not once its status came: a status names its ID, and the
    host's latency is waited once, at the end. The IDs that answered, and whether bytes came
    that are no valid status; ``first``: no more sent once a status came."""
    frames = session.frames
    port.reset_input_buffer()
    data, at = b"", time.perf_counter()
    for device_id in ids:
        _sleep_until(at)  # late only spaces them more
        request = session.send(device_id, instruction, b"")
        port.write(request)
        port.flush()
        at = time.perf_counter() + wire(port, len(request) + frames.status_size(0)) + \
            RETURN_DELAY + GUARD
        if port.in_waiting:
            data += port.read(port.in_waiting)
            if first and frames.split(data):
                break
    deadline = time.monotonic() + at - time.perf_counter() + wait
    while (chunk := _read(port, deadline)) is not None:
        data += chunk
    replies = frames.split(data)
    heard = sum(frames.status_size(len(r[2])) for r in replies)
    return sorted({i for i, _, _ in replies}), heard < len(data)


def _read(port: Any, deadline: float) -> bytes | None:
    """What came by now, or the next byte within the port's read timeout, or nothing;
    None once ``deadline`` (``time.monotonic``) passed. Where a read could block past the
    deadline (or for ever), a short sleep instead."""
    left = deadline - time.monotonic()
    if left <= 0:
        return None
    waiting = port.in_waiting
    if waiting or (port.timeout is not None and left > port.timeout):
        return port.read(waiting or 1)
    time.sleep(min(left, 0.001))
    return b""


def _sleep_until(at: float, spin: float = 0.0003) -> None:
    """A sleep to ``spin`` short of ``at`` (a sleep overshoots by tenths of a millisecond),
    then a spin to it."""
    left = at - time.perf_counter()
    if left > spin:
        time.sleep(left - spin)
    while time.perf_counter() < at:
        pass


def several(ids: list[int]) -> set[int]:
    """The IDs that answered more than once."""
    return {i for i in ids if ids.count(i) > 1}
