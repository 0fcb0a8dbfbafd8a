"""What a servo family gives ``deltoctl setup``: what each joint of a bus block wants (ID,
rate, protocol, model) and, per protocol, the few exchanges that give a servo its address —
torque off (and the EEPROM unlocked where the family locks it), a new ID written at the old
one, a new rate at the new ID, the EEPROM locked again at the new ID and rate, a factory reset
where the family has one — and the PING and model read that verify it. A write of ID or rate
is answered from the ID and at the rate it was addressed at; only then does the servo move.

The exchanges run on a serial port the procedure has opened and set to the rate the servo
answers at; the port's rate is the procedure's to change (``Addresser.baud_after`` says when).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

from deltoctl.errors import DeviceError, NoAnswer
from deltoctl.servo.frames import Reply
from deltoctl.servo.scan import alone
from deltoctl.servo.session import Done, Session

VERIFY_WAIT = 0.05  # s a verification's read waits on, for a second servo's reply
ANSWER_WAIT = 0.2  # s a servo that should be there is given to answer


def free_wait(baud: int) -> float:
    """How long an ID that should be free is listened at: a request and its status (30 bytes
    at the most) on the wire at ``baud``, and 20 ms of the adapter's latency."""
    return 300 / baud + 0.02


@dataclass(frozen=True)
class Wanted:
    """A joint's servo as the profile wants it."""

    joint: str
    block: str
    id: int
    baud: int
    protocol: str  # as deltoctl.servo.scan.Found names it ("Dynamixel 2.0", "Feetech")
    model: str  # the model's name; "" when the profile names none
    # the joint's params as its servo's (a servo gpio's merged in): items among them pinned
    params: dict[str, str] = field(default_factory=dict, compare=False, hash=False)


class Addresser(Protocol):
    """One protocol's addressing exchanges (see the module's docstring)."""

    protocol: str
    reset_options: tuple[str, ...]  # the factory resets it has, by name; () none
    factory: frozenset[tuple[int, int]]  # (ID, baud) a new servo answers at

    def identify(self, port: Any, device_id: int, timeout: float = ANSWER_WAIT) -> str | None:
        """The model name of the servo at ``device_id`` (None: no answer within ``timeout``)."""
        ...

    def prepare(self, port: Any, device_id: int) -> None:
        """Torque off (and the EEPROM unlocked) before the ID and rate are written."""
        ...

    def write_id(self, port: Any, device_id: int, new_id: int) -> None: ...

    def write_baud(self, port: Any, device_id: int, baud: int) -> None: ...

    def finish(self, port: Any, device_id: int) -> None:
        """At the new ID and rate: the EEPROM locked again (nothing where there is no lock)."""
        ...

    def factory_reset(self, port: Any, device_id: int, option: str) -> None: ...


@dataclass(frozen=True)
class Addressing:
    """A family's part of ``setup``: ``wanted(profile, hw, url)`` → a Wanted per joint of the
    block, in its order; ``addresser(protocol)`` → its Addresser (None: not this family's);
    ``no_reset``: why the family has no factory reset ("" when it has one)."""

    wanted: Callable[[Any, Any, str], list[Wanted]]
    addresser: Callable[[str], Addresser | None]
    no_reset: str = ""


def in_joint_order(hw: Any, ids: dict[int, Any], baud: int, protocol: str,
                   model: Callable[[Any], str]) -> list[Wanted]:
    """A Wanted per joint of ``ids`` (its servo's ID → the joint) at the bus's ``baud`` in
    ``protocol``, ``model(joint)`` its model's name (""), in the block's order of joints."""
    order = [j.name for j in hw.joints]
    out = [Wanted(joint.name, hw.name, device_id, baud, protocol, model(joint),
                  dict(joint.params))
           for device_id, joint in ids.items()]
    return sorted(out, key=lambda w: order.index(w.joint) if w.joint in order else len(order))


def ask(port: Any, session: Session, device_id: int, instruction: int, params: bytes,
        what: str, timeout: float = 0.5) -> Reply | None:
    """One request and its status (None when none is expected); NoAnswer naming ``what``
    when none comes within ``timeout`` (a servo answers within a millisecond: the time is
    only spent when it does not)."""
    port.reset_input_buffer()
    port.write(session.send(device_id, instruction, params))
    port.flush()
    if not session.expecting:
        return None
    deadline = time.monotonic() + timeout
    done: Done | None = None
    while time.monotonic() < deadline:
        data = port.read(port.in_waiting or 1)
        if data:
            event = session.receive(data)
            if isinstance(event, Done):
                done = event
                break
    done = done or session.give_up()
    if not done.replies:
        raise NoAnswer(f"{what}: no reply from ID {device_id}",
                       hint="check that the servo is connected, alone, and powered")
    return done.replies[0]


def checked(reply: Reply | None, what: str, describe: Callable[[int], str]) -> Reply | None:
    """A status whose error byte is clear; DeviceError naming the error else."""
    if reply is not None and reply[1]:
        raise DeviceError(f"{what}: the servo at ID {reply[0]} reports {describe(reply[1])}")
    return reply


def one_servo(port: Any, session: Session, device_id: int, instruction: int, params: bytes,
              length: int) -> None:
    """DeviceError unless one servo answers at ``device_id``: the request (a read of its
    present position, which differs between servos) answered by a reply that does not garble
    (see deltoctl.servo.scan.alone)."""
    if not alone(port, session, device_id, instruction, params, VERIFY_WAIT, length):
        raise DeviceError(f"several servos answer at ID {device_id}: their replies to a read "
                          "of the present position garble",
                          hint="scan the bus (deltoctl scan), unplug all but one of them and "
                               "give it its ID alone")
