"""The fleet agent's deadman, processes and files, end to end on loopback: `deltoctl agent
--sim` processes (one started as a shell script starts it), callers that freeze or leave, a
peer that forges heartbeats, remote verbs that aim at the agent's own files."""

from __future__ import annotations

import contextlib
import ipaddress
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

pytest.importorskip("zenoh")

from deltoctl.errors import InvalidInput
from deltoctl.fleet import key, lab, zenoh_module
from deltoctl.fleet.remote_call import RemoteCall
from tests.conftest import eventually
from tests.fleet.test_fleet import JOINT, _children, deltoctl, popen

linux_only = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
SLOW = ("--velocity", "2deg")  # a 20° jog takes 10 s: still moving when the test looks


class Robot:
    """An agent of a simulated DG-5F-R (``lab.AgentProcess``), its caller config, a Zenoh
    session of the test's own, and the links to its simulator."""

    def __init__(self, tmp: Path, name: str, profile: str = "dg-5f-right",
                 args: tuple[str, ...] = ("--allow-unauthenticated-motion", "--deadline", "0.5"),
                 **agent: object) -> None:
        port = lab.free_port()
        self.name, self.workdir = name, tmp
        self.agent_config = lab.write_config(tmp / "agent.json5", "peer",
                                             listen=[lab.endpoint(port)])
        self.agent = lab.AgentProcess(name, profile, list(args), cwd=str(tmp),
                                      config=self.agent_config, **agent)  # type: ignore[arg-type]
        self.config = lab.write_config(tmp.parent / f"{tmp.name}-caller.json5", "client",
                                       connect=[lab.endpoint(port)])
        self.agent.wait_ready()
        zenoh = zenoh_module()
        self.session = zenoh.open(zenoh.Config.from_file(str(self.config)))
        self.links = lab.info(self.session, name)["links"]

    def remote(self, *args: str, **kwargs) -> subprocess.CompletedProcess:
        return deltoctl("--zenoh-config", str(self.config), "--robot", self.name, *args,
                        **kwargs)

    def call(self, *argv: str, timeout: float = 30) -> tuple[int, str]:
        """A raw request from this test's session: the exit code and the stderr (cancelled
        after ``timeout``: 130)."""
        err: list[bytes] = []
        call = RemoteCall(self.session, self.name, list(argv), lambda _: None, err.append)
        timer = threading.Timer(timeout, call.cancel)
        timer.start()
        try:
            code = call.run()
        finally:
            timer.cancel()
        return code, b"".join(err).decode(errors="replace")

    def jog(self, degrees: int = 20) -> tuple[subprocess.Popen, lab.JointProbe, float]:
        """A slow remote jog, moving: its caller, a probe of the joint, the target (rad)."""
        probe = lab.JointProbe("dg-5f-right", lab.targets(self.links)[0], JOINT)
        start = probe.position()
        sign = -1 if start > 0.8 else 1
        target = start + sign * degrees * 3.141592653589793 / 180
        caller = popen("--zenoh-config", str(self.config), "--robot", self.name, "jog", JOINT,
                       f"{sign * degrees}deg", *SLOW, "--yes")
        assert eventually(probe.moving, timeout=20), caller.stderr
        return caller, probe, target

    def verbs(self) -> list[int]:
        """The verb processes the agent's zygote forked."""
        return [c for z in _children(self.agent.pid) for c in _children(z)]

    def close(self) -> None:
        self.session.close()
        self.agent.stop(40)


@contextlib.contextmanager
def robot(tmp: Path, name: str, **kwargs):
    r = Robot(tmp, name, **kwargs)
    try:
        yield r
    finally:
        r.close()


@contextlib.contextmanager
def jogging(r: Robot, degrees: int = 20):
    caller, probe, target = r.jog(degrees)
    try:
        yield caller, probe, target
    finally:
        probe.close()
        if caller.poll() is None:
            caller.send_signal(signal.SIGCONT)
            caller.kill()
        caller.wait()


def _ignored(pid: int) -> set[str]:
    """The signals among SIGINT, SIGTERM, SIGHUP that process ``pid`` ignores."""
    with open(f"/proc/{pid}/status") as f:
        mask = int(next(ln for ln in f if ln.startswith("SigIgn:")).split()[1], 16)
    return {s.name for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
            if mask & (1 << (s - 1))}


def _descendants(pid: int) -> list[int]:
    found = []
    for child in _children(pid):
        found += [child, *_descendants(child)]
    return found


