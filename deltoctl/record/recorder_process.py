"""Recording in a process of its own.

The cycle loop hands its values over a pipe, a few cycles at a time; a child process
encodes them (record/mcap_recorder.py) and writes the MCAP file. Chunk compression and
indexing then never delay a cycle, and the file is closed validly even when the loop's
process dies: the child ignores Ctrl-C and SIGTERM and finishes the file when the pipe closes.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import pickle
import signal
import struct
import time
from array import array
from operator import itemgetter
from pathlib import Path
from typing import Any

from deltoctl.profile.model import Profile

NAN = float("nan")
# Cycles go to the child in batches: at least every 5 ms (a slow loop: every cycle), at most
# 64 KiB at a time. A killed loop loses at most the last 5 ms.
BATCH_SECONDS = 0.005
BATCH_BYTES = 1 << 16


def _nothing(values: dict) -> tuple:
    return ()


def _widen(conn) -> None:  # type: ignore[no-untyped-def]
    """Up to a second of cycles in flight: a pipe of 1 MiB where Linux allows it."""
    try:
        import fcntl

        fcntl.fcntl(conn.fileno(), getattr(fcntl, "F_SETPIPE_SZ", 1031), 1 << 20)
    except (ImportError, OSError):
        pass


def _context():  # type: ignore[no-untyped-def]
    methods = multiprocessing.get_all_start_methods()
    return multiprocessing.get_context("fork" if "fork" in methods else "spawn")


class RecorderProcess:
    """``write``, ``diagnostic(s)`` and ``close`` as ``McapRecorder`` has them; ``counts``
    and ``link_losses`` are known once closed."""

    def __init__(self, path: Path, profile: Profile, metadata: dict[str, dict[str, str]],
                 extra_states: tuple[str, ...] = ()) -> None:
        import deltoctl.record.mcap_recorder  # noqa: F401  (imported before a fork, not after)

        ctx = _context()
        values_in, self._pipe = ctx.Pipe(duplex=False)
        self._results, results_out = ctx.Pipe(duplex=False)
        self.proc = ctx.Process(target=_record, name="deltoctl-recorder", daemon=True,
                                args=(values_in, self._pipe, results_out, str(path), profile,
                                      metadata, extra_states))
        _widen(self._pipe)
        self.proc.start()
        values_in.close()
        results_out.close()
        self.keys: list[str] = []
        self._pick = _nothing
        self._batch = bytearray(b"v")  # cycles not yet handed over: t_ns and values each
        self._flushed = time.monotonic()
        self.counts: dict[str, int] = {}
        self.link_losses = 0
        self.cpu_seconds = 0.0  # the child's, once closed
        self.closed = False

    def write(self, values: dict[str, float], t_ns: int) -> None:
        try:
            picked = self._pick(values)
        except KeyError:  # an interface went missing: NaN for it this cycle
            picked = [values.get(k, NAN) for k in self.keys]
        if len(values) != len(self.keys):  # the set of interfaces changed (the first cycle)
            self._flush()
            self.keys = list(values)
            self._pick = itemgetter(*self.keys) if len(self.keys) > 1 else \
                (lambda v, k=self.keys[0]: (v[k],))
            self._pipe.send_bytes(b"k" + pickle.dumps(self.keys))
            picked = self._pick(values)
        batch = self._batch
        batch += t_ns.to_bytes(8, "little")
        batch += array("d", picked).tobytes()
        now = time.monotonic()
        if now - self._flushed >= BATCH_SECONDS or len(batch) >= BATCH_BYTES:
            self._flush(now)

    def _flush(self, now: float | None = None) -> None:
        """Hand the cycles gathered so far to the child (one write for several cycles)."""
        if len(self._batch) > 1:
            self._pipe.send_bytes(self._batch)
            del self._batch[1:]
        self._flushed = time.monotonic() if now is None else now

    def diagnostic(self, t_ns: int, level: int, name: str, message: str,
                   values: dict[str, Any]) -> None:
        self.diagnostics(t_ns, [(level, name, message, values)])

    def diagnostics(self, t_ns: int, statuses: list[tuple[int, str, str, dict[str, Any]]]) -> None:
        self._flush()
        self._pipe.send_bytes(b"d" + pickle.dumps((t_ns, statuses)))

    def close(self, loop_summary: dict[str, Any] | None = None) -> None:
        """Finish the file (with the loop's final statistics) and wait for the child."""
        if self.closed:
            return
        self.closed = True
        with contextlib.suppress(OSError):  # the child may be gone already
            self._flush()
            self._pipe.send_bytes(b"c" + pickle.dumps(loop_summary))
        self._pipe.close()
        try:
            result = self._results.recv()
            self.counts, self.link_losses = result["counts"], result["link_losses"]
            self.cpu_seconds = result["cpu_seconds"]
        except EOFError:
            pass
        self.proc.join()


def _record(pipe, parent_end, results, path: str, profile: Profile,  # type: ignore[no-untyped-def]
            metadata: dict, extra_states: tuple[str, ...]) -> None:
    """The child: values in, MCAP out, until told to close or the pipe closes."""
    parent_end.close()  # else the pipe would never close while this process holds its end
    from deltoctl.record.mcap_recorder import McapRecorder

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides when recording ends
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    with contextlib.suppress(OSError, AttributeError):
        os.nice(10)  # the loop and the device come first; the pipe holds the backlog
    row = struct.Struct("<q")
    summary = None
    with open(path, "wb") as stream:
        recorder = McapRecorder(stream, profile, metadata, extra_states)
        try:
            while True:
                msg = pipe.recv_bytes()
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
                    summary = pickle.loads(msg[1:])
                    break
        except (EOFError, OSError):
            pass  # the loop's process went away: finish what was recorded
        finally:
            recorder.close(summary, time.time_ns())
    results.send({"counts": recorder.counts, "link_losses": recorder.link_losses,
                  "cpu_seconds": time.process_time()})
