"""A remote ``record``: ``deltoctl --robot ROBOT record FILE.mcap`` writes FILE on this
computer.

The robot's agent runs ``stream --json`` with the record's loop options. Each NDJSON frame
carries the robot's time of its cycle (``t``, integer ns) and every state interface of the
blocks it drives; this computer writes them with deltoctl's own recorder, with the robot's
resolved profile (the agent's ``info?profile_yaml``) and each block's ``identify`` as
metadata: the same kind of recording as one made on the robot, each message logged at the
robot's cycle time. Ctrl-C (SIGTERM, SIGHUP) stops the stream on the robot and the file is
finished; a robot lost mid-recording leaves a finished file too.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import re
import signal
import threading
from array import array
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from deltoctl.errors import WARNINGS, DeltoctlError, DeviceError, InvalidInput, Unreachable
from deltoctl.fleet import key
from deltoctl.fleet.agent import PROFILE_YAML
from deltoctl.fleet.remote_call import FOUND_WAIT, RemoteCall
from deltoctl.profile.model import Profile

NAN = float("nan")
STATUS = "/connection_status"
# the stream's last line on stderr: how many cycles the robot ran
SAMPLES = re.compile(r"(\d+) samples of \d+ interfaces")
# the figures of the robot's own loop a remote record reports, as a local record does
ROBOT_LOOP = ("lateness_p50_ms", "lateness_p99_ms", "packets", "errors", "error_rate_perc")


def agent_info(session: Any, robot: str, wait: float = FOUND_WAIT) -> dict[str, Any]:
    """The robot's info document with its resolved profile's YAML."""
    for reply in session.get(f"{key(robot, 'info')}?{PROFILE_YAML}", timeout=wait):
        if reply.ok is None:
            continue
        with contextlib.suppress(ValueError):
            doc = json.loads(reply.ok.payload.to_bytes())
            if isinstance(doc, dict) and doc.get("robot") == robot:
                return doc
    raise Unreachable(f"robot {robot}: no agent answers",
                      "start 'deltoctl agent' on the robot's computer; "
                      "'deltoctl fleet list' shows the robots found")


def load_profile_text(text: object, source: str) -> Profile:
    """A profile sent over the network: untrusted text, loaded as a profile file is (size and
    YAML bounds, validation)."""
    from deltoctl.profile.catalog import profile_from_text

    if not isinstance(text, str) or not text.strip():
        raise InvalidInput(f"{source}: the agent sent no profile",
                           "update deltoctl on the robot's computer (its agent sends the "
                           "profile a remote record needs)")
    return profile_from_text(text, source)


def driven(profile: Profile, names: list[str]) -> tuple[Profile, tuple[str, ...]]:
    """The profile of the blocks the stream's interfaces come from (``--hardware`` on either
    side), and the drivers' extra states among them (a Bioscara joint's flags)."""
    blocks = [hw for hw in profile.hardware if f"{hw.name}{STATUS}" in names]
    recorded = dataclasses.replace(profile, hardware=blocks) if blocks else profile
    known = {f"{j.name}/{i.name}" for j in recorded.joints() for i in j.state_interfaces}
    joints = {j.name for j in recorded.joints()}
    extras = tuple(n for n in names if n not in known and n.rpartition("/")[0] in joints)
    return recorded, extras


class Lines:
    """Complete lines out of a byte stream's chunks."""

    def __init__(self, line: Callable[[bytes], None]) -> None:
        self.line, self.pending = line, b""

    def feed(self, data: bytes) -> None:
        *lines, self.pending = (self.pending + data).split(b"\n")
        for one in lines:
            self.line(one)

    def close(self) -> None:
        if self.pending:
            self.line(self.pending)
            self.pending = b""