# -- the deadman's signals reach every verb ---------------------------------------------------

@linux_only
def test_an_agent_started_in_the_background_by_a_script_stops_a_frozen_callers_jog(tmp_path):
    """`sh -c 'deltoctl agent … &'`: the agent inherits SIGINT ignored; its zygote, simulator
    and verbs must not, or the deadman's SIGINT is lost and only SIGTERM, seconds later, stops
    the joint."""
    with robot(tmp_path, "hand-bg", background=True) as r:
        assert "SIGINT" in _ignored(r.agent.proc.pid)  # the script's, and its children's
        with jogging(r) as (caller, probe, target):
            started = _descendants(r.agent.pid)
            assert len(started) >= 3  # the simulator, the zygote and the jog it forked
            assert {pid: _ignored(pid) for pid in started} == {pid: set() for pid in started}
            caller.send_signal(signal.SIGSTOP)  # the caller freezes: no more heartbeats
            assert eventually(lambda: probe.still(0.1), timeout=5)
            assert eventually(lambda: "ended by" in r.agent.text(), timeout=10)
            line = next(ln for ln in r.agent.log if "ended by" in ln)
            assert "no heartbeat from its caller" in line and "ended by SIGINT" in line, line
            assert "SIGTERM" not in line  # no escalation was needed
            assert abs(probe.position() - target) > 0.05  # stopped short of its target
            caller.send_signal(signal.SIGCONT)
            assert caller.wait(15) == 130
            assert eventually(lambda: ": jog: exit 130 " in r.agent.text())


@linux_only
def test_while_the_agent_stops_a_verb_that_will_not_stop_is_killed_and_made_safe(tmp_path):
    """Stopping the agent interrupts its verbs; the escalation goes on meanwhile (SIGTERM,
    SIGKILL, the blocks set safe) before the agent leaves, and its log says which signal
    ended the verb and when its process exited."""
    with robot(tmp_path, "hand-st") as r, jogging(r) as (_, probe, _target):
        [verb] = r.verbs()
        os.kill(verb, signal.SIGSTOP)  # a verb that cannot take SIGINT or SIGTERM
        r.agent.stop(60)
        assert r.agent.proc.returncode == 0, r.agent.text()
        text = r.agent.text()
        assert "interrupted (the agent is stopping); SIGINT at 0 ms, SIGTERM at " in text
        assert "ended by SIGKILL: its process exited " in text
        assert "set safe by connect (exit 0)" in text
        assert not os.path.exists(f"/proc/{verb}")
        assert eventually(lambda: probe.still(0.1), timeout=5)


# -- a request that fails leaves nothing behind ----------------------------------------------

def test_the_zygote_refuses_a_command_line_too_long_and_runs_the_next_one(tmp_path):
    from deltoctl.cli.agent_cmd import ZYGOTE
    from deltoctl.fleet.agent import collect
    from deltoctl.fleet.forks import MESSAGE, Zygote

    env = {k: v for k, v in os.environ.items() if not k.startswith("DELTOCTL_")}
    zygote = Zygote([sys.executable, "-c", ZYGOTE, "rrbot-gpio"], env, str(tmp_path))
    try:
        for size in (MESSAGE + 10, 600_000):  # one the zygote would cut, one too big to send
            with pytest.raises(InvalidInput, match="KiB"):
                zygote.take(["-p", "rrbot-gpio", "gpio", "get", "x" * size])
        assert not zygote.pending
        proc = zygote.take(["-p", "rrbot-gpio", "--json", "gpio", "get"])
        out, err = collect(proc, 60)
        assert proc.returncode == 0, err
        assert "flange_vacuum/vacuum" in json.loads(out)["result"]  # its own output, not another's
    finally:
        zygote.close()


@pytest.fixture(scope="module")
def hand(tmp_path_factory):
    """An agent whose profile is a file in its directory, robot.yaml."""
    tmp = tmp_path_factory.mktemp("hand")
    exported = deltoctl("profile", "export", "dg-5f-right", "-f", "yaml", "-o",
                        str(tmp / "robot.yaml"))
    assert exported.returncode == 0, exported.stderr
    r = Robot(tmp, "hand-d", profile="robot.yaml")
    yield r
    r.close()


