"""The sync-read scheduler of a servo bus: reads of one item range of every servo, each at its
communication loop's rate. A cycle's ``start`` runs the slow reads that are due in full, then
sends the fast one (the last added) when it is due and leaves its replies on the wire;
``finish`` takes them — so a System's buses wait for their replies at the same time. Servos
that answer no sync read (``singly``: Feetech's SCS series) are read one READ each, after the
sync read's replies."""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

from deltoctl.core.loop import CommLoop
from deltoctl.errors import LinkLost
from deltoctl.servo.frames import Reply
from deltoctl.servo.serial_io import SerialLink
from deltoctl.servo.session import Session


class SyncRead(NamedTuple):
    loop: CommLoop
    address: int
    length: int
    take: Callable[[list[Reply]], None]  # what the family makes of the valid replies


class SyncLoops:
    """The sync reads of one bus over ``link`` and its host ``session``, sent as
    ``instruction`` (a Sync Read, or a Fast Sync Read where the servos have it); ``lost`` is
    told when the port goes away."""

    def __init__(self, link: SerialLink, session: Session, instruction: int,
                 lost: Callable[[Exception], None]) -> None:
        self.link, self.session, self.instruction, self.lost = link, session, instruction, lost
        self.reads: list[SyncRead] = []
        self._params: dict[tuple, bytes] = {}  # built once per range and IDs
        self._inflight: tuple[SyncRead, list[int]] | None = None
        self.singly: set[int] = set()  # IDs that answer no sync read: a READ each

    def add(self, read: SyncRead) -> None:
        self.reads.append(read)

    @property
    def pending(self) -> bool:
        """Whether a read's replies are on their way."""
        return self._inflight is not None

    def _range(self, address: int, length: int) -> bytes:
        size = self.session.frames.address_size
        return address.to_bytes(size, "little") + length.to_bytes(size, "little")

    def send(self, address: int, length: int, ids: list[int]) -> None:
        """The sync read of ``ids`` that answer one (none: nothing is sent)."""
        ids = [i for i in ids if i not in self.singly]
        if not ids:
            return
        key = (address, length, tuple(ids))
        params = self._params.get(key)
        if params is None:
            params = self._params[key] = self._range(address, length) + bytes(ids)
        self.link.write(self.session.send(self.session.frames.broadcast_id, self.instruction,
                                          params))

    def replies(self, ids: list[int], loop: CommLoop | None = None, address: int = 0,
                length: int = 0) -> list[Reply]:
        """The replies to the read sent, then a READ of ``address``, ``length`` from each of
        ``ids`` that answers no sync read: a missing or corrupted one counts as an error (of
        the bus and of ``loop``), never raises."""
        stats = self.link.stats
        synced = [i for i in ids if i not in self.singly]
        replies: list[Reply] = []
        if synced:
            stats["packets"] += 1
            replies = self.link.collect(self.session, self.link.policy.timeout).replies
            stats["errors"] += len(replies) != len(synced)
        for i in ids:
            if i in self.singly:
                stats["packets"] += 1
                done = self.link.exchange(self.session, i, self.session.instructions.read,
                                          self._range(address, length))
                stats["errors"] += not done.replies
                replies += done.replies
        if loop is not None:
            loop.count(len(replies) == len(ids))
        return replies

    def read(self, address: int, length: int, ids: list[int],
             loop: CommLoop | None = None) -> list[Reply]:
        """One sync read, in full: ``(id, error, data)`` per valid reply."""
        self.send(address, length, ids)
        return self.replies(ids, loop, address, length)

    def start(self, ids: list[int]) -> None:
        """This cycle's slow reads, when due; then the fast read sent, when due."""
        if self._inflight is not None or self.link.port is None or not self.reads:
            return
        *slow, fast = self.reads
        try:
            for each in slow:
                if each.loop.due():
                    each.take(self.read(each.address, each.length, ids, each.loop))
            if fast.loop.due():
                self._inflight = (fast, ids)
                self.send(fast.address, fast.length, ids)
        except (OSError, LinkLost) as exc:  # pyserial's errors are OSErrors too
            self._inflight = None
            self.lost(exc)

    def finish(self) -> None:
        """The fast read's replies, taken."""
        if self._inflight is None:
            return
        fast, ids = self._inflight
        self._inflight = None
        try:
            replies = self.replies(ids, fast.loop, fast.address, fast.length)
        except (OSError, LinkLost) as exc:
            self.lost(exc)
            return
        fast.take(replies)
