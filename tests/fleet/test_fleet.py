"""Remote robots over Zenoh, end to end on loopback: `deltoctl agent --sim` processes serving
simulated robots, and `deltoctl --robot …` / `deltoctl fleet …` processes calling them."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time

import pytest

pytest.importorskip("zenoh")

from deltoctl.fleet import lab
from deltoctl.fleet.remote_call import RemoteCall
from tests.conftest import REPO, eventually

JOINT = "rj_dg_2_2"


def deltoctl(*args: str, timeout: float = 60, **kwargs) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if not k.startswith("DELTOCTL_")}
    return subprocess.run([*lab.deltoctl_command(), *args], capture_output=True, text=True,
                          timeout=timeout, env=env, stdin=subprocess.DEVNULL, **kwargs)


def popen(*args: str) -> subprocess.Popen:
    env = {k: v for k, v in os.environ.items() if not k.startswith("DELTOCTL_")}
    return subprocess.Popen([*lab.deltoctl_command(), *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env,
                            stdin=subprocess.DEVNULL)


class Bench:
    """One agent serving a simulated DG-5F-R, reached directly (the caller connects to the
    agent's loopback endpoint), and a Zenoh session of the test's own to look at it."""

    def __init__(self, tmp, robot: str, profile: str, *agent_args: str) -> None:
        port = lab.free_port()
        self.robot, self.workdir = robot, tmp
        self.agent = lab.AgentProcess(robot, profile, ["--listen", lab.endpoint(port),
                                                       *agent_args], cwd=str(tmp))
        self.config = lab.write_config(tmp / f"{robot}.json5", "client",
                                       connect=[lab.endpoint(port)])
        self.agent.wait_ready()
        from deltoctl.fleet import zenoh_module

        zenoh = zenoh_module()
        self.session = zenoh.open(zenoh.Config.from_file(str(self.config)))
        self.info = lab.info(self.session, robot)
        self.links = [a for a in self.info["links"]]

    def remote(self, *args: str, **kwargs) -> subprocess.CompletedProcess:
        return deltoctl("--zenoh-config", str(self.config), "--robot", self.robot, *args,
                        **kwargs)

    def remote_popen(self, *args: str) -> subprocess.Popen:
        return popen("--zenoh-config", str(self.config), "--robot", self.robot, *args)

    def local(self, *args: str) -> subprocess.CompletedProcess:
        """The same verb run on the robot's computer, against the same simulator."""
        return deltoctl(*self.links, *args)

    def state(self) -> str:
        return lab.info(self.session, self.robot)["state"]

    def probe(self, joint: str = JOINT) -> lab.JointProbe:
        return lab.JointProbe(self.info["profile"], lab.targets(self.links)[0], joint)

    def close(self) -> None:
        self.session.close()
        self.agent.stop()


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    # a deadline with room for a loaded test machine: a test asserts that motion stops, the
    # benchmark (bench/fleet.py) how fast, with the default 0.2 s
    b = Bench(tmp_path_factory.mktemp("bench"), "hand-1", "dg-5f-right",
              "--allow-unauthenticated-motion", "--deadline", "0.5")
    yield b
    b.close()


def _without(doc, keys):
    if isinstance(doc, dict):
        return {k: _without(v, keys) for k, v in doc.items() if k not in keys}
    if isinstance(doc, list):
        return [_without(v, keys) for v in doc]
    return doc


# -- (a) every verb remote, unchanged ---------------------------------------------------------

@pytest.mark.parametrize("verb", [["identify"], ["detect"], ["gpio", "get"]])
def test_a_remote_verb_prints_what_it_prints_on_the_robot(bench, verb):
    remote, local = bench.remote("--json", *verb), bench.local("--json", *verb)
    assert remote.returncode == local.returncode == 0, remote.stderr + local.stderr
    remote_doc, local_doc = json.loads(remote.stdout), json.loads(local.stdout)
    # the agent serves a simulator (--sim): its verbs say so; a run on the robot's computer
    # that names the same simulator by -t cannot know it
    assert all(b.pop("simulated") is True for b in remote_doc.get("blocks", []))
    assert all(b.pop("simulated") is False for b in local_doc.get("blocks", []))
    assert remote_doc == local_doc
    text = bench.remote(*verb)  # the tables for people too
    assert text.returncode == 0 and text.stdout == bench.local(*verb).stdout


def test_remote_connect_and_stream_have_the_local_shape(bench):
    remote, local = bench.remote("connect", "--json", "-n", "3"), bench.local("connect", "--json",
                                                                               "-n", "3")
    assert remote.returncode == local.returncode == 0, remote.stderr
    assert all(b["simulated"] for b in json.loads(remote.stdout)["blocks"])  # agent --sim
    assert _without(json.loads(remote.stdout), {"rtt_ms", "simulated"}) == \
        _without(json.loads(local.stdout), {"rtt_ms", "simulated"})
    remote = bench.remote("stream", "--duration", "0.3", "--rate", "100", "-i", "rj_dg_1_*")
    local = bench.local("stream", "--duration", "0.3", "--rate", "100", "-i", "rj_dg_1_*")
    assert remote.returncode == local.returncode == 0, remote.stderr
    frames = [json.loads(line) for line in remote.stdout.splitlines()]
    assert len(frames) >= 10
    assert {tuple(f["values"]) for f in frames} == \
        {tuple(json.loads(line)["values"]) for line in local.stdout.splitlines()}


def test_a_remote_stream_on_a_terminal_draws_the_live_table(bench):
    import re

    pexpect = pytest.importorskip("pexpect")
    env = {k: v for k, v in os.environ.items() if not k.startswith("DELTOCTL_")}
    command = [*lab.deltoctl_command(), "--zenoh-config", str(bench.config), "--robot",
               bench.robot, "stream", "--duration", "0.5"]
    child = pexpect.spawn(command[0], command[1:], dimensions=(24, 80), encoding="utf-8",
                          timeout=60, env={**env, "TERM": "xterm"})
    child.expect(pexpect.EOF)
    child.close()
    text = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", child.before).replace("\r", "")
    assert child.exitstatus == 0, text
    assert "samples from robot hand-1 · links up" in text and "Ctrl-C to stop" in text
    assert "right_fingertip_finger_5" in text and "input_1" in text
    assert '"values"' not in text  # the frames drawn, not printed


def test_a_remote_stream_publishes_its_frames(bench):
    frames, states = [], []
    with bench.session.declare_subscriber("deltoctl/hand-1/frames/*",
                                          lambda s: frames.append(s.payload.to_bytes())), \
            bench.session.declare_subscriber("deltoctl/hand-1/state",
                                             lambda s: states.append(s.payload.to_string())):
        result = bench.remote("stream", "--duration", "0.3", "--rate", "50", "-i", "*/position")
        assert result.returncode == 0
        lines = result.stdout.splitlines()
        assert eventually(lambda: len(frames) == len(lines) and states[-1:] == ["idle"])
    assert [json.loads(f) for f in frames] == [json.loads(line) for line in lines]
    assert "busy" in states


def test_a_remote_recording_is_written_on_the_callers_computer(bench, tmp_path):
    """--robot: here (tests/fleet/test_fleet_record.py says more); fleet run: on each robot, in its
    agent's directory (one file name, many robots)."""
    result = bench.remote("record", "remote.mcap", "--duration", "0.5", "--rate", "100",
                          cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "remote.mcap").stat().st_size > 0
    assert not (bench.workdir / "remote.mcap").exists()
    run = deltoctl("--zenoh-config", str(bench.config), "fleet", "run", "record", "fleet.mcap",
                   "--duration", "0.5", "--rate", "100", cwd=tmp_path)
    assert run.returncode == 0, run.stdout + run.stderr
    assert (bench.workdir / "fleet.mcap").stat().st_size > 0
    summary = bench.remote("info", "fleet.mcap", "--json")
    local = deltoctl("info", "fleet.mcap", "--json", cwd=bench.workdir)
    assert summary.returncode == 0 and summary.stdout == local.stdout


def test_remote_errors_keep_their_exit_code_and_name_the_robot(bench, tmp_path):
    remote = bench.remote("jog", "no_such_joint", "5deg", "--json")
    local = bench.local("jog", "no_such_joint", "5deg", "--json")
    assert remote.returncode == local.returncode == 2
    error = json.loads(remote.stderr)["error"]
    assert error["robot"] == "hand-1"
    assert error["message"] == json.loads(local.stderr)["error"]["message"]
    text = bench.remote("jog", "no_such_joint", "5deg")
    assert text.returncode == 2 and "deltoctl: error: robot hand-1: " in text.stderr
    # the agent runs its own profile and links, and names no file outside its directory
    for args in (["-p", "mh5", "identify"], ["--log-file", "x.ndjson", "identify"],
                 ["config", "snapshot", "-o", "/tmp/x.yaml"], ["sim", "serve"]):
        result = bench.remote(*args, cwd=tmp_path)  # --log-file: this side logs there
        assert result.returncode == 2, args
        assert "robot hand-1" in result.stderr and "Traceback" not in result.stderr
    # no agent of that name: unreachable
    missing = deltoctl("--zenoh-config", str(bench.config), "--robot", "nobody", "identify")
    assert missing.returncode == 4 and "robot nobody: no agent answers" in missing.stderr
    nowhere = lab.write_config(tmp_path / "nowhere.json5", "client",
                               connect=[lab.endpoint(lab.free_port())])
    result = deltoctl("--zenoh-config", str(nowhere), "--robot", "hand-1", "identify")
    assert result.returncode == 4 and "robot hand-1: cannot open the Zenoh session" in \
        result.stderr and " at /" not in result.stderr


# -- (b) motion across the network -----------------------------------------------------------

def test_remote_motion_needs_yes_and_the_robot_keeps_its_state(bench):
    refused = bench.remote("jog", JOINT, "5deg")
    assert refused.returncode == 5 and "robot hand-1" in refused.stderr
    assert "--yes" in refused.stderr
    moved = bench.remote("jog", JOINT, "5deg", "--yes", "--json")
    assert moved.returncode == 0, moved.stderr
    report = json.loads(moved.stdout)
    assert report["result"]["settled"]
    probe = bench.probe()
    try:  # the same simulator: the joint stays where the remote jog left it
        assert probe.position() == pytest.approx(report["blocks"][0]["joints"][JOINT]["position"],
                                                 abs=0.02)
    finally:
        probe.close()


def _start_slow_jog(bench, *extra: str) -> tuple[subprocess.Popen, lab.JointProbe]:
    probe = bench.probe()
    start = probe.position()
    target = "-20deg" if start > 0.3 else "20deg"
    client = bench.remote_popen("jog", JOINT, target, "--velocity", "4deg", "--yes", *extra)
    assert eventually(probe.moving, timeout=20), client.stderr
    return client, probe


@contextlib.contextmanager
def _jogging_agent(tmp_path, robot):
    """An agent of its own (the tests stop or kill it) whose robot is in a slow remote jog:
    yields the Bench, the caller's process and a probe of the joint."""
    b = Bench(tmp_path, robot, "dg-5f-right", "--allow-unauthenticated-motion", "--deadline", "0.5")
    try:
        client, probe = _start_slow_jog(b)
        try:
            yield b, client, probe
        finally:
            probe.close()
            if client.poll() is None:
                client.kill()
    finally:
        b.close()


def test_one_motion_verb_at_a_time_and_ctrl_c_stops_it(bench):
    client, probe = _start_slow_jog(bench)
    try:
        assert bench.state() == "moving"
        second = bench.remote("home", "--yes")
        assert second.returncode == 5
        assert "robot hand-1: busy: 'jog'" in second.stderr
        assert bench.remote("gpio", "get").returncode == 0  # reading goes on meanwhile
        client.send_signal(signal.SIGINT)  # Ctrl-C on the caller: the robot stops
        assert client.wait(15) == 130
        assert eventually(lambda: probe.still(0.1), timeout=5)
    finally:
        probe.close()
        if client.poll() is None:
            client.kill()
    assert eventually(lambda: bench.state() == "idle", timeout=5)


def test_a_partition_during_a_remote_jog_stops_the_joint(bench):
    client, probe = _start_slow_jog(bench)
    try:
        client.send_signal(signal.SIGSTOP)  # the caller freezes: no more heartbeats
        frozen = time.monotonic()
        assert eventually(lambda: probe.still(0.1), timeout=5)
        stopped_after = probe.last_change() - frozen
        still = probe.position()
        time.sleep(0.3)
        assert probe.position() == pytest.approx(still, abs=1e-6)
        assert eventually(lambda: "no heartbeat from its caller for 0.5 s" in bench.agent.text())
        print(f"joint stopped {stopped_after * 1e3:.0f} ms after the caller froze")
        client.send_signal(signal.SIGCONT)
        assert client.wait(15) == 130  # the verb was interrupted on the robot
    finally:
        probe.close()
        if client.poll() is None:
            client.kill()


def test_a_killed_caller_stops_the_joint(bench):
    client, probe = _start_slow_jog(bench)
    try:
        client.kill()  # its session, heartbeat and token vanish at once
        assert eventually(lambda: probe.still(0.1), timeout=5)
        assert eventually(lambda: bench.state() == "idle", timeout=5)
    finally:
        probe.close()
        client.wait()


def test_a_router_going_down_during_a_remote_jog_stops_the_joint(tmp_path):
    """A real partition: caller and agent reach each other only through a router, which
    goes away mid-move."""
    router = lab.Router()
    agent_config = lab.write_config(tmp_path / "agent.json5", "client",
                                    connect=[router.endpoint])
    agent = lab.AgentProcess("hand-p", "dg-5f-right", ["--allow-unauthenticated-motion", "--deadline", "0.5"],
                             cwd=str(tmp_path), config=agent_config).wait_ready()
    config = lab.write_config(tmp_path / "caller.json5", "client", connect=[router.endpoint])
    try:
        from deltoctl.fleet import zenoh_module

        zenoh = zenoh_module()
        with zenoh.open(zenoh.Config.from_file(str(config))) as session:
            links = lab.info(session, "hand-p")["links"]
        probe = lab.JointProbe("dg-5f-right", lab.targets(links)[0], JOINT)
        client = popen("--zenoh-config", str(config), "--robot", "hand-p", "jog", JOINT,
                       "20deg", "--velocity", "4deg", "--yes")
        try:
            assert eventually(probe.moving, timeout=20), client.stderr
            router.close()
            assert eventually(lambda: probe.still(0.1), timeout=5)
            assert eventually(lambda: "interrupted" in agent.text(), timeout=5)
            assert client.wait(30) == 4  # the caller lost the robot: unreachable
        finally:
            probe.close()
            if client.poll() is None:
                client.kill()
    finally:
        agent.stop()
        router.close()


def test_a_killed_agent_stops_the_joint(tmp_path):
    """SIGKILL leaves the agent no time: its verb processes stop on their own when it goes."""
    with _jogging_agent(tmp_path, "hand-k") as (b, client, probe):
        b.agent.proc.kill()
        assert eventually(lambda: probe.still(0.1), timeout=5)
        assert client.wait(30) == 4


def _children(pid):
    """The processes whose parent is ``pid`` (Linux /proc)."""
    found = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as f:
                    stat = f.read()
            except OSError:
                continue
            if int(stat.rpartition(")")[2].split()[1]) == pid:
                found.append(int(entry))
    return found


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_a_motion_verb_that_will_not_stop_is_killed_and_its_blocks_set_safe(tmp_path):
    """A verb frozen (SIGSTOP: it cannot take SIGINT or SIGTERM) is killed by the deadman's
    escalation; the agent then sets the robot's blocks safe itself (a gripper keeps its last
    duty otherwise)."""
    with _jogging_agent(tmp_path, "hand-f") as (b, client, probe):
        verbs = [c for z in _children(b.agent.proc.pid) for c in _children(z)]
        assert len(verbs) == 1, verbs  # the jog, forked by the agent's warm process
        os.kill(verbs[0], signal.SIGSTOP)
        client.send_signal(signal.SIGINT)  # the deadman's SIGINT, then SIGTERM, then KILL
        assert eventually(lambda: "set safe by connect (exit 0)" in b.agent.text(), timeout=30)
        assert eventually(lambda: probe.still(0.1), timeout=5)


def test_stopping_the_agent_stops_the_joint(tmp_path):
    with _jogging_agent(tmp_path, "hand-2") as (b, client, probe):
        b.agent.proc.terminate()
        assert eventually(lambda: probe.still(0.1), timeout=5)
        assert b.agent.proc.wait(15) == 0
        assert client.wait(15) in (130, 4)
        assert "the agent is stopping" in b.agent.text()


def test_an_agent_open_to_unauthenticated_peers_moves_nothing(tmp_path):
    b = Bench(tmp_path, "hand-3", "dg-5f-right")  # plain TCP, no --allow-unauthenticated-motion
    try:
        assert b.remote("identify").returncode == 0
        for args in (["jog", JOINT, "5deg", "--yes"], ["home", "--yes"],
                     ["gpio", "set", "output_2", "on"]):
            result = b.remote(*args)
            assert result.returncode == 5, args
            assert "robot hand-3" in result.stderr and "authenticated" in result.stderr
        assert "refused" in b.info["motion"]
        # a raw request, global options after the verb as the CLI takes them, is judged as
        # the CLI would parse it; `calibrate ft` is of the actuating group `calibrate`
        outside = str(tmp_path.parent / f"{tmp_path.name}-outside.yaml")  # beside its workdir
        for argv, code in ((["gpio", "--hardware", "DG5FRightHardware", "set", "output_2",
                             "on", "--yes"], 5), (["calibrate", "ft", "--yes"], 5),
                           (["config", "snapshot", f"--output={outside}"], 2),
                           (["config", "snapshot", f"-o{outside}"], 2),
                           (["stream", "--duration", "0.1", "--foxglove"], 2)):
            call = RemoteCall(b.session, "hand-3", argv, lambda _: None, lambda _: None)
            assert call.run() == code, argv
        assert not os.path.exists(outside)
        assert json.loads(b.local("gpio", "get", "--json").stdout)["result"]["gpio/output_2"] == 0.0
    finally:
        b.close()
    # and the flag is for a loopback bench only
    result = deltoctl("-p", "dg-5f-right", "--sim", "agent", "--listen", "tcp/0.0.0.0:0",
                      "--allow-unauthenticated-motion", "--deadline", "0.5")
    assert result.returncode == 2 and "loopback" in result.stderr


# -- (c) fleets: several agents of different families behind one router ---------------------

FLEET = {"hand-r": "dg-5f-right", "hand-l": "dg-5f-left", "hand-3f": "dg-3f-m",
         "hand-4f": "dg-4f", "hand-s15": "dg-5f-s15-left", "arm-1": "bioscara-arm",
         "arm-2": "bioscara-dg-3f-m", "humanoid": "mh5", "rrbot": "rrbot-gpio",
         "ft": "fts-2d"}


class Fleet:
    def __init__(self, tmp) -> None:
        self.router = lab.Router()
        agent_config = lab.write_config(tmp / "agent.json5", "client",
                                        connect=[self.router.endpoint])
        self.config = lab.write_config(tmp / "caller.json5", "client",
                                       connect=[self.router.endpoint])
        self.agents = [lab.AgentProcess(robot, profile, ["--allow-unauthenticated-motion", "--deadline", "0.5"],
                                        cwd=str(tmp), config=agent_config)
                       for robot, profile in FLEET.items()]
        for agent in self.agents:
            agent.wait_ready()

    def run(self, *args: str) -> subprocess.CompletedProcess:
        return deltoctl("--zenoh-config", str(self.config), *args)

    def close(self) -> None:
        for agent in self.agents:
            agent.stop()
        self.router.close()


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    f = Fleet(tmp_path_factory.mktemp("fleet"))
    yield f
    f.close()


def test_fleet_list_shows_every_robot_with_profile_identity_and_state(fleet):
    result = fleet.run("fleet", "list", "--json")
    assert result.returncode == 0, result.stderr
    robots = {r["robot"]: r for r in json.loads(result.stdout)["result"]}
    assert {name: r["profile"] for name, r in robots.items()} == FLEET
    assert all(r["state"] == "idle" and "error" not in r["identity"] for r in robots.values())
    assert robots["hand-r"]["identity"]["DG5FRightHardware"]["firmware"] == "3.0"
    assert robots["humanoid"]["identity"]  # every block of a two-family robot
    table = fleet.run("fleet", "list")
    assert table.returncode == 0 and all(name in table.stdout for name in FLEET)


def test_fleet_run_identify_on_ten_robots(fleet):
    result = fleet.run("fleet", "run", "identify", "--json")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)["result"]
    assert report["exit_code"] == 0
    rows = {r["robot"]: r for r in report["robots"]}
    assert set(rows) == set(FLEET)
    for name, row in rows.items():
        assert row["exit_code"] == 0 and row["output"]["profile"] == FLEET[name]
    # the same verb, one robot, remote: the fleet report embeds exactly what it prints
    one = fleet.run("--robot", "arm-1", "identify", "--json")
    assert json.loads(one.stdout) == rows["arm-1"]["output"]
    table = fleet.run("fleet", "run", "--robots", "hand-*", "identify")
    assert table.returncode == 0
    assert "hand-r" in table.stdout and "arm-1" not in table.stdout