class RemoteRecord:
    """Records ``robot``'s stream to ``output`` on this computer.

    ``options``: the global options the robot's verbs get (``--hardware`` …); ``err``: where
    the robot's stderr goes; ``opened``: called when the file is created. ``run()`` returns
    the stream's exit code, or raises the error that stopped it (a lost robot: Unreachable)
    once the file is finished; ``result`` is the report a local ``record --json`` prints."""

    def __init__(self, session: Any, robot: str, output: Path, rate: float,
                 duration: float | None, options: list[str], gpio_type: str = "group-values",
                 allow_model_mismatch: bool = False,
                 err: Callable[[bytes], None] = lambda _: None,
                 opened: Callable[[], None] = lambda: None,
                 name: Callable[[Path, dict[str, dict[str, Any]]], Path] | None = None) -> None:
        self.session, self.robot, self.output = session, robot, output
        self.name = name  # the file's name from each block's identity (and its checks)
        self.opened = opened  # called once the file is created (the first frame came)
        self.rate, self.duration, self.options = rate, duration, list(options)
        self.gpio_type, self.err = gpio_type, err
        self.mismatch = ["--allow-model-mismatch"] if allow_model_mismatch else []
        self.profile: Profile | None = None
        self.metadata: dict[str, dict[str, str]] = {}
        self.recorder: Any = None
        self.failure: DeltoctlError | None = None  # why frames stopped being written here
        self.call: RemoteCall | None = None
        self.cancelled = threading.Event()
        self.cycles = 0
        self.robot_cycles: int | None = None
        self.robot_loop: dict[str, float] = {}  # the robot's lateness and packet figures
        self.first_ns = self.last_ns = 0
        self.periods = array("q")
        self.bad_lines = 0
        self.result: dict[str, Any] = {}
        self._frames = Lines(self._frame)
        self._errors = Lines(self._error_line)

    # -- the run ----------------------------------------------------------------------------

    def run(self) -> int:
        from deltoctl.version import __version__

        info = agent_info(self.session, self.robot)
        self.profile = load_profile_text(info.get(PROFILE_YAML),
                                         f"robot {self.robot}: its profile")
        identities, code = self._identify()
        if identities is None:
            return code
        if self.cancelled.is_set():  # Ctrl-C before the stream started: no file
            return 130
        self._name_output(identities)
        self.metadata = {"identify": identities, "deltoctl": {"version": __version__},
                         "remote": {"robot": self.robot, "profile": self.profile.name}}
        argv = [*self.options, "stream", "--json", "--rate", repr(self.rate), *self.mismatch]
        if self.duration is not None:
            argv += ["--duration", repr(self.duration)]
        stopped: DeltoctlError | None = None
        code = -1
        try:
            self.call = RemoteCall(self.session, self.robot, argv, self._frames.feed,
                                   self._errors.feed)
            code = self.call.run()
        except DeltoctlError as exc:  # the robot went away: finish what arrived
            stopped = exc
        finally:
            self._frames.close()
            self._errors.close()
            self._finish(ended_well=code == 0)
        if stopped is not None:
            raise stopped
        if self.failure is not None:
            raise self.failure
        return code

    def cancel(self) -> None:
        """Stop the stream on the robot (Ctrl-C); the file is finished as it ends."""
        self.cancelled.set()
        call = self.call
        if call is not None:
            call.cancel()

    def _identify(self) -> tuple[dict[str, str] | None, int]:
        """Each block's identify result, as a local record keeps it; None and the exit code
        when the robot cannot say (its error passed on, no file written)."""
        out: list[bytes] = []
        err: list[bytes] = []
        self.call = RemoteCall(self.session, self.robot,
                               [*self.options, "identify", "--json", *self.mismatch],
                               out.append, err.append)
        code = self.call.run()
        try:
            report = json.loads(b"".join(out)) if code in (0, 3) else None
            blocks = report["blocks"] if isinstance(report, dict) else None
            identities = {str(b["name"]): json.dumps(
                {"family": b.get("family"), "target": b.get("target"),
                 "simulated": b.get("simulated"), **b.get("identity", {})}, default=str)
                for b in blocks} if isinstance(blocks, list) else None
        except (ValueError, KeyError, TypeError, AttributeError):
            identities = None
        if identities is None:
            self.err(b"".join(err))
            return None, code or 1
        return identities, code

    def _name_output(self, identities: dict[str, str]) -> None:
        """The file's name (``{serial}`` …) from the blocks the robot identified, by
        ``name``, which may refuse it."""
        if self.name is not None:
            self.output = self.name(self.output, {block: json.loads(text)
                                                  for block, text in identities.items()})

    # -- frames -----------------------------------------------------------------------------

    def _frame(self, line: bytes) -> None:
        if not line.startswith(b"{") or self.failure is not None:
            return
        try:
            doc = json.loads(line)
            t_ns, values = doc["t"], doc["values"]
            if not isinstance(t_ns, int) or not isinstance(values, dict):
                raise TypeError
        except (ValueError, KeyError, TypeError):
            self.bad_lines += 1
            return
        if None in values.values():  # an interface without a value this cycle
            values = {k: NAN if v is None else v for k, v in values.items()}
        try:
            if self.recorder is None:
                self._open(list(values))
            self.recorder.write(values, t_ns)
        except (DeltoctlError, TypeError, ValueError) as exc:  # the file failed: stop there
            self.failure = exc if isinstance(exc, DeltoctlError) else \
                DeviceError(f"robot {self.robot}: a frame could not be recorded: {exc}")
            self.cancel()
            return
        if self.cycles:
            self.periods.append(t_ns - self.last_ns)
        else:
            self.first_ns = t_ns
        self.cycles += 1
        self.last_ns = t_ns

    def _open(self, names: list[str]) -> None:
        from deltoctl.profile.exporter import to_yaml
        from deltoctl.record.recorder_process import RecorderProcess

        assert self.profile is not None
        recorded, extras = driven(self.profile, names)
        metadata = {"profile": {"name": recorded.name, "yaml": to_yaml(recorded)},
                    **self.metadata}
        try:
            self.recorder = RecorderProcess(self.output, recorded, metadata, extras,
                                            gpio_type=self.gpio_type)
        except OSError as exc:
            raise DeviceError(f"cannot write {self.output}: {exc.strerror or exc}") from None
        self.opened()

    def _error_line(self, line: bytes) -> None:
        if line.startswith(b'{"verb"'):  # the stream's document: the robot's loop
            self._stream_document(line)
            return
        found = SAMPLES.fullmatch(line.decode(errors="replace").strip())
        if found:  # said by this side, as a local record says it
            self.robot_cycles = int(found.group(1))
        else:
            self.err(line + b"\n")

    def _stream_document(self, line: bytes) -> None:
        """The robot's loop figures a local record reports (lateness, packets, errors), from
        the stream's closing document; what is not a number of its is left out."""
        try:
            loop = json.loads(line)["result"]["loop"]
        except (ValueError, KeyError, TypeError):
            return
        if isinstance(loop, dict):
            self.robot_loop = {k: loop[k] for k in ROBOT_LOOP if isinstance(
                loop.get(k), (int, float)) and not isinstance(loop.get(k), bool)}

    # -- the end ----------------------------------------------------------------------------

    def _finish(self, ended_well: bool) -> None:
        """Finish the file (an empty recording when the robot ran no cycle but the stream
        ended well) and make the report."""
        if self.recorder is None:
            if not ended_well or self.profile is None or self.failure is not None:
                return
            try:
                self._open([])
            except DeltoctlError as exc:
                self.failure = exc
                return
        summary = self.summary()
        self.recorder.close(summary)
        if self.recorder.error and self.failure is None:
            self.failure = DeviceError(self.recorder.error)
        self.result = {"output": str(self.output), "robot": self.robot,
                       "messages": self.recorder.counts,
                       "link_losses": self.recorder.link_losses, "loop": summary}

    def summary(self) -> dict[str, Any]:
        """The robot's loop as its cycle times tell it: rate, cycles, period jitter, and the
        cycles it ran against those written here; its lateness and packet figures as its
        stream's document says them (0 from an agent that sends none)."""
        period_ns = 1e9 / self.rate
        span = (self.last_ns - self.first_ns) / 1e9
        jitter = sorted(abs(p - period_ns) for p in self.periods)

        def ms(q: float) -> float:
            return round(jitter[min(len(jitter) - 1, round(q * (len(jitter) - 1)))] / 1e6,
                         4) if jitter else 0.0

        robot = {k: self.robot_loop.get(k, 0) for k in ROBOT_LOOP}
        return {"requested_rate": self.rate,
                "real_rate": round((self.cycles - 1) / span, 2) if span > 0 else 0.0,
                "cycles": self.cycles,
                "deadline_misses": sum(1 for p in self.periods if p >= 2 * period_ns),
                "lateness_p50_ms": robot["lateness_p50_ms"],
                "lateness_p99_ms": robot["lateness_p99_ms"],
                "period_jitter_p50_ms": ms(0.5), "period_jitter_p99_ms": ms(0.99),
                "packets": robot["packets"], "errors": robot["errors"],
                "error_rate_perc": robot["error_rate_perc"],
                "robot": self.robot, "robot_cycles": self.robot_cycles,
                "cycles_not_received": max(0, (self.robot_cycles or 0) - self.cycles)}


