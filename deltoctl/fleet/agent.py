"""The agent: serves one robot over Zenoh. Each remote verb runs as a deltoctl process of its
own against the robot's links (with ``--sim``, against one simulator that lives as long as the
agent, so homing and positions persist between verbs as on the robot). The verb's stdout,
stderr and exit code travel back as replies to the caller's query.

Deadman: while a verb runs, its caller publishes a heartbeat and holds a liveliness token. The
agent interrupts the verb (SIGINT: the CLI stops motion safely and exits 130) when no heartbeat
came for the deadline (motion: ``--deadline``, 0.2 s by default; other verbs: 5 s), when the
token goes, when the caller cancels, or when the agent stops.
"""

from __future__ import annotations

import contextlib
import hmac
import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Collection
from typing import Any

from deltoctl.errors import DeltoctlError, InvalidInput, Refused, Unreachable
from deltoctl.fleet import (
    ACTUATING,
    DEADLINE,
    ERR,
    EXIT,
    MAX_VERBS,
    MOTION,
    OUT,
    SET_SAFE,
    key,
    zenoh_module,
)
from deltoctl.fleet.argv import _values, check_argv, fits, read_request
from deltoctl.fleet.remote_call import KEY_BYTES, sign
from deltoctl.verbs import UNRESOLVED

WATCH_PERIOD = 0.005  # s between two looks at the heartbeats
LENIENT = 5.0  # s: the deadline of a verb that moves nothing (a busy caller is no danger)
ESCALATE = (3.0, 6.0)  # s after SIGINT: SIGTERM, then SIGKILL, for a verb that will not stop
MAKE_SAFE = 30.0  # s for the connect that leaves a killed motion verb's blocks safe
_RID = frozenset("0123456789abcdef")
PROFILE_YAML = "profile_yaml"  # the info query's parameter, and its key in the answer


def log(message: str) -> None:
    stamp = time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime())
    sys.stderr.write(f"{stamp}Z {message}\n")
    sys.stderr.flush()


def _signal_name(number: int) -> str:
    try:
        return signal.Signals(number).name
    except ValueError:
        return f"signal {number}"


def beat_key(request: dict[str, Any]) -> bytes:
    """The heartbeat key of a run request: a secret only the caller and this agent know, that
    signs its heartbeats and its cancel (see client.sign)."""
    text = request.get("key")
    if not (isinstance(text, str) and len(text) == 2 * KEY_BYTES and set(text) <= _RID):
        raise InvalidInput("a run request needs the key of its heartbeats (hex digits)",
                           "update deltoctl on the caller's computer")
    return bytes.fromhex(text)


class Running:
    """One verb running for one caller."""

    def __init__(self, rid: str, verb: str, proc: subprocess.Popen[bytes],
                 beat: bytes = b"") -> None:
        self.rid, self.verb, self.proc = rid, verb, proc
        self.started = self.last_beat = time.monotonic()
        self.beat, self.beats = beat, 0  # the heartbeat key; the last heartbeat's number
        self.caller_gone = False
        self.interrupted_at: float | None = None
        self.ended_at: float | None = None  # when the deadman saw the process gone
        self.signals: list[tuple[signal.Signals, float]] = []  # sent, and when
        self.why = ""
        self.made_safe = False  # killed, then its blocks set safe by the agent

    def interrupt(self, why: str) -> None:
        if self.interrupted_at is None and self.proc.poll() is None:
            self.interrupted_at, self.why = time.monotonic(), why
            self.send(signal.SIGINT)

    def send(self, sig: signal.Signals) -> None:
        self.signals.append((sig, time.monotonic()))
        with contextlib.suppress(ProcessLookupError):
            self.proc.send_signal(sig)

    def escalate(self, now: float) -> signal.Signals | None:
        """SIGTERM, then SIGKILL, each once, for an interrupted verb that will not stop."""
        assert self.interrupted_at is not None
        sent = {sig for sig, _ in self.signals}
        for sig, after in zip((signal.SIGTERM, signal.SIGKILL), ESCALATE):
            if now - self.interrupted_at > after and sig not in sent:
                self.send(sig)
                return sig
        return None

    def signed(self, payload: bytes, what: str) -> bool:
        """Whether ``payload`` is a heartbeat (``alive``) or the cancel of this verb's caller:
        signed with its key, a heartbeat numbered after the last one (a heartbeat seen on
        the network cannot be played again)."""
        number = payload.partition(b":")[0]
        if not (self.beat and number.isdigit() and len(number) <= 18):
            return False
        n = int(number)
        if (what == "alive" and n <= self.beats) or \
                not hmac.compare_digest(payload, sign(self.beat, self.rid, what, n)):
            return False
        if what == "alive":
            self.beats = n
        return True

    def ending(self, code: int) -> str:
        """Which signal ended the verb, and when its process exited (its motion stopped)."""
        assert self.interrupted_at is not None
        ended = getattr(self.proc, "exited_at", None) or self.ended_at or time.monotonic()
        ms = (ended - self.interrupted_at) * 1e3
        sent = ", ".join(f"{sig.name} at {(t - self.interrupted_at) * 1e3:.0f} ms"
                         for sig, t in self.signals)
        before = [sig.name for sig, t in self.signals if t <= ended]
        by = _signal_name(-code) if code < 0 else before[-1] if before else "its own end"
        return f"{sent}; ended by {by}: its process exited {ms:.0f} ms after the interrupt"