def test_after_an_oversized_request_a_callerless_jog_still_stops(hand):
    code, err = hand.call("gpio", "get", *(["x" * 1000] * 600))  # ~600 KB of reading verb
    assert code == 2 and "Traceback" not in err, err
    with jogging(hand) as (caller, probe, _):
        caller.kill()  # its session, heartbeat and token vanish at once
        assert eventually(lambda: probe.still(0.1), timeout=5)
    assert eventually(lambda: "interrupted (its caller left)" in hand.agent.text())
    assert hand.remote("gpio", "get").returncode == 0  # and the next verb is its own


# -- heartbeats count only from the verb's caller --------------------------------------------

@contextlib.contextmanager
def watched_jog(r: Robot):
    """A remote jog, and what another peer sees of it: its heartbeats' key and the last one."""
    seen: list[tuple[str, bytes]] = []
    with r.session.declare_subscriber(
            key(r.name, "alive", "*"),
            lambda s: seen.append((str(s.key_expr), s.payload.to_bytes()))), \
            jogging(r) as (caller, probe, target):
        assert eventually(lambda: len(seen) >= 3)
        yield caller, probe, target, seen[-1]


def test_a_peer_forging_heartbeats_does_not_keep_a_frozen_callers_jog_alive(hand):
    zenoh = zenoh_module()
    with watched_jog(hand) as (caller, probe, target, (beat_key, real)):
        rid = beat_key.rsplit("/", 1)[-1]
        stop = threading.Event()

        def forge() -> None:  # empty, replayed and made-up heartbeats, faster than the caller's
            with zenoh.open(zenoh.Config.from_file(str(hand.config))) as spoofer:
                n = 10**6
                while not stop.wait(0.02):
                    for payload in (b"", real, f"{n}:{'0' * 64}".encode()):
                        spoofer.put(beat_key, payload)
                    n += 1

        spoofing = threading.Thread(target=forge, daemon=True)
        spoofing.start()
        try:
            caller.send_signal(signal.SIGSTOP)
            assert eventually(lambda: probe.still(0.1), timeout=5)
            assert abs(probe.position() - target) > 0.05
        finally:
            stop.set()
            spoofing.join()
        assert eventually(lambda: f"{rid}: jog interrupted (no heartbeat from its caller"
                          in hand.agent.text())


def test_a_cancel_from_another_peer_is_ignored(hand):
    with watched_jog(hand) as (caller, probe, _, (beat_key, _beat)):
        hand.session.put(beat_key.replace("/alive/", "/cancel/"), b"")
        time.sleep(0.3)
        assert probe.moving(0.2)  # the jog goes on
        caller.send_signal(signal.SIGINT)  # its own caller's cancel stops it
        assert caller.wait(15) == 130
        assert eventually(lambda: probe.still(0.1), timeout=5)


# -- the agent's own files -------------------------------------------------------------------

def test_a_remote_verb_cannot_overwrite_the_agents_profile_or_configuration(hand):
    profile = hand.workdir / "robot.yaml"
    before = profile.read_bytes()
    (hand.workdir / "link.yaml").unlink(missing_ok=True)
    (hand.workdir / "link.yaml").symlink_to("robot.yaml")
    (hand.workdir / "hard.yaml").unlink(missing_ok=True)
    os.link(profile, hand.workdir / "hard.yaml")
    for argv in (["profile", "export", "dg-5f-left", "-f", "yaml", "-o", "robot.yaml"],
                 ["profile", "export", "dg-5f-left", "-f", "yaml", "--output=./robot.yaml"],
                 ["profile", "export", "dg-5f-left", "-f", "yaml", "-olink.yaml"],
                 ["profile", "export", "dg-5f-left", "-f", "yaml", "-o", "hard.yaml"],
                 ["config", "snapshot", "-o", "robot.yaml"],
                 ["config", "snapshot", "-o", "agent.json5"]):
        code, err = hand.call(*argv)
        assert code == 5 and "the agent's own files" in err, (argv, err)
    assert profile.read_bytes() == before
    assert json.loads(hand.agent_config.read_text())["listen"]  # the config, unchanged
    # any other file in its directory is the verb's to write
    done = hand.remote("profile", "export", "dg-5f-left", "-f", "yaml", "-o", "left.yaml")
    assert done.returncode == 0, done.stderr
    assert "dg-5f-left" in (hand.workdir / "left.yaml").read_text()
    assert hand.remote("identify").returncode == 0  # its next verb loads its own profile