@contextlib.contextmanager
def cancelled_by_signals(cancel: Callable[[], None]) -> Iterator[None]:
    """Ctrl-C, SIGTERM and SIGHUP stop the remote stream (the file is finished as it ends);
    the old handlers come back after. Outside the main thread: nothing to install."""
    previous = {}
    for sig in (signal.SIGINT, signal.SIGTERM, getattr(signal, "SIGHUP", None)):
        if sig is not None:
            with contextlib.suppress(ValueError):
                previous[sig] = signal.signal(sig, lambda *_: cancel())
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


@dataclasses.dataclass
class Recorded:
    """How a remote record ended. ``code``: the stream's exit code on the robot (4 when its
    link was down at the end, 3 when lost and back), 3 when cycles it ran did not arrive, 130
    when interrupted before the stream started; ``result``: the report a local ``record
    --json`` prints, once the file is finished (empty when none is to be shown); ``failure``:
    the error that stopped the record (a lost robot: Unreachable, its file finished)."""

    code: int
    result: dict[str, Any]
    failure: DeltoctlError | None = None
    profile: str | None = None  # the name of the robot's profile, as its agent sent it

    @property
    def not_received(self) -> int:
        """The cycles the robot ran that did not arrive here (their gaps are marked on
        /diagnostics)."""
        return int(self.result["loop"]["cycles_not_received"]) if self.result else 0


