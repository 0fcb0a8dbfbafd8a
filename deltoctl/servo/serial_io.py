"""The serial port a servo driver talks on: requests written, replies collected through the
host session until every one expected is in or the time is up, tries by the exchange policy,
and a lost port (an adapter unplugged) reopened by the policy's :class:`Reopener`."""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import MutableMapping
from typing import Any

from deltoctl.core.exchange import ExchangePolicy, Reopener
from deltoctl.errors import DeltoctlError, LinkLost, NoAnswer
from deltoctl.servo.frames import Reply
from deltoctl.servo.session import Done, Session


class SerialLink:
    """One bus: ``url`` (serial:///dev/…?baud=N), its ``policy``; ``stats`` are the driver's
    (packets, errors, reconnects)."""

    def __init__(self, url: str, policy: ExchangePolicy,
                 stats: MutableMapping[str, int]) -> None:
        self.url, self.policy, self.stats = url, policy, stats
        for key in ("packets", "errors", "reconnects"):
            stats.setdefault(key, 0)
        self.reopener = Reopener(policy)
        self.port: Any = None
        self._poll: Any = None
        self._stale = False  # bytes of an exchange that went wrong may be waiting

    # -- the port --------------------------------------------------------------------------------
    def open(self) -> None:
        from deltoctl.transport.serial_port import open_serial

        self._attach(open_serial(self.url))

    def _attach(self, port: Any) -> None:
        from deltoctl import trace

        self.port = port
        if hasattr(port, "fd") and not trace.PACKETS:  # traced: through the port's calls
            import select

            self._poll = select.poll()
            self._poll.register(port.fd, select.POLLIN)

    def close(self) -> None:
        port, self.port, self._poll = self.port, None, None
        if port is not None:
            with contextlib.suppress(Exception):
                port.close()

    def lost(self) -> None:
        """The port went away: closed, and reopened one reopen period from now."""
        self.stats["errors"] += 1
        self.reopener.lost()
        self.close()

    def reopen(self) -> bool:
        """A lost port reopened when it is due; whether it is back."""
        if not self.reopener.due():
            return False
        try:
            self.open()
        except DeltoctlError:
            self.reopener.failed()
            return False
        self.reopener.reopened()
        self._stale = True
        self.stats["reconnects"] += 1
        return True

    # -- bytes -----------------------------------------------------------------------------------
    def _port(self) -> Any:
        """The open port; LinkLost while it is away (lost, not yet reopened)."""
        if self.port is None:
            raise LinkLost(f"{self.url} is not open (lost, or closed)",
                           hint="check the adapter and its cable")
        return self.port

    def _gone(self, exc: OSError) -> LinkLost:
        return LinkLost(f"{self.url} went away: {exc}", hint="check the adapter and its cable")

    def write(self, packet: bytes) -> None:
        """Write a request; bytes left over from an exchange that went wrong are dropped
        first. LinkLost when the port is away or fails."""
        port = self._port()
        try:
            if self._stale:
                port.reset_input_buffer()
                self._stale = False
            if self._poll is None:  # no file descriptor (not POSIX), or traced: pyserial's calls
                port.write(packet)
                return
            view = memoryview(packet)
            while view:
                view = view[os.write(port.fd, view):]
        except OSError as exc:  # pyserial's errors are OSErrors too
            raise self._gone(exc) from None

    def flush(self) -> None:
        """Until every byte written has left (a request without replies, before a return)."""
        try:
            self._port().flush()
        except OSError as exc:
            raise self._gone(exc) from None

    def collect(self, session: Session, timeout: float) -> Done:
        """The replies the session expects, taken as their bytes come (the hot path of the
        sync loops: each read is checked while later replies are still on the wire), until
        all are in or ``timeout`` passes. LinkLost when the port is away or fails."""
        port = self._port()
        try:
            return self._collect(port, session, timeout)
        except OSError as exc:
            raise self._gone(exc) from None

    def _collect(self, port: Any, session: Session, timeout: float) -> Done:
        receive = session.receive
        if self._poll is not None:
            fd, poll, read, clock = port.fd, self._poll.poll, os.read, time.perf_counter
            deadline = clock() + timeout
            while True:
                left = deadline - clock()
                if left <= 0 or not poll(left * 1000):
                    break
                event = receive(read(fd, 4096))
                if isinstance(event, Done):
                    self._stale = session.received != session.expected_bytes
                    return event
        else:
            deadline = time.monotonic() + timeout
            while time.monotonic() < deadline:
                data = port.read(port.in_waiting or 1)
                if data:
                    event = receive(data)
                    if isinstance(event, Done):
                        return event
        self._stale = True
        return session.give_up()

    # -- exchanges -------------------------------------------------------------------------------
    def exchange(self, session: Session, device_id: int, instruction: int,
                 params: bytes = b"", timeout: float | None = None) -> Done:
        """One request and its replies (none when the session expects none)."""
        self.write(session.send(device_id, instruction, params))
        if not session.expecting:
            return Done([], [])
        return self.collect(session, self.policy.timeout if timeout is None else timeout)

    def request(self, session: Session, device_id: int, instruction: int, params: bytes,
                what: str, policy: ExchangePolicy | None = None) -> Reply:
        """A unicast request's status, tried by ``policy`` (the link's) while no valid one
        comes; NoAnswer naming ``what`` after the last try."""
        policy = policy or self.policy

        def attempt() -> Reply:
            done = self.exchange(session, device_id, instruction, params, policy.timeout)
            if not done.replies:
                raise NoAnswer(f"{what}: no reply")
            return done.replies[0]

        return policy.run(attempt, what, self.stats)
