"""Verb processes forked from a warm deltoctl process (a "zygote"): its imports done and the
robot's profile and drivers loaded once, each verb starts in a few milliseconds instead of an
interpreter's start-up, and twenty robots answering at once do not each pay it.

The agent and its zygote talk over a Unix socket pair: the agent sends a command line with the
two pipe ends the verb writes its stdout and stderr to; the zygote forks, answers the child's
pid, and later its exit status. The agent signals the child by pid (it runs in a session of its
own). Children die with their zygote, and the zygote with the agent (SIGINT, then exit): a verb
never outlives the agent that watches its deadman.
"""

from __future__ import annotations

import collections
import contextlib
import json
import os
import signal
import socket
import subprocess
import threading
import time
from typing import Any

from deltoctl.errors import InvalidInput

MESSAGE = 65536  # bytes: the largest message between the agent and its zygote
# what a verb relies on: Ctrl-C's KeyboardInterrupt (the deadman's SIGINT stops its motion),
# SIGTERM and SIGHUP ending it; a process started from a script (`agent … &`, nohup) inherits
# them ignored
RESTORED = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def restore_signals() -> None:
    """Default dispositions for RESTORED (a Python process started after this installs its
    KeyboardInterrupt handler); for ``preexec_fn`` of every process the agent starts."""
    for sig in RESTORED:
        signal.signal(sig, signal.SIG_DFL)


class Forked:
    """A verb process forked by the zygote: the part of ``subprocess.Popen`` the agent uses."""

    def __init__(self, pid: int, stdout: Any, stderr: Any) -> None:
        self.pid, self.stdout, self.stderr = pid, stdout, stderr
        self.returncode: int | None = None
        self.exited_at: float | None = None  # time.monotonic() when the zygote reaped it
        self._exited = threading.Event()

    def send_signal(self, sig: int) -> None:
        if self.returncode is None:
            os.kill(self.pid, sig)

    def poll(self) -> int | None:
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        if not self._exited.wait(timeout):
            raise subprocess.TimeoutExpired(str(self.pid), timeout or 0)
        assert self.returncode is not None
        return self.returncode

    def exited(self, code: int) -> None:
        self.exited_at = time.monotonic()
        self.returncode = code
        self._exited.set()


class Zygote:
    """The agent's side: ``take(argv)`` runs a command line in a forked child."""

    def __init__(self, command: list[str], env: dict[str, str], cwd: str) -> None:
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        self.sock = ours
        self.proc = subprocess.Popen([*command, str(theirs.fileno())], pass_fds=[theirs.fileno()],
                                     stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                     env=env, cwd=cwd, start_new_session=True,
                                     preexec_fn=restore_signals)
        theirs.close()
        self.lock = threading.Lock()
        self.pending: collections.deque[tuple[Any, Any, threading.Event, list[Forked]]] = \
            collections.deque()
        self.children: dict[int, Forked] = {}
        self.reader = threading.Thread(target=self._read, name="zygote", daemon=True)
        self.reader.start()

    def take(self, argv: list[str]) -> Forked:
        """Fork a child running ``argv``. A command line too long for one message is refused
        before anything is sent; should the send fail, nothing stays queued (the next verb's
        pid must not be matched with this one's pipes)."""
        message = json.dumps(argv).encode()
        if len(message) > MESSAGE:
            raise InvalidInput(f"the command line is {len(message)} bytes; the agent runs "
                               f"command lines of up to {MESSAGE // 1024} KiB")
        out_r, out_w = os.pipe()
        err_r, err_w = os.pipe()
        ready = threading.Event()
        box: list[Forked] = []
        entry = (os.fdopen(out_r, "rb", buffering=0), os.fdopen(err_r, "rb", buffering=0),
                 ready, box)
        try:
            with self.lock:  # queued before the send: the zygote may answer at once
                self.pending.append(entry)
                try:
                    socket.send_fds(self.sock, [message], [out_w, err_w])
                except OSError:
                    self.pending.remove(entry)
                    entry[0].close()
                    entry[1].close()
                    raise
        finally:
            os.close(out_w)
            os.close(err_w)
        if not ready.wait(30) or not box:
            raise OSError("the verb process did not start")
        return box[0]

    def _read(self) -> None:
        while True:
            try:
                data = self.sock.recv(MESSAGE)
            except OSError:
                data = b""
            if not data:
                break
            message = json.loads(data)
            if "pid" in message or "refused" in message:
                stdout, stderr, ready, box = self.pending.popleft()
                if "refused" in message:  # a message it could not read: no child
                    stdout.close()
                    stderr.close()
                    ready.set()
                    continue
                child = Forked(message["pid"], stdout, stderr)
                self.children[child.pid] = child
                box.append(child)
                ready.set()
            elif "exit" in message:
                pid, code = message["exit"]
                child = self.children.pop(pid, None)
                if child is not None:
                    child.exited(code)
        for child in list(self.children.values()):  # the zygote died: so did its children
            child.exited(-signal.SIGKILL)
        while self.pending:
            self.pending.popleft()[2].set()

    def alive(self) -> bool:
        return self.proc.poll() is None

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self.sock.shutdown(socket.SHUT_RDWR)
        self.sock.close()
        try:
            self.proc.wait(5)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


