"""The live view in Foxglove: `stream --foxglove` and `record --foxglove` serve a robot's topics
over the Foxglove WebSocket protocol; a client (websockets) subscribes and decodes the CDR
messages. The robot: the cell of examples/bringup-cell.sh, a Bioscara arm on I2C carrying a
DG-3F-M gripper on TCP, both simulated."""

from __future__ import annotations

import asyncio
import json
import math
import signal
import socket
import struct
import subprocess
import sys
import threading
from collections.abc import Callable

import pytest

websockets = pytest.importorskip("websockets")
pytest.importorskip("foxglove")
from mcap_ros2._dynamic import generate_dynamic  # noqa: E402

PROFILE = "bioscara-dg-3f-m"
# foxglove-sdk 0.30 speaks the WebSocket protocol as "foxglove.sdk.v1"; earlier servers
# (ros-foxglove-bridge) as "foxglove.websocket.v1": a client offers both, as Foxglove does
SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
WAIT = 120.0  # s: generous, the machine may be busy; a test never fails on timing


def _start(*args: str, robot: tuple[str, ...] = ("-p", PROFILE, "--sim"),
           ) -> tuple[subprocess.Popen, str, list[str], list[str]]:
    """deltoctl in a process of its own, with its Foxglove URL (read from stderr); threads
    keep draining stdout and stderr (a full pipe would stall the loop). Returns the process,
    the URL and the lists of stdout's and stderr's lines, as they come."""
    proc = subprocess.Popen([sys.executable, "-m", "deltoctl", *robot, *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    lines: list[str] = []
    out: list[str] = []
    found = threading.Event()
    url: list[str] = []

    def drain() -> None:
        for line in proc.stderr:  # type: ignore[union-attr]
            lines.append(line)
            if "ws://" in line and not url:
                url.append(line[line.index("ws://"):].split()[0])
                found.set()
        found.set()

    readers = [threading.Thread(target=drain, daemon=True),
               threading.Thread(target=lambda: out.extend(proc.stdout), daemon=True)]
    for reader in readers:
        reader.start()
    proc.readers = readers  # type: ignore[attr-defined]
    found.wait(WAIT)
    if not url:
        proc.kill()
        pytest.fail("no Foxglove URL on stderr: " + "".join(lines))
    return proc, url[0], out, lines


async def _watch(url: str, topics: list[str], done: Callable[[dict, dict], bool],
                 subscribed: Callable[[], None] | None = None) -> tuple[dict, dict]:
    """Subscribe to the topics once advertised, then gather their messages as (timestamp,
    payload) until ``done(channels, messages)``; ``subscribed`` is called once subscribed.
    Returns the advertised channels and the messages."""
    async with websockets.connect(url, subprotocols=SUBPROTOCOLS, max_size=None) as ws:
        assert ws.subprotocol in SUBPROTOCOLS
        channels: dict[str, dict] = {}
        while not all(t in channels for t in topics):
            msg = await ws.recv()
            if isinstance(msg, str):
                op = json.loads(msg)
                if op["op"] == "advertise":
                    channels.update({c["topic"]: c for c in op["channels"]})
        subs = {n + 1: topic for n, topic in enumerate(topics)}
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": n, "channelId": channels[t]["id"]} for n, t in subs.items()]}))
        if subscribed is not None:
            subscribed()
        got: dict[str, list[tuple[int, bytes]]] = {t: [] for t in topics}
        while not done(channels, got):
            msg = await ws.recv()
            if isinstance(msg, bytes) and msg[0] == 1:  # messageData
                sub, stamp = struct.unpack_from("<IQ", msg, 1)
                got[subs[sub]].append((stamp, msg[13:]))
        return channels, got


def watch(url: str, topics: list[str], err: list[str], count: int = 5,
          done: Callable[[dict, dict], bool] | None = None,
          subscribed: Callable[[], None] | None = None) -> tuple[dict, dict]:
    """``count`` messages of each topic (or until ``done``)."""
    def enough(channels: dict, got: dict) -> bool:
        return all(len(m) >= count for m in got.values())

    try:
        return asyncio.run(asyncio.wait_for(_watch(url, topics, done or enough, subscribed),
                                            WAIT))
    except asyncio.TimeoutError:
        pytest.fail(f"what was awaited of {topics} did not come in {WAIT} s; deltoctl said: "
                    f"{''.join(err)}")


def decode(channel: dict, payload: bytes):
    assert channel["encoding"] == "cdr" and channel["schemaEncoding"] == "ros2msg"
    return generate_dynamic(channel["schemaName"], channel["schema"])[channel["schemaName"]](
        payload)


def _stop(proc: subprocess.Popen) -> int:
    """Ctrl-C, as a person ends a stream; the exit code, once stdout and stderr are read."""
    proc.send_signal(signal.SIGINT)
    code = proc.wait(timeout=WAIT)
    for reader in proc.readers:  # type: ignore[attr-defined]
        reader.join(WAIT)
    return code


def test_stream_serves_the_recordings_topics_to_foxglove():
    proc, url, out, err = _start("stream", "--foxglove", "--foxglove-port", "0", "--duration", "300",
                            "--json", "--rate", "100")
    try:
        assert url.startswith("ws://127.0.0.1:")
        topics = ["/joint_states", "/gpio", "/fingertip_finger_1/wrench", "/diagnostics"]
        channels, got = watch(url, topics, err)
    finally:
        code = _stop(proc)
    assert code == 0, "".join(err)
    assert channels["/joint_states"]["schemaName"] == "sensor_msgs/msg/JointState"
    assert "/dynamic_joint_states" in channels
    for stamp, payload in got["/joint_states"]:
        msg = decode(channels["/joint_states"], payload)
        assert msg.name[:4] == ["j1", "j2", "j3", "j4"]  # the arm on I2C ...
        assert any(n.startswith("j_dg_") for n in msg.name)  # ... and the gripper on TCP
        assert len(msg.position) == len(msg.name)
        assert all(math.isfinite(p) for p in msg.position)
        assert stamp == msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
    gpio = decode(channels["/gpio"], got["/gpio"][-1][1])
    groups = dict(zip(gpio.interface_groups, gpio.interface_values))
    for block in ("bioscara_arm", "dg3f_m_driver", "system"):
        status = dict(zip(groups[block].interface_names, groups[block].values))
        assert status["connection_status"] == 1.0
    wrench = decode(channels["/fingertip_finger_1/wrench"], got["/fingertip_finger_1/wrench"][0][1])
    assert all(math.isfinite(v) for v in (wrench.wrench.force.x, wrench.wrench.torque.z))
    diag = decode(channels["/diagnostics"], got["/diagnostics"][0][1])
    assert "deltoctl/loop" in [s.name for s in diag.status]
    lines = [json.loads(line) for line in out]  # stdout: NDJSON frames only
    assert lines and all(set(line) == {"t", "values"} for line in lines)


def test_record_serves_the_very_bytes_it_records(tmp_path):
    from mcap.reader import make_reader

    mcap = tmp_path / "cell.mcap"
    proc, url, out, err = _start("record", str(mcap), "--foxglove", "--foxglove-port", "0",
                            "--duration", "300", "--json")
    try:
        channels, got = watch(url, ["/joint_states", "/dynamic_joint_states"], err, 10)
    finally:
        code = _stop(proc)
    assert code == 0, "".join(err)
    result = json.loads("".join(out))["result"]
    assert result["foxglove"]["url"] == url and result["foxglove"]["cycles_sent"] > 0
    recorded: dict[tuple[str, int], bytes] = {}
    with mcap.open("rb") as f:
        for _, channel, message in make_reader(f).iter_messages(
                topics=["/joint_states", "/dynamic_joint_states"]):
            recorded[channel.topic, message.log_time] = message.data
    for topic, messages in got.items():
        for stamp, payload in messages:
            assert recorded[topic, stamp] == payload
    dyn = decode(channels["/dynamic_joint_states"], got["/dynamic_joint_states"][0][1])
    assert "j1" in dyn.joint_names


def test_foxglove_without_its_extra_says_how_to_install_it(cli, monkeypatch):
    monkeypatch.setitem(sys.modules, "foxglove", None)  # not installed
    result = cli("-p", PROFILE, "--sim", "stream", "--foxglove", "--duration", "0.1")
    assert result.exit_code == 1
    assert "pip install 'deltoctl[foxglove]'" in result.stderr
    assert "Traceback" not in result.stderr


def test_a_port_in_use_is_one_clear_message(cli, tmp_path):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        for verb in (["stream"], ["record", str(tmp_path / "r.mcap")]):
            result = cli("-p", PROFILE, "--sim", *verb, "--foxglove", "--foxglove-port",
                         str(port), "--duration", "0.1")
            assert result.exit_code == 2, result.stderr
            assert f"--foxglove-port {port}" in result.stderr and "in use" in result.stderr
            assert "Traceback" not in result.stderr
    assert not (tmp_path / "r.mcap").exists()  # refused before the devices were opened


def test_serving_beyond_this_machine_is_said(cli):
    result = cli("-p", PROFILE, "--sim", "stream", "--foxglove", "--foxglove-host", "0.0.0.0",
                 "--foxglove-port", "0", "--duration", "0.1", "--json")
    assert result.exit_code == 0, result.stderr
    assert "served beyond this machine" in result.stderr
    assert "ws://0.0.0.0:" in result.stderr
    assert all(json.loads(line) for line in result.stdout.splitlines())


def test_a_bad_port_is_a_usage_error(cli):
    result = cli("-p", PROFILE, "--sim", "stream", "--foxglove", "--foxglove-port", "70000")
    assert result.exit_code == 2
    assert "--foxglove-port" in result.stderr


def test_a_live_view_that_falls_behind_drops_cycles_and_counts_them():
    """The cycle thread never waits: past the queue's bound, cycles are dropped and counted;
    the publisher sends the rest once it runs, and closing ends everything."""
    from deltoctl.core.loop import LoopStats
    from deltoctl.profile.catalog import load_profile
    from deltoctl.record.foxglove_live import FoxgloveLive

    profile = load_profile(PROFILE)
    with FoxgloveLive("127.0.0.1", 0, queue_cycles=10) as live:
        values = {"j1/position": 0.1, "system/connection_status": 1.0}
        for n in range(25):  # 1 kHz, no publisher yet: it is "behind" by everything
            live.frame(1_000_000 * (n + 1), values)
        assert live.dropped > 0 and live.queued <= 10
        live.begin(profile)
        live.close(LoopStats(1000.0))
        assert not live.thread.is_alive() and live.error is None
        assert live.queued + live.dropped == 25 and live.taken == live.queued
        assert live.sent == 0  # no client watched: nothing was packed
    assert live.stopped


def test_bench_loop_runs_beside_a_foxglove_client(cli):
    result = cli("bench", "loop", "--rate", "200", "--duration", "0.5", "--unpaced", "0",
                 "--foxglove", "--json")
    assert result.exit_code == 0, result.stderr
    one = json.loads(result.stdout)["result"]["hands"]["1"]
    assert one["paced"]["cycles"] > 0 and "foxglove" not in one["paced"]
    live = one["paced_foxglove"]
    assert "foxglove" in live["stage_us_per_cycle"]
    assert live["foxglove"]["cycles_sent"] > 0
    assert 0 < live["foxglove"]["client_joint_states"] <= live["foxglove"]["cycles_sent"]


def test_a_lost_link_shows_in_foxglove_and_the_stream_goes_on():
    """The gripper's link drops while a client watches: /gpio shows its connection_status 0,
    /diagnostics says the link was lost and restored; the stream ends as usual (exit 3)."""
    from deltoctl.families.delto.emulator import DeltoServer, firmware_for_profile
    from deltoctl.profile.catalog import load_profile

    def events(channels: dict, got: dict) -> list[str]:
        return [s.message for _, p in got["/diagnostics"]
                for s in decode(channels["/diagnostics"], p).status if s.name == "deltoctl/link"]

    def statuses(channels: dict, got: dict) -> list[float]:
        return [decode(channels["/gpio"], p).interface_values[-1].values[0]
                for _, p in got["/gpio"]]

    def restored(channels: dict, got: dict) -> bool:
        return "link restored" in events(channels, got)

    with DeltoServer(firmware_for_profile(load_profile("dg-5f-right"))) as server:
        proc, url, _, err = _start("stream", "--foxglove", "--foxglove-port", "0", "--json",
                                   "--duration", "300", robot=("-p", "dg-5f-right", "-t",
                                                               server.endpoint))
        try:
            channels, got = watch(url, ["/gpio", "/diagnostics"], err, done=restored,
                                  subscribed=lambda: threading.Timer(
                                      0.5, server.drop_connections).start())
        finally:
            code = _stop(proc)
    assert events(channels, got) == ["link lost", "link restored"]
    seen = statuses(channels, got)  # the system's connection_status, cycle by cycle
    assert seen[0] == 1.0 and 0.0 in seen and seen[-1] == 1.0
    assert code == 3, "".join(err)
    assert "the link was lost 1 time(s) and came back" in "".join(err)


def test_an_address_that_does_not_resolve_is_a_usage_error(cli):
    result = cli("-p", PROFILE, "--sim", "stream", "--foxglove", "--foxglove-host",
                 "no-such-host.invalid", "--duration", "0.1")
    assert result.exit_code == 2
    assert "--foxglove-host no-such-host.invalid" in result.stderr
    assert "Traceback" not in result.stderr
