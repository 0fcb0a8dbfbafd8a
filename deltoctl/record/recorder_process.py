"""Recording in a process of its own.

The cycle loop hands its values over a pipe, a few cycles at a time; a child process
encodes them (record/mcap_recorder.py) and writes the MCAP file. Chunk compression and
indexing then never delay a cycle, and the file outlives the loop's process:

- the child ignores the signals a terminal or a supervisor sends to the whole process group
  (Ctrl-C's SIGINT, SIGTERM, SIGHUP, SIGQUIT): the parent decides when recording ends;
- it finishes the file when the pipe closes — the parent closed it, or died (EOF), or died
  while something else holds the pipe open (the parent's pid is polled when the pipe is idle);
- the file is a whole MCAP at every moment (``McapFile``), with a chunk written at least once a
  second; a write that fails (disk full, file too large) or a file removed while written
  stops the recording: the child says why, and the parent's next hand-over fails with that
  message (exit 1).
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import pickle
import signal
import struct
import time
from collections.abc import Iterator
from operator import itemgetter
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from deltoctl.errors import DeviceError
from deltoctl.profile.model import Profile

if TYPE_CHECKING:
    from multiprocessing.connection import Connection
    from multiprocessing.context import ForkContext, SpawnContext

    from deltoctl.record.mcap_recorder import McapFile, McapRecorder

NAN = float("nan")
# Cycles go to the child in batches: at least every 5 ms (a slow loop: every cycle), at most
# 64 KiB at a time. A killed loop loses at most the last 5 ms.
BATCH_SECONDS = 0.005
BATCH_BYTES = 1 << 16
CHUNK_SECONDS = 1.0  # the child writes the chunk in progress at least this often
IDLE_CHECK = 0.25  # s without data after which the child looks whether its parent is alive
# What a terminal or a supervisor sends to a whole process group; the child ignores them.
GROUP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP",
                                                         "SIGQUIT") if hasattr(signal, name))


def _nothing(values: dict) -> tuple:
    return ()


def _widen(conn: Connection) -> None:
    """Up to a second of cycles in flight: a pipe of 1 MiB where Linux allows it."""
    try:
        import fcntl

        fcntl.fcntl(conn.fileno(), getattr(fcntl, "F_SETPIPE_SZ", 1031), 1 << 20)
    except (ImportError, OSError):
        pass


def _context() -> ForkContext | SpawnContext:
    if "fork" in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context("fork")
    return multiprocessing.get_context("spawn")


@contextlib.contextmanager
def _signals_held() -> Iterator[None]:
    """The group's signals wait (blocked, not lost) until the block ends: a child started
    inside ignores them before any can reach it, and a message is never sent by halves (a
    KeyboardInterrupt between two writes of one would garble the pipe)."""
    block = getattr(signal, "pthread_sigmask", None)
    if block is None:  # Windows: no signals to a group
        yield
        return
    previous = block(signal.SIG_BLOCK, GROUP_SIGNALS)
    try:
        yield
    finally:
        block(signal.SIG_SETMASK, previous)


class RecorderProcess:
    """``write``, ``diagnostic(s)`` and ``close`` as ``McapRecorder`` has them; ``counts``,
    ``link_losses`` and ``error`` (why the recording stopped early, or None) are known once
    closed. A hand-over that finds the child gone closes and raises DeviceError with its
    reason. Use it as a context manager so the file is finished whatever happens."""

    def __init__(self, path: Path, profile: Profile, metadata: dict[str, dict[str, str]],
                 extra_states: tuple[str, ...] = (), gpio_type: str = "group-values",
                 commands: bool = False) -> None:
        """``gpio_type``: /gpio's message type (``ros2_msgs.GPIO_TYPES``); ``commands``: a
        /joint_commands topic of each cycle's setpoints too (``McapRecorder``)."""
        import deltoctl.record.mcap_recorder  # noqa: F401  (imported before a fork, not after)
        from deltoctl.record.ros2_msgs import GPIO_TYPES

        if gpio_type not in GPIO_TYPES:  # said here, not by a child that cannot start
            raise ValueError(f"gpio_type {gpio_type!r}: one of {', '.join(GPIO_TYPES)}")

        ctx = _context()
        values_in, self._pipe = ctx.Pipe(duplex=False)
        self._results, results_out = ctx.Pipe(duplex=False)
        self.path = path
        self.proc = ctx.Process(target=_record, name="deltoctl-recorder", daemon=True,
                                args=(values_in, self._pipe, results_out, str(path), profile,
                                      metadata, extra_states, gpio_type, os.getpid(),
                                      commands))
        _widen(self._pipe)
        with _signals_held():  # the child starts with them blocked and ignores them
            self.proc.start()
        values_in.close()
        results_out.close()
        self.keys: list[str] = []
        self._pick = _nothing
        self._row = struct.Struct("<Q")  # a cycle's t_ns and values, as handed over
        self._batch = bytearray(b"v")  # cycles not yet handed over: t_ns and values each
        self._flushed = time.monotonic()
        self.counts: dict[str, int] = {}
        self.link_losses = 0
        self.cpu_seconds = 0.0  # the child's, once closed
        self.setup_cpu_seconds = 0.0  # of which starting and finishing the file
        self.error: str | None = None
        self.closed = False

    def __enter__(self) -> RecorderProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def write(self, values: dict[str, float], t_ns: int) -> None:
        keys = self.keys
        if len(values) == len(keys) and list(values) == keys:  # the usual: as last cycle
            self._batch += self._row.pack(t_ns, *values.values())
        else:
            self._write_picked(values, t_ns)
        now = time.monotonic()
        if now - self._flushed >= BATCH_SECONDS or len(self._batch) >= BATCH_BYTES:
            self._flush(now)

    def _write_picked(self, values: dict[str, float], t_ns: int) -> None:
        """A cycle whose interfaces are not the last cycle's, or not in their order."""
        try:
            picked = self._pick(values)
        except KeyError:  # an interface went missing: NaN for it this cycle
            picked = [values.get(k, NAN) for k in self.keys]
        if len(values) != len(self.keys):  # the set of interfaces changed (the first cycle)
            self._flush()
            self.keys = list(values)
            self._pick = itemgetter(*self.keys) if len(self.keys) > 1 else \
                (lambda v, k=self.keys[0]: (v[k],))
            self._row = struct.Struct(f"<Q{len(self.keys)}d")
            self._send(b"k" + pickle.dumps(self.keys))
            picked = self._pick(values)
        self._batch += self._row.pack(t_ns, *picked)

    def _flush(self, now: float | None = None) -> None:
        """Hand the cycles gathered so far to the child (one write for several cycles)."""
        if len(self._batch) > 1:
            self._send(self._batch)
            del self._batch[1:]
        self._flushed = time.monotonic() if now is None else now

    def _send(self, message: bytes | bytearray) -> None:
        try:
            with _signals_held():
                self._pipe.send_bytes(message)
        except OSError:  # the child stopped reading: it says why once closed
            self.close()
            raise DeviceError(self.error or "the recorder process stopped") from None

    def diagnostic(self, t_ns: int, level: int, name: str, message: str,
                   values: dict[str, Any]) -> None:
        self.diagnostics(t_ns, [(level, name, message, values)])

    def diagnostics(self, t_ns: int, statuses: list[tuple[int, str, str, dict[str, Any]]]) -> None:
        self._flush()
        self._send(b"d" + pickle.dumps((t_ns, statuses)))

    def close(self, loop_summary: dict[str, Any] | None = None) -> None:
        """Finish the file (with the loop's final statistics) and wait for the child."""
        if self.closed:
            return
        self.closed = True
        with contextlib.suppress(OSError), _signals_held():  # the child may be gone already
            if len(self._batch) > 1:
                self._pipe.send_bytes(self._batch)
            self._pipe.send_bytes(b"c" + pickle.dumps(loop_summary))
        self._pipe.close()
        try:
            result = self._results.recv()
        except EOFError:  # killed, or it crashed before it could say anything
            result = {"error": f"the recorder process ended unexpectedly; {self.path} keeps "
                               "what it had written (a valid MCAP up to its last chunk)"}
        self.counts = result.get("counts", {})
        self.link_losses = result.get("link_losses", 0)
        self.cpu_seconds = result.get("cpu_seconds", 0.0)
        self.setup_cpu_seconds = result.get("setup_cpu_seconds", 0.0)
        self.error = result.get("error")
        self._results.close()
        self.proc.join()