def test_fleet_run_exits_with_the_worst_code(fleet):
    result = fleet.run("fleet", "run", "gpio", "get", "--json")
    report = json.loads(result.stdout)["result"]
    codes = {r["robot"]: r["exit_code"] for r in report["robots"]}
    assert codes["hand-r"] == 0 and codes["rrbot"] == 0
    assert codes["arm-1"] == 2  # a robot with no GPIO: invalid input there
    assert result.returncode == report["exit_code"] == 2
    row = next(r for r in report["robots"] if r["robot"] == "arm-1")
    assert row["error"] == "bioscara-arm has no GPIO"
    refused = fleet.run("fleet", "run", "--robots", "hand-[rl]", "jog", JOINT, "1deg")
    assert refused.returncode == 5  # motion without --yes: each robot refuses
    assert fleet.run("fleet", "run", "--robots", "nothing-*", "identify").returncode == 4


def test_fleet_run_a_bring_up_script(fleet, tmp_path):
    script = tmp_path / "bringup.sh"
    script.write_text(
        "#!/usr/bin/env bash\nset -euo pipefail\n"
        '"$deltoctl" sim serve dg-5f-right --json > "$out/sim.json" &\n'
        "deltoctl connect -n 3\n"
        '"$deltoctl" identify  # what is there\n'
        "deltoctl home --yes\n"
        "deltoctl gpio get && echo done\n"
        "deltoctl stream --duration 0.2 --interfaces '*_dg_2_*/position' | tail -n 1\n"
        'deltoctl record "$out/x.mcap" --duration 1\n')
    result = fleet.run("fleet", "run", "--robots", "hand-[rl]", str(script), "--json")
    assert result.returncode == 0, result.stdout + result.stderr
    report = json.loads(result.stdout)["result"]
    assert [r["robot"] for r in report["robots"]] == ["hand-l", "hand-r"]
    assert all(r["lines_run"] == r["lines"] == 5 for r in report["robots"])
    # sim serve, set -e, the shell variable, and what follows && (never dropped silently)
    assert len(report["skipped"]) == 4 and "'&&'" in report["skipped"][2]
    assert "skipped" in result.stderr