class OwnFiles:
    """The agent's own files (its profile and includes, its Zenoh configuration and
    certificates), known by real path and by inode (a hard link to one is one too)."""

    def __init__(self, paths: Collection[str]) -> None:
        self.paths = {os.path.realpath(p) for p in paths}
        self.inodes = set()
        for path in self.paths:
            with contextlib.suppress(OSError):
                st = os.stat(path)
                self.inodes.add((st.st_dev, st.st_ino))

    def holds(self, value: str, workdir: str) -> bool:
        """Whether ``value``, read as a path from ``workdir``, is one of them."""
        path = os.path.realpath(os.path.join(workdir, value))
        if path in self.paths:
            return True
        try:
            st = os.stat(path)
        except (OSError, ValueError):
            return False
        return (st.st_dev, st.st_ino) in self.inodes


class Spares:
    """deltoctl processes started ahead, their imports done, each waiting for its command
    line on stdin: a verb starts without paying the interpreter's start-up."""

    def __init__(self, command: list[str], env: dict[str, str], cwd: str) -> None:
        self.command, self.env, self.cwd = command, env, cwd
        self.lock = threading.Lock()
        self.spare: subprocess.Popen[bytes] | None = None
        self.closed = False
        self._refill()

    def _start(self) -> subprocess.Popen[bytes]:
        from deltoctl.fleet.forks import restore_signals

        return subprocess.Popen(self.command, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, env=self.env, cwd=self.cwd,
                                start_new_session=True, preexec_fn=restore_signals)

    def _refill(self) -> None:
        with self.lock:
            if not self.closed and self.spare is None:
                self.spare = self._start()

    def take(self, argv: list[str]) -> subprocess.Popen[bytes]:
        with self.lock:
            proc, self.spare = self.spare, None
        if proc is None or proc.poll() is not None:
            proc = self._start()
        assert proc.stdin is not None
        proc.stdin.write(json.dumps(argv).encode() + b"\n")
        proc.stdin.close()
        proc.stdin = None  # written and closed: communicate() must not flush it
        return proc

    def refill(self) -> None:
        """Start the next spare, after a verb ended: not while it runs, competing with it."""
        threading.Thread(target=self._refill, daemon=True).start()

    def close(self) -> None:
        with self.lock:
            self.closed = True
            proc, self.spare = self.spare, None
        if proc is not None:
            proc.kill()
            proc.wait()