# -- the child -----------------------------------------------------------------------------------

def _record(pipe: Connection, parent_end: Connection, results: Connection, path: str,
            profile: Profile, metadata: dict[str, Any], extra_states: tuple[str, ...],
            gpio_type: str, parent_pid: int, commands: bool = False) -> None:
    """The child: values in, MCAP out, until told to close or the parent is gone."""
    parent_end.close()  # else the pipe would never close while this process holds its end
    if _context().get_start_method() == "fork":  # spawn passes only the pipes
        _close_inherited({pipe.fileno(), results.fileno()})
    for sig in GROUP_SIGNALS:  # the parent decides when recording ends
        signal.signal(sig, signal.SIG_IGN)
    if hasattr(signal, "pthread_sigmask"):  # blocked since before the fork
        signal.pthread_sigmask(signal.SIG_UNBLOCK, GROUP_SIGNALS)
    with contextlib.suppress(OSError, AttributeError):
        os.nice(10)  # the loop and the device come first; the pipe holds the backlog
    from deltoctl.record.mcap_recorder import McapFile, McapRecorder

    error = recorder = out = None
    cycles_cpu = 0.0  # the CPU time of the cycles, between starting and finishing the file
    summary = None
    try:
        out = McapFile(path)
        recorder = McapRecorder(out, profile, metadata, extra_states, gpio_type,
                                commands=commands)
        cycles_cpu = -time.process_time()
        summary = _receive(pipe, recorder, out, parent_pid)
        cycles_cpu += time.process_time()
    except Exception as exc:  # the file failed (OSError), or a bug: finish what was recorded
        error = exc
    pipe.close()  # the parent's next hand-over fails at once: its loop stops
    if recorder is not None:
        try:
            recorder.close(summary, time.time_ns())
        except Exception as exc:
            error = error or exc
    report = {"counts": recorder.counts if recorder else {},
              "link_losses": recorder.link_losses if recorder else 0,
              "error": _why_stopped(path, out, error)}
    if out is not None:
        with contextlib.suppress(OSError):
            out.close()
    report["cpu_seconds"] = time.process_time()
    report["setup_cpu_seconds"] = report["cpu_seconds"] - max(cycles_cpu, 0.0)
    with contextlib.suppress(OSError):  # a parent killed cannot hear it
        results.send(report)


