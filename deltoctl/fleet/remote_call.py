"""The caller's side: run one verb on a robot's agent (``--robot``), and find the robots."""

from __future__ import annotations

import contextlib
import hashlib
import hmac
import json
import secrets
import threading
import time
from collections.abc import Callable
from typing import Any

from deltoctl.errors import DeltoctlError, DeviceError, Unreachable
from deltoctl.fleet import ERR, EXIT, HEARTBEAT, OUT, check_robot, key, zenoh_module

FOUND_WAIT = 2.0  # s to wait for agents to answer a look-up
WEEK = 7 * 86400.0  # a query's timeout: a verb (a stream) may run for long
# s to wait for the verb's exit after a cancel: beyond the agent's SIGKILL at 6 s
CANCEL_GRACE = 8.0
KEY_BYTES = 16  # the heartbeat key's size
POLL = 0.005  # s between two looks at a verb's replies when none is waiting


def sign(key_: bytes, rid: str, what: str, number: int) -> bytes:
    """A heartbeat (``alive``, numbered from 1) or the cancel (``cancel``, 0) of verb ``rid``:
    its number and an HMAC with the key that only the caller and the agent know (sent in the
    run request). Another peer can see a heartbeat but not make the next one."""
    mac = hmac.new(key_, f"{rid}/{what}/{number}".encode(), hashlib.sha256).hexdigest()
    return f"{number}:{mac}".encode()


class ErrorLines:
    """The verb's stderr, with each error naming the robot (``deltoctl: error: robot R: …``;
    with --json, a ``"robot"`` key in the error object)."""

    def __init__(self, robot: str, as_json: bool, write: Callable[[str], None]) -> None:
        self.robot, self.as_json, self.write = robot, as_json, write
        self.pending = ""

    def feed(self, data: bytes) -> None:
        text = self.pending + data.decode(errors="replace")
        *lines, self.pending = text.split("\n")
        for line in lines:
            self.write(self.named(line) + "\n")

    def close(self) -> None:
        if self.pending:
            self.write(self.named(self.pending))
            self.pending = ""

    def named(self, line: str) -> str:
        prefix = "deltoctl: error: "
        if line.startswith(prefix):
            return f"{prefix}robot {self.robot}: {line[len(prefix):]}"
        if self.as_json and line.startswith('{"error"'):
            with contextlib.suppress(ValueError, AttributeError):
                doc = json.loads(line)
                doc["error"]["robot"] = self.robot
                return json.dumps(doc)
        return line


def agents(session: Any, pattern: str = "*", wait: float = FOUND_WAIT) -> dict[str, str]:
    """``{robot: profile}`` of the agents whose liveliness token is there."""
    found: dict[str, str] = {}
    for reply in session.liveliness().get(key(pattern, "agent", "*"), timeout=wait):
        if reply.ok is not None:
            parts = str(reply.ok.key_expr).split("/")
            if len(parts) == 4:
                found[parts[1]] = parts[3]
    return found


def infos(session: Any, pattern: str = "*", wait: float = FOUND_WAIT) -> dict[str, dict]:
    """``{robot: info}`` from the agents' ``info`` queryables."""
    zenoh = zenoh_module()
    found: dict[str, dict] = {}
    for reply in session.get(key(pattern, "info"), timeout=wait,
                             consolidation=zenoh.ConsolidationMode.NONE):
        if reply.ok is not None:
            with contextlib.suppress(ValueError):
                doc = json.loads(reply.ok.payload.to_bytes())
                if isinstance(doc, dict) and isinstance(doc.get("robot"), str):
                    found[doc["robot"]] = doc
    return found