def die_with_parent(sig: int) -> None:
    """Linux: this process gets ``sig`` when its parent dies."""
    with contextlib.suppress(Exception):
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, sig)  # PR_SET_PDEATHSIG


def serve(sock_fd: int, run: Any) -> None:
    """The zygote's loop: for each command line received, fork a child that calls
    ``run(argv)`` (returning its exit code) with the pipes received as stdout and stderr."""
    import select

    die_with_parent(signal.SIGTERM)
    sock = socket.socket(fileno=sock_fd)
    children: set[int] = set()
    while True:
        readable, _, _ = select.select([sock], [], [], 0.002 if children else None)
        if readable:
            try:
                data, fds, flags, _ = socket.recv_fds(sock, MESSAGE, 2)
            except OSError:
                data, fds, flags = b"", [], 0
            if not data:
                break
            argv = _command_line(data, fds, flags)
            if argv is None:
                for fd in fds:
                    os.close(fd)
                sock.send(b'{"refused": "not a command line"}')
                continue
            pid = os.fork()
            if pid == 0:
                sock.close()
                _child(argv, fds, run)
            for fd in fds:
                os.close(fd)
            children.add(pid)
            sock.send(json.dumps({"pid": pid}).encode())
        while children:
            pid, status = os.waitpid(-1, os.WNOHANG)
            if pid == 0:
                break
            children.discard(pid)
            with contextlib.suppress(OSError):
                sock.send(json.dumps({"exit": [pid, os.waitstatus_to_exitcode(status)]}).encode())
    for pid in children:  # the agent is gone: stop what it can no longer watch
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGINT)


def _command_line(data: bytes, fds: list[int], flags: int) -> list[str] | None:
    """The command line of a whole message with its two pipes; None for anything else."""
    if flags & (socket.MSG_TRUNC | socket.MSG_CTRUNC) or len(fds) != 2:
        return None
    try:
        argv = json.loads(data)
    except ValueError:
        return None
    if not isinstance(argv, list) or not all(isinstance(a, str) for a in argv):
        return None
    return argv


def _child(argv: list[str], fds: list[int], run: Any) -> None:
    """In the forked child: the pipes as stdout and stderr, no stdin, a session of its own."""
    import sys

    code = 1
    try:
        os.setsid()
        restore_signals()
        signal.signal(signal.SIGINT, signal.default_int_handler)  # Ctrl-C's, as at start-up
        die_with_parent(signal.SIGINT)
        os.dup2(fds[0], 1)
        os.dup2(fds[1], 2)
        for fd in fds:
            os.close(fd)
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        os.close(null)
        code = run(argv)
    except KeyboardInterrupt:  # before the verb started: nothing to stop
        code = 130
    except BaseException:  # the verb's own errors are handled by the CLI; this is a bug
        import traceback

        traceback.print_exc()
    finally:
        with contextlib.suppress(Exception):
            sys.stdout.flush()
            sys.stderr.flush()
        os._exit(code)