def _close_inherited(keep: set[int]) -> None:
    """Close what a fork brought along beyond the pipes and stdio: held here, the parent's
    device connections and serial ports (flock-ed, opened exclusively) would outlive it, and
    a port the parent reopens would find itself busy."""
    low = 3
    for fd in sorted(k for k in keep if k >= low):
        os.closerange(low, fd)
        low = fd + 1
    with contextlib.suppress(ValueError, OSError):
        os.closerange(low, os.sysconf("SC_OPEN_MAX"))


def _receive(pipe: Connection, recorder: McapRecorder, out: McapFile,
             parent_pid: int) -> dict[str, Any] | None:
    """Hand the parent's messages to the recorder until it closes (returns the loop's summary)
    or goes away, or the file is removed (None). The chunk in progress goes to disk at least
    every CHUNK_SECONDS."""
    row = struct.Struct("<q")
    flushed = time.monotonic()
    while not out.removed:
        if pipe.poll(IDLE_CHECK):
            try:
                msg = pipe.recv_bytes()
            except (EOFError, OSError):
                return None  # the loop's process went away: finish what was recorded
            kind = msg[:1]
            if kind == b"v":
                for at in range(1, len(msg), row.size):
                    t_ns, *values = row.unpack_from(msg, at)
                    recorder.write_row(values, t_ns)
            elif kind == b"k":
                keys = pickle.loads(msg[1:])
                recorder.set_keys(keys)
                row = struct.Struct(f"<q{len(keys)}d")
            elif kind == b"d":
                recorder.diagnostics(*pickle.loads(msg[1:]))
            elif kind == b"c":
                return cast("dict[str, Any]", pickle.loads(msg[1:]))
        elif os.getppid() != parent_pid:
            return None  # the parent died while something else holds the pipe open
        now = time.monotonic()
        if now - flushed >= CHUNK_SECONDS:
            recorder.flush()
            flushed = now
    return None


def _why_stopped(path: str, out: Any, error: BaseException | None) -> str | None:
    """One sentence for the user when the recording did not end as asked, else None."""
    if out is not None and out.removed:
        try:
            copy = out.save_copy()
        except OSError as exc:
            return (f"recording stopped: {path} was removed while recording, and what was "
                    f"recorded could not be saved elsewhere ({exc.strerror or exc})")
        return (f"recording stopped: {path} was removed while recording; what was recorded "
                f"is saved in {copy}")
    if error is None:
        return None
    if isinstance(error, OSError):
        reason = f"cannot write {path}: {error.strerror or error}"
    else:
        reason = f"the recorder failed: {type(error).__name__}: {error}"
    if out is None or not out.readable:
        return f"recording stopped: {reason}; nothing could be recorded"
    return (f"recording stopped: {reason}; the file is a valid MCAP with everything written "
            "before the error")