class RemoteCall:
    """One verb on one robot: heartbeat and caller token while it runs, its output handed to
    ``out``/``err`` as it comes, its exit code returned. Ctrl-C (``cancel``) interrupts it on
    the robot and waits for its exit."""

    def __init__(self, session: Any, robot: str, argv: list[str],
                 out: Callable[[bytes], None], err: Callable[[bytes], None]) -> None:
        self.session, self.robot, self.argv = session, check_robot(robot), argv
        self.out, self.err = out, err
        self.rid = secrets.token_hex(8)
        self.key = secrets.token_bytes(KEY_BYTES)  # signs its heartbeats and its cancel
        self.done = threading.Event()
        self.agent_gone = threading.Event()
        self.cancelled_at: float | None = None

    def run(self) -> int:
        zenoh = zenoh_module()
        s, live, robot = self.session, self.session.liveliness(), self.robot
        # channels, read from this thread: Zenoh's threads never call into Python, which
        # may be shutting down when they do (an abort at exit, "exception not rethrown")
        watch = live.declare_subscriber(key(robot, "agent", "*"))
        if not agents(s, robot):
            watch.undeclare()
            raise Unreachable(f"robot {robot}: no agent answers",
                              "start 'deltoctl agent' on the robot's computer; "
                              "'deltoctl fleet list' shows the robots found")
        token = live.declare_token(key(robot, "caller", self.rid))
        beat = s.declare_publisher(key(robot, "alive", self.rid), express=True,
                                   priority=zenoh.Priority.REAL_TIME)
        beats = threading.Thread(target=self._beat, args=(beat,), daemon=True)
        beats.start()
        try:
            replies = s.get(key(robot, "run"),
                            payload=json.dumps({"id": self.rid, "argv": self.argv,
                                                "key": self.key.hex()}),
                            consolidation=zenoh.ConsolidationMode.NONE, timeout=WEEK)
            return self._collect(replies, watch)
        finally:
            self.done.set()
            beats.join()
            for entity in (beat, token, watch):
                with contextlib.suppress(Exception):
                    entity.undeclare()

    def cancel(self) -> None:
        if self.cancelled_at is None:
            self.cancelled_at = time.monotonic()
            with contextlib.suppress(Exception):
                self.session.put(key(self.robot, "cancel", self.rid),
                                 sign(self.key, self.rid, "cancel", 0))

    def _collect(self, replies: Any, watch: Any) -> int:
        """The verb's replies as they come (the channel polled), until its query ends."""
        closed = zenoh_module().ZError  # what the channel raises once the query has ended
        code: int | None = None
        gone_at: float | None = None
        while True:
            try:
                reply = replies.try_recv()
                if reply is None:
                    self._watch_agent(watch)
                    now = time.monotonic()
                    if self.agent_gone.is_set() and gone_at is None:
                        gone_at = now  # replies sent before it left may still be on their way
                    if (gone_at and now - gone_at > 0.3) or (
                            self.cancelled_at and now - self.cancelled_at > CANCEL_GRACE):
                        break
                    time.sleep(POLL)
                    continue
            except closed:
                break
            except KeyboardInterrupt:
                self.cancel()
                continue
            if reply.ok is None:
                message = reply.err.payload.to_string() if reply.err is not None else "?"
                raise DeltoctlError(f"robot {self.robot}: {message}")
            data = reply.ok.payload.to_bytes()
            tag, body = data[:1], data[1:]
            if tag == OUT:
                self.out(body)
            elif tag == ERR:
                self.err(body)
            elif tag == EXIT:
                try:
                    code = int(body)
                except ValueError:
                    raise DeviceError(f"robot {self.robot}: a malformed reply from its agent "
                                      f"(exit code {body[:20]!r})") from None
        if code is None and self.cancelled_at is not None:
            self.err(f"deltoctl: robot {self.robot}: interrupted; its verb did not report "
                     f"its end within {CANCEL_GRACE:g} s\n".encode())
            return 130
        if code is None:
            raise Unreachable(f"robot {self.robot}: the agent went away before the verb "
                              "finished (the agent interrupts its verbs when it stops)")
        return code

    def _beat(self, publisher: Any) -> None:
        number = 0
        while not self.done.wait(HEARTBEAT):
            number += 1
            with contextlib.suppress(Exception):
                publisher.put(sign(self.key, self.rid, "alive", number))

    def _watch_agent(self, watch: Any) -> None:
        """The agent's liveliness token gone: it stopped (or the link to it is lost)."""
        delete = zenoh_module().SampleKind.DELETE
        while (sample := watch.try_recv()) is not None:
            if sample.kind == delete:
                self.agent_gone.set()


@contextlib.contextmanager
def caller_session(config_file: str | None, what: str) -> Any:
    from deltoctl.fleet.config import load, open_session

    session = open_session(load(config_file, "caller"), what)
    try:
        yield session
    finally:
        session.close()
