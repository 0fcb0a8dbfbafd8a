"""Control lines: what turns a simulated device from outside while it is served. An emulator
answers lines that start with a word of its own (``face -x`` turns one);
``deltoctl sim serve`` reads them on its standard input, one a line, and the pytest fixture
passes them as text. A line runs no code: its first word picks an answerer its family
declared, which checks the rest."""

from __future__ import annotations

import errno
import os
import select
import threading
from collections.abc import Callable

from deltoctl.core.emulator_contract import ControlHandler
from deltoctl.errors import DeltoctlError, InvalidInput

MAX_LINE = 200  # bytes: a longer line is left out whole


class Controls:
    """The control lines of the served devices, by first word."""

    def __init__(self) -> None:
        self._answerers: dict[str, list[tuple[str, ControlHandler]]] = {}

    def add(self, word: str, usage: str, handler: ControlHandler) -> None:
        self._answerers.setdefault(word, []).append((usage, handler))

    def words(self) -> list[str]:
        return sorted(self._answerers)

    def usage(self) -> str:
        lines = sorted({usage for found in self._answerers.values() for usage, _ in found})
        return "\n".join([*lines, "help: these lines"])

    def run(self, line: str) -> str:
        """Run one control line; its reply, or one InvalidInput naming what is wrong."""
        words = line.split()
        if not words:
            raise InvalidInput("an empty control line")
        if words[0] == "help":
            return self.usage()
        found = self._answerers.get(words[0])
        if not found:
            raise InvalidInput(f"unknown control {words[0]!r} (controls: "
                               f"{', '.join([*self.words(), 'help'])})")
        # each family answers for its own parts: a reply of nothing is another's line
        return "\n".join(r for _, handler in found if (r := handler(words[1:])))

    def follow(self, fd: int, stop: threading.Event, reply: Callable[[str, str], None],
               complain: Callable[[str], None]) -> None:
        """Run each line read from ``fd`` until ``stop`` is set, telling ``reply(line,
        answer)`` or ``complain(message)``. At the end of the input, serving goes on; a
        background job that may not read its terminal waits until it may."""
        pending, skipping = b"", False
        while not stop.is_set():
            if not select.select([fd], [], [], 0.5)[0]:
                continue
            try:
                chunk = os.read(fd, 4096)
            except OSError as exc:
                if exc.errno not in (errno.EIO, errno.EAGAIN, errno.EINTR):
                    raise
                stop.wait(0.5)  # a background job's terminal: read again once in front
                continue
            if not chunk:
                stop.wait()
                return
            *lines, pending = (pending + chunk).split(b"\n")
            for raw in lines:
                if not skipping:
                    self._answer(raw, reply, complain)
                skipping = False
            if len(pending) > MAX_LINE:
                complain(f"a control line longer than {MAX_LINE} bytes: left out")
                pending, skipping = b"", True

    def _answer(self, raw: bytes, reply: Callable[[str, str], None],
                complain: Callable[[str], None]) -> None:
        line = raw.decode("utf-8", "replace").strip()
        if not line or line.startswith("#"):
            return
        if len(raw) > MAX_LINE:
            complain(f"a control line longer than {MAX_LINE} bytes: left out")
            return
        try:
            reply(line, self.run(line))
        except DeltoctlError as exc:
            complain(f"{line}: {exc}")