def test_fleet_run_the_shipped_bring_up_script(fleet):
    script = REPO / "examples" / "bringup.sh"
    result = fleet.run("fleet", "run", "--robots", "hand-r", str(script), "--json")
    assert result.returncode == 0, result.stdout + result.stderr
    row = json.loads(result.stdout)["result"]["robots"][0]
    assert row["lines_run"] == row["lines"] >= 9  # home, two jogs, gpio set …


# -- (e) mutual TLS ---------------------------------------------------------------------------

def test_over_mutual_tls_only_a_caller_with_a_certificate_reaches_the_robot(tmp_path):
    pki = lab.make_pki(tmp_path / "pki", ("agent", "caller"))
    intruder = lab.make_pki(tmp_path / "intruder", ("caller",))
    port = lab.free_port()
    tls_endpoint = lab.endpoint(port, "tls")
    agent_config = lab.write_config(tmp_path / "agent.json5", "peer", listen=[tls_endpoint],
                                    tls=lab.tls_settings(pki, "agent"))
    agent = lab.AgentProcess("secure", "dg-5f-right", [], cwd=str(tmp_path),
                             config=agent_config).wait_ready()
    try:
        assert "motion allowed" in agent.text()  # every link is mutual TLS
        callers = {
            "trusted": lab.tls_settings(pki, "caller"),
            "no certificate": lab.tls_settings(pki, None, mtls=False),
            "another CA's certificate": {**lab.tls_settings(intruder, "caller"),
                                         "root_ca_certificate": str(pki["ca"])},
        }
        results = {}
        for name, tls in callers.items():
            config = lab.write_config(tmp_path / f"{name}.json5", "client",
                                      connect=[tls_endpoint], tls=tls)
            results[name] = deltoctl("--zenoh-config", str(config), "--robot", "secure",
                                     "jog", JOINT, "2deg", "--yes", "--json")
        plain = lab.write_config(tmp_path / "plain.json5", "client",
                                 connect=[lab.endpoint(port)])
        results["plain TCP"] = deltoctl("--zenoh-config", str(plain), "--robot", "secure",
                                        "jog", JOINT, "2deg", "--yes", "--json")
        assert results.pop("trusted").returncode == 0
        for name, result in results.items():  # they cannot even reach it
            assert result.returncode == 4, name
            error = json.loads(result.stderr)["error"]
            assert error["robot"] == "secure" and "cannot open the Zenoh session" in \
                error["message"], name
        moves = [line for line in agent.log if ": jog: " in line and "exit" not in line]
        assert len(moves) == 1  # only the trusted caller's jog reached the agent
        log = agent.text() + json.dumps(agent_config.read_text())
        assert "PRIVATE KEY" not in agent.text()
        assert pki["agent_key"].read_text() not in log
    finally:
        agent.stop()