class Launcher:
    """Starts verb processes: forked from the zygote (see forks.py), or, should it be gone,
    from spare processes."""

    def __init__(self, zygote: list[str], spare: list[str], env: dict[str, str],
                 cwd: str) -> None:
        from deltoctl.fleet.forks import Zygote

        self.spare_command, self.env, self.cwd = spare, env, cwd
        self.spares: Spares | None = None
        self.zygote: Any = None
        try:
            self.zygote = Zygote(zygote, env, cwd)
        except OSError as exc:
            log(f"no zygote ({exc}): verbs start as new processes")

    def take(self, argv: list[str]) -> Any:
        if self.zygote is not None and self.zygote.alive():
            try:
                return self.zygote.take(argv)
            except OSError as exc:
                log(f"the zygote failed ({exc}): verbs start as new processes")
        if self.spares is None:
            self.spares = Spares(self.spare_command, self.env, self.cwd)
        return self.spares.take(argv)

    def refill(self) -> None:
        if self.spares is not None:
            self.spares.refill()

    def close(self) -> None:
        if self.zygote is not None:
            self.zygote.close()
        if self.spares is not None:
            self.spares.close()


def collect(proc: Any, timeout: float) -> tuple[bytes, bytes]:
    """All of a verb's stdout and stderr, once it exits."""
    box: dict[str, bytes] = {}

    def read(name: str, stream: Any) -> None:
        box[name] = b"".join(iter(lambda: os.read(stream.fileno(), 65536), b""))
        stream.close()

    threads = [threading.Thread(target=read, args=(n, getattr(proc, n)), daemon=True)
               for n in ("stdout", "stderr")]
    for t in threads:
        t.start()
    proc.wait(timeout)
    for t in threads:
        t.join(timeout)
    return box.get("stdout", b""), box.get("stderr", b"")


# what makes an agent serve motion: a rehearsal on its own computer, or mutual TLS
MOTION_HINT = ("to rehearse on this computer, start the agent with "
               "--allow-unauthenticated-motion and loopback endpoints only (--listen "
               "tcp/127.0.0.1:7447); over a network, give it a --zenoh-config whose every link "
               "is mutual TLS, e.g. zenoh-agent.json5 of `deltoctl help examples` (deltoctl "
               "help security)")


