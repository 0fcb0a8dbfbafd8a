"""The exchange policy every family configures: how often a request is tried, how long a try
waits for its reply, how long between tries, and when a lost link is reopened. A driver keeps
one :class:`ExchangePolicy` and one :class:`Reopener` per link instead of loops of its own, so
every family retries, gives up and reconnects alike and says so in the same words."""

from __future__ import annotations

import time
from collections.abc import Callable, MutableMapping
from dataclasses import dataclass
from typing import TypeVar

from deltoctl.errors import NoAnswer, ProtocolError

T = TypeVar("T")


@dataclass(frozen=True)
class ExchangePolicy:
    """``tries`` of ``timeout`` seconds each, ``pause`` seconds apart; a lost link reopened
    every ``reopen_period`` seconds, ``reopen_tries`` times a round (0: until it is back)."""

    tries: int = 3
    timeout: float = 0.1
    pause: float = 0.0
    reopen_period: float = 1.0
    reopen_tries: int = 0

    def __post_init__(self) -> None:
        if self.tries < 1 or self.timeout <= 0 or self.pause < 0 or self.reopen_period <= 0:
            raise ValueError(f"an exchange policy needs tries ≥ 1 and positive times: {self}")

    def run(self, attempt: Callable[[], T], what: str,
            stats: MutableMapping[str, int] | None = None) -> T:
        """``attempt()`` until it returns. No answer or bytes that break the protocol are tried
        again (each try counted in ``stats["packets"]``, each failure in ``stats["errors"]``);
        a device's own error reply (:class:`~deltoctl.errors.DeviceFault`) and a lost link are
        answers, raised at once. After the last try: :class:`NoAnswer` naming ``what``."""
        last: Exception | None = None
        for number in range(self.tries):
            if number and self.pause:
                time.sleep(self.pause)
            if stats is not None:
                stats["packets"] = stats.get("packets", 0) + 1
            try:
                return attempt()
            except (NoAnswer, ProtocolError) as exc:
                last = exc
                if stats is not None:
                    stats["errors"] = stats.get("errors", 0) + 1
        reason = f": {last.message}" if isinstance(last, ProtocolError) else ""
        raise NoAnswer(f"no valid reply to {what} ({self.tries} tries){reason}")


class Reopener:
    """When a lost link is next reopened, and how often it was: a driver calls :meth:`lost`
    when its link goes away, asks :meth:`due` before using it, and reports each attempt's
    outcome (:meth:`reopened`, :meth:`failed`). ``clock`` is ``time.monotonic`` but in tests."""

    def __init__(self, policy: ExchangePolicy,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.policy, self.clock = policy, clock
        self.is_lost = False
        self.reconnects = 0  # links reopened
        self.attempts = 0  # attempts in the current round
        self._next = 0.0

    def lost(self) -> None:
        """The link went away: the first attempt is one period from now."""
        if not self.is_lost:
            self.is_lost, self.attempts = True, 0
            self._next = self.clock() + self.policy.reopen_period

    def due(self) -> bool:
        """Whether a lost link should be tried now (never while the link is up)."""
        return self.is_lost and self.clock() >= self._next

    def failed(self) -> bool:
        """An attempt failed: the next is one period later. Returns whether the round is
        over (``reopen_tries`` attempts made; a new round starts with the next attempt)."""
        self.attempts += 1
        self._next = self.clock() + self.policy.reopen_period
        over = bool(self.policy.reopen_tries) and self.attempts >= self.policy.reopen_tries
        if over:
            self.attempts = 0
        return over

    def reopened(self) -> None:
        """An attempt succeeded: the link is up again."""
        self.is_lost, self.attempts = False, 0
        self.reconnects += 1