def record_remote(zenoh_config: str | None, robot: str, output: Path, rate: float,
                  duration: float | None, options: list[str], gpio_type: str,
                  allow_model_mismatch: bool, err: Callable[[bytes], None],
                  opened: Callable[[Path], None],
                  name: Callable[[Path, dict[str, dict[str, Any]]], Path]) -> Recorded:
    """``deltoctl --robot ROBOT record FILE``: the robot's stream recorded to ``output`` on
    this computer (see RemoteRecord), over a caller's session of ``zenoh_config``; Ctrl-C,
    SIGTERM and SIGHUP end it and the file is finished. ``opened`` is told the file once it
    is created."""
    from deltoctl.fleet.remote_call import caller_session

    failure: DeltoctlError | None = None
    with caller_session(zenoh_config, f"robot {robot}") as session:
        rec = RemoteRecord(session, robot, output, rate, duration, options, gpio_type,
                           allow_model_mismatch, err, opened=lambda: opened(rec.output),
                           name=name)
        with cancelled_by_signals(rec.cancel):
            try:
                code = rec.run()
            except DeltoctlError as exc:
                failure, code = exc, exc.exit_code
    shown = rec.result and (failure is None or isinstance(failure, Unreachable))
    done = Recorded(code, rec.result if shown else {}, failure,
                    rec.profile.name if rec.profile else None)
    if done.not_received:
        done.code = done.code or WARNINGS
    return done