class Agent:
    """Serves ``robot`` (profile ``spec``) on a Zenoh session opened from ``config``.

    ``children``: the commands that start the zygote and a spare (see Launcher); ``links``:
    the global options that point a verb at the robot (``-t BUS=URL`` …); ``own_files``: the
    agent's profile, its includes, its configuration and certificates, which no remote
    command line names; ``check``: the CLI's further checks of a command line (verb, argv)."""

    def __init__(self, robot: str, spec: str, profile_name: str, links: list[str],
                 children: tuple[list[str], list[str]], config: Any, motion_allowed: bool,
                 why_not: str, deadline: float = DEADLINE, workdir: str = ".",
                 simulated: bool = False, profile_yaml: str = "",
                 own_files: Collection[str] = (),
                 check: Callable[[str, list[str]], None] | None = None) -> None:
        self.robot, self.spec, self.profile_name = robot, spec, profile_name
        self.own_files = OwnFiles(own_files)
        self.check = check
        self.profile_yaml = profile_yaml  # the resolved profile, for a caller that records
        self.links, self.config = links, config
        self.motion_allowed, self.why_not = motion_allowed, why_not
        self.deadline, self.workdir, self.simulated = deadline, workdir, simulated
        env = {k: v for k, v in os.environ.items() if not k.startswith("DELTOCTL_")}
        env["PYTHONUNBUFFERED"] = "1"
        env["COLUMNS"] = "100"
        self.launcher = Launcher(*children, env, workdir)
        self.running: dict[str, Running] = {}
        self.lock = threading.Lock()
        self.stopping = threading.Event()
        self.identity: dict[str, Any] = {}
        self.state = "starting"
        self.session: Any = None
        self._declared: list[Any] = []
        self._threads: list[threading.Thread] = []
        self._making_safe: list[threading.Thread] = []
        self._deadman: threading.Thread | None = None
        self._gone: set[str] = set()

    # -- life ----------------------------------------------------------------------------------

    def start(self) -> None:
        from deltoctl.fleet.config import open_session

        self.identity = self._identify()
        self.session = open_session(self.config, f"agent of robot {self.robot}",
                                    "check the endpoints (--listen, --connect, the config "
                                    "file): free to listen on, reachable to connect to")
        s, live = self.session, self.session.liveliness()
        self._declared = [
            s.declare_queryable(key(self.robot, "run"), self._on_run),
            s.declare_queryable(key(self.robot, "info"), self._on_info),
            s.declare_subscriber(key(self.robot, "alive", "*"), self._on_beat),
            s.declare_subscriber(key(self.robot, "cancel", "*"), self._on_cancel),
            live.declare_subscriber(key(self.robot, "caller", "*"), self._on_caller),
        ]
        self._state_pub = s.declare_publisher(key(self.robot, "state"))
        self._deadman = threading.Thread(target=self._watch, name="deadman", daemon=True)
        self._deadman.start()
        self._set_state()
        self._token = live.declare_token(key(self.robot, "agent", self.profile_name))

    def serve(self) -> None:
        """Until SIGINT or SIGTERM (or ``stop``)."""
        self.stopping.wait()

    def stop(self) -> None:
        self.stopping.set()

    def close(self) -> None:
        """Interrupt every verb (they stop their motion), wait for them — the deadman escalates
        to SIGTERM, SIGKILL and a safe stop of its own for a verb that will not stop —, then
        leave."""
        self.stopping.set()
        if self._deadman is not None:
            self._deadman.join(timeout=ESCALATE[1] + MAKE_SAFE + 5)
        for t in list(self._threads):
            t.join(timeout=5)  # the verbs' last output, their exit codes
        self.launcher.close()
        if self.session is not None:
            with contextlib.suppress(Exception):
                self._token.undeclare()
            self.session.close()

    # -- what the robot is -----------------------------------------------------------------

    def _identify(self) -> dict[str, Any]:
        """The robot's identity, from ``identify --json`` run once at start: per block, its
        family, the fields its device reports (model, firmware …) and how many parts (joints,
        servos) it reports."""
        proc = self.launcher.take([*self.links, "identify", "--json"])
        try:
            out, err = collect(proc, 60)
        except subprocess.TimeoutExpired:
            proc.send_signal(signal.SIGKILL)
            out, err = b"", b"identify did not finish within 60 s"
        self.launcher.refill()
        try:
            report = json.loads(out)
        except ValueError:
            last = (err.decode(errors="replace").strip().splitlines() or ["no output"])[-1]
            with contextlib.suppress(ValueError, KeyError, TypeError):
                last = str(json.loads(last)["error"]["message"])
            log(f"robot {self.robot}: identify failed (exit {proc.returncode}): {last}")
            return {"error": last, "exit_code": proc.returncode}
        return {b["name"]: {"family": b["family"], **{
            k: len(v) if isinstance(v, (dict, list)) else v
            for k, v in b["identity"].items() if k not in ("bus", "target")}}
            for b in report.get("blocks", [])}

    def info(self) -> dict[str, Any]:
        with self.lock:
            verbs = [{"verb": r.verb,
                      "seconds": round(time.monotonic() - r.started, 3)}
                     for r in self.running.values()]
        return {"robot": self.robot, "profile": self.profile_name, "state": self.state,
                "identity": self.identity, "simulated": self.simulated,
                "motion": "allowed" if self.motion_allowed else "refused",
                "motion_refused_because": None if self.motion_allowed else self.why_not,
                "deadline_s": self.deadline, "links": self.links, "running": verbs,
                "pid": os.getpid()}

    def _set_state(self) -> None:
        with self.lock:
            verbs = [r.verb for r in self.running.values()]
        state = ("moving" if any(v in MOTION for v in verbs) else "busy" if verbs else "idle")
        if state != self.state:
            self.state = state
            with contextlib.suppress(Exception):
                self._state_pub.put(state)

    # -- zenoh callbacks (zenoh's threads: never block) ------------------------------------

    def _on_info(self, query: Any) -> None:
        """The info document; with the ``profile_yaml`` parameter (``info?profile_yaml``),
        the resolved profile's YAML too (a remote ``record`` writes it in its file)."""
        with query:
            doc = self.info()
            if query.parameters.get(PROFILE_YAML) is not None:
                doc[PROFILE_YAML] = self.profile_yaml
            query.reply(key(self.robot, "info"), json.dumps(doc))

    def _on_beat(self, sample: Any) -> None:
        """A heartbeat counts only signed by the verb's own caller (another peer may see the
        verb's id, not its key)."""
        r = self.running.get(str(sample.key_expr).rsplit("/", 1)[-1])
        if r is not None and r.signed(sample.payload.to_bytes(), "alive"):
            r.last_beat = time.monotonic()

    def _on_cancel(self, sample: Any) -> None:
        r = self.running.get(str(sample.key_expr).rsplit("/", 1)[-1])
        if r is not None and r.signed(sample.payload.to_bytes(), "cancel"):
            r.interrupt("the caller cancelled it")

    def _on_caller(self, sample: Any) -> None:
        if sample.kind != zenoh_module().SampleKind.DELETE:
            return
        rid = str(sample.key_expr).rsplit("/", 1)[-1]
        r = self.running.get(rid)
        if r is None:
            self._gone.add(rid)  # the caller left before its verb started
        else:
            r.caller_gone = True

    def _on_run(self, query: Any) -> None:
        """Each request in a thread of its own; with 2 × MAX_VERBS threads already (verbs
        running, requests being read), refused at once: a flood of requests costs no thread."""
        if self.stopping.is_set():
            query.reply_err("the agent is stopping")
            query.drop()
            return
        t = threading.Thread(target=self._serve_query, args=(query,), daemon=True)
        with self.lock:
            self._threads = [th for th in self._threads if th.is_alive()]
            full = len(self._threads) >= 2 * MAX_VERBS
            if not full:
                self._threads.append(t)
        if full:
            _refuse(query, key(self.robot, "run"), Refused(
                f"busy: the agent is serving {2 * MAX_VERBS} requests", "try again later"), False)
        else:
            t.start()

    # -- one verb --------------------------------------------------------------------------

    def _serve_query(self, query: Any) -> None:
        """A request, checked (bounded, then judged by the CLI's own parse of its command
        line), runs its verb; a bad one gets one error reply, and one line in the log."""
        run_key = key(self.robot, "run")
        as_json = False
        try:
            request = read_request(query.payload.to_bytes() if query.payload else b"")
            rid, argv = request.get("id"), request.get("argv")
            if not (isinstance(rid, str) and 0 < len(rid) <= 32 and set(rid) <= _RID):
                raise InvalidInput("a run request needs an id of hex digits")
            as_json = isinstance(argv, list) and "--json" in argv
            verb = check_argv(argv, self.workdir, self.links)
            self._vet(verb, argv)
            running = self._launch(rid, verb, argv, beat_key(request))
        except Exception as exc:  # a bug too: one line and one reply, never a traceback
            if not isinstance(exc, DeltoctlError):
                exc = DeltoctlError(f"internal error: {type(exc).__name__}: {exc}")
            log(f"robot {self.robot}: request refused (exit {exc.exit_code}): "
                f"{exc.message[:200]}")
            _refuse(query, run_key, exc, as_json)
            return
        try:
            self._pump(query, run_key, running)
        finally:
            with self.lock:
                self.running.pop(running.rid, None)
                self._gone.discard(running.rid)
                self._threads = [t for t in self._threads if t.is_alive()
                                 and t is not threading.current_thread()]
            self._set_state()
            self.launcher.refill()
            query.drop()

    def _vet(self, verb: str, argv: list[str]) -> None:
        """Beyond check_argv: no remote command line names one of the agent's own files (a
        verb writing one would change the next verb's profile or the agent's security), and
        the CLI's own checks (a record's duration) hold."""
        for arg in argv:
            if any(self.own_files.holds(v, self.workdir) for v in _values(arg)):
                raise Refused(f"{arg!r} names one of the agent's own files: a remote verb "
                              "neither reads nor writes the agent's profile, its includes, its "
                              "Zenoh configuration or certificates",
                              "name another file in the agent's directory")
        if self.check is not None:
            self.check(verb, argv)

    def _launch(self, rid: str, verb: str, argv: list[str], beat: bytes = b"") -> Running:
        # by what this command line does (report actuates; report --yes moves); undeclared
        # commands too
        if verb in ACTUATING and not self.motion_allowed:
            what = ("a command deltoctl cannot classify (it counts as motion)"
                    if verb == UNRESOLVED else f"'{verb}'")
            raise Refused(f"{what} refused: {self.why_not}", MOTION_HINT)
        fits(self.links, argv)  # before any bookkeeping: the zygote takes it in one message
        with self.lock:
            if rid in self.running:
                raise InvalidInput(f"request {rid} is running already")
            if len(self.running) >= MAX_VERBS:
                raise Refused(f"busy: {len(self.running)} verbs are running on this robot, "
                              f"at most {MAX_VERBS} at once", "try again when one has ended")
            moving = [r for r in self.running.values() if r.verb in MOTION]
            if verb in MOTION and moving:
                raise Refused(f"busy: '{moving[0].verb}' (request {moving[0].rid}) is moving "
                              "the robot; one motion verb at a time")
            running = Running(rid, verb, self.launcher.take([*self.links, *argv]), beat)
            if rid in self._gone:
                running.caller_gone = True
            self.running[rid] = running
        self._set_state()
        shown = json.dumps(argv)
        if len(shown) > 2000:  # one readable line in the journal
            shown = f"{shown[:2000]}… ({len(shown)} characters)"
        log(f"robot {self.robot}: {rid}: {verb}: {shown}")
        return running

    def _pump(self, query: Any, run_key: str, r: Running) -> None:
        """The verb's output as replies while it runs; its exit code last."""
        assert r.proc.stdout is not None and r.proc.stderr is not None
        frames: list[bytes] | None = [] if r.verb == "stream" else None

        def err_pump() -> None:
            for chunk in iter(lambda: os.read(r.proc.stderr.fileno(), 65536), b""):
                query.reply(run_key, ERR + chunk)

        errs = threading.Thread(target=err_pump, daemon=True)
        errs.start()
        for chunk in iter(lambda: os.read(r.proc.stdout.fileno(), 65536), b""):
            query.reply(run_key, OUT + chunk)
            if frames is not None:
                self._publish_frames(r.rid, frames, chunk)
        code = r.proc.wait()
        errs.join()
        r.proc.stdout.close()
        r.proc.stderr.close()
        seconds = time.monotonic() - r.started
        if r.interrupted_at is not None:
            log(f"robot {self.robot}: {r.rid}: {r.verb} interrupted ({r.why}); "
                f"{r.ending(code)}")
        log(f"robot {self.robot}: {r.rid}: {r.verb}: exit {code} after {seconds:.3f} s")
        query.reply(run_key, EXIT + str(code).encode())

    def _publish_frames(self, rid: str, pending: list[bytes], chunk: bytes) -> None:
        """Each complete NDJSON line of a stream, published on ``frames/<id>``."""
        pending.append(chunk)
        if b"\n" not in chunk:
            return
        data = b"".join(pending)
        *lines, rest = data.split(b"\n")
        pending[:] = [rest] if rest else []
        target = key(self.robot, "frames", rid)
        for line in lines:
            if line.startswith(b"{"):
                self.session.put(target, line)

    # -- the deadman ---------------------------------------------------------------------

    def _watch(self) -> None:
        """The deadman's loop; should it ever fail, the agent stops (its verbs interrupted)
        rather than serve on without a deadman."""
        try:
            self._watching()
        except Exception as exc:
            log(f"robot {self.robot}: the deadman failed ({exc!r}): stopping the agent")
            self.stop()

    def _watching(self) -> None:
        """Until the agent stops and every verb it ran has exited (made safe if killed)."""
        while True:
            with self.lock:
                running = list(self.running.values())
                self._making_safe = [t for t in self._making_safe if t.is_alive()]
                busy = bool(self._making_safe)
            for r in running:
                self._look_at(r, time.monotonic())
            if self.stopping.is_set() and not busy and \
                    all(r.proc.poll() is not None for r in running):
                return
            time.sleep(WATCH_PERIOD)

    def _look_at(self, r: Running, now: float) -> None:
        """Interrupt a verb whose caller is gone, silent or the agent stopping; escalate."""
        if r.proc.poll() is not None:
            if r.ended_at is None:
                r.ended_at = now
            return
        deadline = self.deadline if r.verb in MOTION else LENIENT
        if self.stopping.is_set():
            r.interrupt("the agent is stopping")
        elif r.caller_gone:
            r.interrupt("its caller left")
        elif now - r.last_beat > deadline:
            r.interrupt(f"no heartbeat from its caller for {deadline:g} s")
        if r.interrupted_at is not None and r.escalate(now) == signal.SIGKILL and \
                r.verb in MOTION and not r.made_safe:
            r.made_safe = True
            t = threading.Thread(target=self._make_safe, args=(r,), daemon=True)
            with self.lock:
                self._making_safe.append(t)
            t.start()

    def _make_safe(self, r: Running) -> None:
        """A motion verb killed had no time for its safe stop (a gripper keeps its last
        duty): once it is gone, a ``connect`` of the robot's links leaves every block in its
        safe state, whatever that connect sent (a verb's own stop would spare a gripper it
        never drove)."""
        r.proc.wait()
        proc = self.launcher.take([SET_SAFE, *self.links, "connect", "--json"])
        try:
            collect(proc, MAKE_SAFE)
        except subprocess.TimeoutExpired:
            proc.send_signal(signal.SIGKILL)
        self.launcher.refill()
        log(f"robot {self.robot}: {r.rid}: {r.verb} killed; its blocks set safe by connect "
            f"(exit {proc.returncode})")