def test_an_agent_without_workdir_runs_remote_verbs_in_a_directory_of_its_own(tmp_path):
    state = tmp_path / "state"
    env = {k: v for k, v in os.environ.items() if not k.startswith("DELTOCTL_")}
    env["XDG_STATE_HOME"] = str(state)
    port = lab.free_port()
    agent = lab.AgentProcess("hand-w", "dg-5f-right", ["--listen", lab.endpoint(port)],
                             env=env).wait_ready()
    try:
        config = lab.write_config(tmp_path / "caller.json5", "client",
                                  connect=[lab.endpoint(port)])
        result = deltoctl("--zenoh-config", str(config), "--robot", "hand-w", "config",
                          "snapshot", "-o", "snap.yaml")
        assert result.returncode == 0, result.stderr
        own = state / "deltoctl" / "agent" / "hand-w"
        assert (own / "snap.yaml").is_file()
        assert (own.stat().st_mode & 0o777) == 0o700
    finally:
        agent.stop()


# -- records on the robot's computer ---------------------------------------------------------

def test_a_record_written_on_the_robots_computer_needs_a_bounded_duration(hand, tmp_path):
    for argv in (["record", "long.mcap"], ["record", "long.mcap", "--duration", "7200"],
                 ["--json", "record", "long.mcap", "--rate", "100"]):
        code, err = hand.call(*argv)
        assert code == 2 and "--duration" in err and "Traceback" not in err, (argv, err)
    run = deltoctl("--zenoh-config", str(hand.config), "fleet", "run", "--robots", hand.name,
                   "record", "long.mcap", "--rate", "100", "--json")
    assert run.returncode == 2
    assert "--duration" in json.loads(run.stdout)["result"]["robots"][0]["error"]
    assert not (hand.workdir / "long.mcap").exists()
    code, err = hand.call("record", "short.mcap", "--duration", "0.3", "--rate", "50")
    assert code == 0, err
    assert (hand.workdir / "short.mcap").stat().st_size > 0
    # a record written on the caller's computer streams; Ctrl-C or --duration ends it
    here = hand.remote("record", "here.mcap", "--duration", "0.3", cwd=tmp_path)
    assert here.returncode == 0 and (tmp_path / "here.mcap").is_file()


# -- a configuration file without listen endpoints --------------------------------------------

def _listening(pid: int) -> list[ipaddress.IPv4Address | ipaddress.IPv6Address]:
    """The addresses process ``pid`` listens on over TCP (Linux /proc)."""
    sockets = set()
    for fd in os.listdir(f"/proc/{pid}/fd"):
        with contextlib.suppress(OSError):
            target = os.readlink(f"/proc/{pid}/fd/{fd}")
            if target.startswith("socket:["):
                sockets.add(target[8:-1])
    found = []
    for table in ("tcp", "tcp6"):
        with open(f"/proc/{pid}/net/{table}") as f:
            for row in list(f)[1:]:
                fields = row.split()
                if fields[3] == "0A" and fields[9] in sockets:  # LISTEN
                    raw = bytes.fromhex(fields[1].split(":")[0])
                    raw = b"".join(raw[i:i + 4][::-1] for i in range(0, len(raw), 4))
                    found.append(ipaddress.ip_address(raw))
    return found


@linux_only
def test_an_agent_config_file_without_listen_endpoints_listens_on_loopback_only(tmp_path):
    with contextlib.suppress(OSError), socket.create_connection(
            ("127.0.0.1", 7447), timeout=0.5):
        pytest.skip("something listens on 127.0.0.1:7447 already")
    config = tmp_path / "agent.json5"
    config.write_text(json.dumps({"mode": "peer",
                                  "scouting": {"multicast": {"enabled": False}}}))
    agent = lab.AgentProcess("hand-l", "dg-5f-right", [], cwd=str(tmp_path),
                             config=config).wait_ready()
    try:
        assert "listening on tcp/127.0.0.1:7447" in agent.text()
        addresses = _listening(agent.pid)
        assert addresses and all(a.is_loopback or (a.version == 6 and a.ipv4_mapped
                                                   and a.ipv4_mapped.is_loopback)
                                 for a in addresses), addresses
        caller = lab.write_config(tmp_path / "caller.json5", "client",
                                  connect=["tcp/127.0.0.1:7447"])
        assert deltoctl("--zenoh-config", str(caller), "--robot", "hand-l",
                        "identify").returncode == 0
    finally:
        agent.stop()
