"""What a servo family's ``scan`` gives the ``scan`` verb: its probes, one per protocol and
baud rate, each a broadcast (one request every servo answers) or a sweep (a PING to each ID
in turn), and what a probe hears, on a serial port the verb has opened and set to the probe's
rate. Two servos at one ID answer at once: their bytes garble (or one ID answers twice), and
the probe says so rather than naming a servo."""

from __future__ import annotations

import time
from collections.abc import Callable
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
    ``wait`` the seconds it waits for a reply (a broadcast listens for 30 servos' replies
    besides); ``first``: a sweep ends at the first servo that answers."""

    protocol: str
    baud: int
    stage: int  # the order probes run in: BROADCAST, FACTORY_ID (one ID), SWEEP (every ID)
    run: Callable[[Any, float, bool], list[Found]] = field(compare=False)


def listen(port: Any, session: Session, device_id: int, instruction: int, params: bytes,
           wait: float) -> tuple[list[Reply], bool]:
    """One request's replies, every one heard within ``wait`` (an ID answering twice is two
    servos at it), and whether bytes came that are no valid reply (replies that collided)."""
    replies, data = hear(port, session, device_id, instruction, params, wait)
    heard = sum(session.frames.status_size(len(r[2])) for r in replies)
    return replies, heard < len(data)


def hear(port: Any, session: Session, device_id: int, instruction: int, params: bytes,
         wait: float) -> tuple[list[Reply], bytes]:
    """One request's valid replies within ``wait``, and every byte heard."""
    port.reset_input_buffer()
    port.write(session.send(device_id, instruction, params))
    port.flush()
    data = b""
    deadline = time.monotonic() + wait
    while time.monotonic() < deadline:
        data += port.read(port.in_waiting or 1)
    return session.frames.split(data), data


def broadcast_wait(baud: int, wait: float, reply_bytes: int = 14) -> float:
    """How long a broadcast listens: ``wait`` and the wire time of 30 replies at ``baud``."""
    return wait + 30 * reply_bytes * 10 / baud


def several(ids: list[int]) -> set[int]:
    """The IDs that answered more than once."""
    return {i for i in ids if ids.count(i) > 1}