def _refuse(query: Any, run_key: str, exc: DeltoctlError, as_json: bool) -> None:
    """The only replies to a request that runs nothing: the error, then its exit code."""
    query.reply(run_key, ERR + _error_line(exc, as_json))
    query.reply(run_key, EXIT + str(exc.exit_code).encode())
    query.drop()


def _error_line(exc: DeltoctlError, as_json: bool) -> bytes:
    """A refusal written as the CLI writes its errors."""
    if as_json:
        error = {"message": exc.message, "hint": exc.hint, "exit_code": exc.exit_code}
        return (json.dumps({"error": error}) + "\n").encode()
    text = f"deltoctl: error: {exc.message}\n"
    if exc.hint:
        text += f"  hint: {exc.hint}\n"
    return text.encode()


def start_simulator(command: list[str], env: dict[str, str] | None = None,
                    timeout: float = 30.0) -> tuple[subprocess.Popen[bytes], dict[str, Any]]:
    """``deltoctl sim serve --json`` in a process of its own; returns it and what it serves."""
    from deltoctl.fleet.forks import die_with_parent, restore_signals

    def preexec() -> None:
        restore_signals()
        die_with_parent(signal.SIGKILL)  # a simulator keeps nothing, must not outlive its agent

    proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            stdin=subprocess.DEVNULL, env=env, start_new_session=True,
                            preexec_fn=preexec)
    assert proc.stdout is not None
    line = _readline(proc, timeout)
    try:
        return proc, json.loads(line)
    except ValueError:
        proc.kill()
        _, err = proc.communicate()
        raise Unreachable("the simulator did not start: "
                          + (err.decode(errors="replace").strip() or "no output")) from None


def _readline(proc: subprocess.Popen[bytes], timeout: float) -> bytes:
    box: list[bytes] = []
    stdout = proc.stdout
    assert stdout is not None  # started with stdout=PIPE
    reader = threading.Thread(target=lambda: box.append(stdout.readline()), daemon=True)
    reader.start()
    reader.join(timeout)
    return box[0] if box else b""


def stop_process(proc: subprocess.Popen[bytes]) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def signals_stop(stop: Callable[[], None]) -> None:
    """SIGINT and SIGTERM stop the agent (its verbs are interrupted first)."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop())