def test_without_zenoh_one_message_says_what_to_install(cli, monkeypatch):
    monkeypatch.setitem(sys.modules, "zenoh", None)  # `import zenoh` fails
    for args in (["--robot", "hand-1", "identify"], ["fleet", "list"],
                 ["-p", "dg-5f-right", "agent", "--sim"]):
        result = cli(*args)
        assert result.exit_code == 2, args
        assert "pip install 'deltoctl[fleet]'" in result.stderr
        assert "Traceback" not in result.stderr


def test_the_cli_does_not_import_zenoh_for_a_local_verb():
    code = ("import sys; sys.argv = ['deltoctl', 'profile', 'list', '--json']\n"
            "from deltoctl.cli.main import main\n"
            "try:\n    main()\nexcept SystemExit:\n    pass\n"
            "assert 'zenoh' not in sys.modules and 'deltoctl.fleet' not in sys.modules\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


def test_ctrl_c_on_a_fleet_run_interrupts_every_robot(fleet):
    run = popen("--zenoh-config", str(fleet.config), "fleet", "run", "--robots", "hand-*",
                "stream", "--json")
    from deltoctl.fleet import zenoh_module

    zenoh = zenoh_module()
    with zenoh.open(zenoh.Config.from_file(str(fleet.config))) as session:
        hands = [r for r in FLEET if r.startswith("hand-")]
        assert eventually(lambda: all(lab.info(session, r)["state"] == "busy" for r in hands),
                          timeout=20)
        run.send_signal(signal.SIGINT)
        out, _ = run.communicate(timeout=30)
        rows = json.loads(out)["result"]["robots"]
        codes = {r["exit_code"] for r in rows}
        # each stream ends as on Ctrl-C at its terminal: 0 once streaming, 130 before
        assert codes <= {0, 130}, [(r["robot"], r["exit_code"], r["error"]) for r in rows]
        assert run.returncode == (130 if 130 in codes else 0)
        assert eventually(lambda: all(lab.info(session, r)["state"] == "idle" for r in hands))


def test_without_its_zygote_the_agent_starts_verbs_as_new_processes(tmp_path):
    from deltoctl.cli.agent_cmd import SPARE
    from deltoctl.fleet.agent import Launcher, collect

    env = {k: v for k, v in os.environ.items() if not k.startswith("DELTOCTL_")}
    launcher = Launcher([sys.executable, "-c", "pass"], [sys.executable, "-c", SPARE, "rrbot-gpio"],
                        env, str(tmp_path))
    try:
        for _ in range(2):  # the spare, then the one started after it
            proc = launcher.take(["-p", "rrbot-gpio", "--json", "gpio", "get"])
            out, err = collect(proc, 60)
            assert proc.returncode == 0, err
            assert "flange_vacuum/vacuum" in json.loads(out)["result"]
            launcher.refill()
        assert launcher.spares is not None  # the spare processes did it
    finally:
        launcher.close()
