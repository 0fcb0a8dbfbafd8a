"""``bench loop``: the read+write cycle of 1, 2, 4 … simulated hands, each served by ``sim serve``
in a process of its own, recording to MCAP through the cycle runner, the time per cycle split
by stage; beside it, the same loop idle. With ``--foxglove``, the same run again while the live
view serves every topic to a Foxglove WebSocket client (another process, subscribed to all)."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from deltoctl.core.loop import LoopStats
from deltoctl.core.runner import Sink
from deltoctl.errors import DeltoctlError, DeviceError, InvalidInput
from deltoctl.profile.model import Profile


def loop_options(rate: float, duration: float, unpaced: float, hands: str,
                 hands_per_process: int | None = None) -> tuple[int, ...]:
    """``bench loop``'s options checked; the numbers of hands (``1,2,4``), sorted."""
    import math

    if not all(math.isfinite(x) for x in (rate, duration, unpaced)) or rate <= 0 \
            or duration <= 0 or unpaced < 0:
        raise InvalidInput("--rate and --duration must be positive, --unpaced not negative")
    try:
        counts = tuple(sorted({int(n) for n in hands.split(",") if n.strip()}))
    except ValueError:
        raise InvalidInput(f"--hands takes numbers, e.g. 1,2,4; got {hands!r}") from None
    if not counts or not all(1 <= n <= 16 for n in counts):
        raise InvalidInput("--hands takes 1 to 16 hands")
    if hands_per_process is not None and not 1 <= hands_per_process <= 16:
        raise InvalidInput("--hands-per-process takes 1 to 16")
    return counts


def _serve(profile: str) -> tuple[subprocess.Popen, list[str]]:
    """The simulated devices of a profile in a process of their own; their endpoints, in
    the order of its blocks."""
    import json

    proc = subprocess.Popen([sys.executable, "-m", "deltoctl", "sim", "serve", profile,
                             "--json"], stdout=subprocess.PIPE, text=True)
    line = proc.stdout.readline() if proc.stdout else ""
    if not line:
        proc.kill()
        raise DeviceError("sim serve did not start")
    return proc, list(json.loads(line)["buses"].values())


def _serve_hands(prof: Profile, count: int, per_process: int, tmp: Path,
                 procs: list[subprocess.Popen]) -> list[str]:
    """``count`` simulated hands, ``per_process`` of them to a ``sim serve`` process; their
    endpoints. Each process joins ``procs`` as soon as it runs."""
    endpoints: list[str] = []
    while len(endpoints) < count:
        k = min(per_process, count - len(endpoints))
        proc, served = _serve(str(prof.source) if k == 1 else str(_hands_file(prof, k, tmp)))
        procs.append(proc)
        endpoints += served[:k]
    return endpoints


def _hands_file(prof: Profile, hands: int, tmp: Path) -> Path:
    """A profile of ``hands`` copies of the profile's first block, for ``sim serve``."""
    from deltoctl.profile.exporter import to_yaml

    robot = robot_of(prof, hands)
    for hw in robot.hardware:
        hw.bus = None  # served by block name, each block on a port of its own
    path = tmp / f"hands-{hands}.yaml"
    path.write_text(to_yaml(dataclasses.replace(robot, buses={})))
    return path


def robot_of(prof: Profile, hands: int) -> Profile:
    """A robot of ``hands`` copies of the profile's first block, each on a bus of its own
    (its parts renamed ``h<N>_…``)."""
    import copy
    import dataclasses

    blocks = []
    for n in range(1, hands + 1):
        hw = copy.deepcopy(prof.hardware[0])
        hw.name, hw.bus = f"{hw.name}_{n}", f"hand{n}"
        for comp in hw.components():
            comp.name = f"h{n}_{comp.name}"
        blocks.append(hw)
    return dataclasses.replace(prof, name=f"{prof.name}-x{hands}", hardware=blocks,
                               buses={hw.bus: "" for hw in blocks if hw.bus})


def _cpu_ticks() -> list[int] | None:
    """The machine's CPU time by kind (Linux /proc/stat), to tell how much of a run the
    hypervisor took away (steal): on a shared virtual machine, the cause of most misses."""
    try:
        with open("/proc/stat") as f:
            return [int(x) for x in f.readline().split()[1:9]]
    except (OSError, ValueError):
        return None


def _steal_percent(before: list[int] | None, after: list[int] | None) -> float | None:
    if not before or not after:
        return None
    delta = [b - a for a, b in zip(before, after)]
    return round(100 * delta[7] / max(sum(delta), 1), 2)


def _idle_loop(rate: float, duration: float) -> dict:
    """The baseline: the same cycle loop doing nothing, on this machine, right now. What it
    misses, no work in the cycle can avoid."""
    from deltoctl.core.loop import CycleLoop

    ticks = _cpu_ticks()
    loop = CycleLoop(rate, duration)
    for _ in loop:
        pass
    stats = loop.stats.summary()
    return {"real_rate": stats["real_rate"],
            "achieved_fraction": round(stats["real_rate"] / rate, 4),
            "deadline_misses": stats["deadline_misses"],
            "lateness_p99_ms": stats["lateness_p99_ms"],
            "cpu_steal_percent": _steal_percent(ticks, _cpu_ticks())}


class _Recording(Sink):
    """The bench's sink: every frame to the recorder process, timed."""

    def __init__(self, recorder: Any, timing: dict[str, float]) -> None:
        self.recorder, self.timing = recorder, timing

    def frame(self, t_ns: int, values: dict[str, float]) -> None:
        t0 = time.perf_counter()
        self.recorder.write(values, t_ns)
        self.timing["recording"] += time.perf_counter() - t0

    def close(self, stats: LoopStats) -> None:
        self.recorder.close(stats.summary())


class _Timed(Sink):
    """Another sink's frames, timed as a stage of their own."""

    def __init__(self, sink: Sink, timing: dict[str, float], stage: str) -> None:
        self.sink, self.timing, self.stage = sink, timing, stage
        timing[stage] = 0.0

    def frame(self, t_ns: int, values: dict[str, float]) -> None:
        t0 = time.perf_counter()
        self.sink.frame(t_ns, values)
        self.timing[self.stage] += time.perf_counter() - t0

    def periodic(self, t_ns: int, stats: LoopStats, comm_loops: list) -> None:
        self.sink.periodic(t_ns, stats, comm_loops)

    def close(self, stats: LoopStats) -> None:
        self.sink.close(stats)


FOXGLOVE_CLIENT = """
import asyncio, json, sys, time
import websockets

async def main(url):
    counts = {}
    async with websockets.connect(url, subprotocols=["foxglove.sdk.v1", "foxglove.websocket.v1"],
                                  max_size=None) as ws:
        channels = {}
        while len(channels) < int(sys.argv[2]):
            op = json.loads(await ws.recv())
            if op["op"] == "advertise":
                channels.update({c["id"]: c["topic"] for c in op["channels"]})
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": cid, "channelId": cid} for cid in channels]}))
        print("subscribed", flush=True)
        first = last = None
        try:
            async for msg in ws:
                if isinstance(msg, bytes) and msg[0] == 1:
                    topic = channels[int.from_bytes(msg[1:5], "little")]
                    counts[topic] = counts.get(topic, 0) + 1
                    last = time.monotonic()
                    first = first or last
        except websockets.ConnectionClosed:
            pass
    print(json.dumps({"messages": counts, "seconds": (last - first) if first else 0,
                      "cpu_seconds": time.process_time()}))

asyncio.run(main(sys.argv[1]))
"""


def _foxglove_client(url: str, channels: int) -> subprocess.Popen:
    """A Foxglove WebSocket client in a process of its own, subscribed to every channel
    (returns once it is)."""
    try:
        import websockets  # noqa: F401
    except ImportError:
        raise DeltoctlError("bench loop --foxglove needs websockets for its client",
                            "pip install websockets") from None
    proc = subprocess.Popen([sys.executable, "-c", FOXGLOVE_CLIENT, url, str(channels)],
                            stdout=subprocess.PIPE, text=True)
    if not proc.stdout or proc.stdout.readline().strip() != "subscribed":
        proc.kill()
        raise DeviceError(f"the Foxglove client did not subscribe at {url}")
    return proc


def _run(system: Any, rate: float, duration: float, mcap_path: Path,
         foxglove: bool = False) -> dict:
    """The cycle runner on every hand: read, zero efforts written, recorded; with
    ``foxglove``, served live to a subscribed client as well."""
    from deltoctl.core.runner import run_cycles
    from deltoctl.record.recorder_process import RecorderProcess

    timing = {"codec": 0.0, "socket": 0.0, "recording": 0.0, "write": 0.0}
    write = _timed_write(system, timing)
    recorded = dataclasses.replace(system.profile, hardware=[m.hw for m in system])
    sinks: list[Sink] = []
    live = client = None
    if foxglove:
        live, client = _live_view(recorded, system)
        sinks.append(_Timed(live, timing, "foxglove"))
    recorder = RecorderProcess(mcap_path, recorded, {})
    before = _Usage()
    try:
        loop = run_cycles(system, rate, duration, [_Recording(recorder, timing), *sinks], write)
    finally:
        for m in system:
            m.driver.timing = None
        if live is not None:
            live.stop()
    used = before.since()
    n = max(loop.cycles, 1)
    return {
        **_cycle_figures(loop, rate, used, len(system.members)),
        "recorder_process_cpu_us_per_cycle": round(recorder.cpu_seconds / n * 1e6, 1),
        # of which starting and finishing the file, once a run; the rest is the cycles'
        "recorder_process_setup_cpu_ms": round(recorder.setup_cpu_seconds * 1e3, 1),
        "recorder_process_cycles_cpu_us_per_cycle":
            round((recorder.cpu_seconds - recorder.setup_cpu_seconds) / n * 1e6, 1),
        "stage_us_per_cycle": {k: round(v / n * 1e6, 1) for k, v in timing.items()},
        "mcap_bytes": mcap_path.stat().st_size,
        "mcap_messages": sum(recorder.counts.values()),
        "errors": system.stats["errors"],
        **({"foxglove": _foxglove_report(live, client)} if live and client else {}),
    }


def _timed_write(system: Any, timing: dict[str, float]) -> Callable[[dict[str, float]], None]:
    """The cycle's write, zero efforts to every hand, timed; each driver times its read into
    ``timing`` too."""
    hands = [(m.driver, {f"{j.name}/effort": 0.0 for j in m.hw.joints}) for m in system]
    for driver, _ in hands:
        driver.timing = timing

    def write(values: dict[str, float]) -> None:
        t0 = time.perf_counter()
        for driver, efforts in hands:
            driver.write(efforts)
        timing["write"] += time.perf_counter() - t0

    return write


def _live_view(recorded: Profile, system: Any) -> tuple[Any, subprocess.Popen]:
    """The Foxglove live view of the run and a client subscribed to every topic."""
    from deltoctl.record.foxglove_live import FoxgloveLive

    live = FoxgloveLive("127.0.0.1", 0)
    try:
        live.begin(recorded, tuple(system.extra_states()))
        return live, _foxglove_client(live.url, len(live.recorder.channels))
    except BaseException:
        live.stop()
        raise


class _Usage:
    """What the calling thread (the loop's) and its process used from now on: CPU time,
    and the times the thread blocked and was woken (voluntary context switches)."""

    def __init__(self) -> None:
        self.process, self.thread = time.process_time(), time.thread_time()
        self.ticks, self.wakeups = _cpu_ticks(), _wakeups()

    def since(self) -> dict[str, Any]:
        return {"process_cpu": time.process_time() - self.process,
                "thread_cpu": time.thread_time() - self.thread,
                "wakeups": _wakeups() - self.wakeups,
                "steal": _steal_percent(self.ticks, _cpu_ticks())}


def _wakeups() -> int:
    """The calling thread's voluntary context switches so far (0 where not counted)."""
    try:
        import resource

        return resource.getrusage(resource.RUSAGE_THREAD).ru_nvcsw
    except (ImportError, AttributeError, OSError):
        return 0


def _cycle_figures(loop: LoopStats, rate: float, used: dict[str, Any], hands: int) -> dict:
    """The loop's statistics, its rate against the requested one and its own cost: the
    loop thread's CPU per cycle, per hand, and its wake-ups per cycle."""
    stats = loop.summary()
    n = max(stats["cycles"], 1)
    return {
        **stats,
        "achieved_fraction": round(stats["real_rate"] / rate, 4) if rate else None,
        "cpu_us_per_cycle": round(used["process_cpu"] / n * 1e6, 1),
        "loop_thread_cpu_us_per_cycle": round(used["thread_cpu"] / n * 1e6, 1),
        "loop_cpu_us_per_hand_cycle": round(used["thread_cpu"] / n / hands * 1e6, 1),
        "loop_wakeups_per_cycle": round(used["wakeups"] / n, 2),
        "cpu_steal_percent": used["steal"],
    }


def _syscalls(system: Any, rate: float, duration: float, mcap_path: Path) -> dict | None:
    """The loop thread's system calls per cycle, by name, counted by ``strace -c`` attached
    to it during a paced run of its own (tracing slows every call: the run's timing is not
    reported). None where strace is missing or may not attach."""
    import shutil
    import signal
    import threading

    strace = shutil.which("strace")
    if strace is None:
        return None
    proc = subprocess.Popen([strace, "-c", "-p", str(threading.get_native_id())],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    attached = proc.stderr.readline() if proc.stderr else ""  # "Process N attached"
    if "attached" not in attached:
        proc.kill()
        proc.communicate()
        return None
    try:
        run = _run(system, rate, duration, mcap_path)
    finally:
        proc.send_signal(signal.SIGINT)
        table = proc.communicate(timeout=30)[1]
    calls = _strace_counts(table)
    n = max(run["cycles"], 1)
    return {"cycles": run["cycles"],
            "per_cycle": round(sum(calls.values()) / n, 2),
            "by_call": {name: round(count / n, 2) for name, count
                        in sorted(calls.items(), key=lambda c: -c[1]) if count / n >= 0.01}}


def _strace_counts(table: str) -> dict[str, int]:
    """``strace -c``'s summary → calls by system call name."""
    calls = {}
    for line in table.splitlines():
        parts = line.split()  # % time, seconds, usecs/call, calls, [errors], syscall
        if len(parts) in (5, 6) and parts[3].isdigit() and parts[-1] != "total":
            calls[parts[-1]] = int(parts[3])
    return calls


def _foxglove_report(live: Any, client: subprocess.Popen) -> dict:
    """What the live view sent and the client received."""
    import json

    out, _ = client.communicate(timeout=60)
    got = json.loads(out.splitlines()[-1]) if out.strip() else {"messages": {}, "seconds": 0}
    received = got["messages"].get("/joint_states", 0)
    return {"cycles_sent": live.sent, "cycles_dropped": live.dropped,
            "client_messages": sum(got["messages"].values()),
            "client_joint_states": received,
            "client_joint_states_per_s": round(received / got["seconds"], 1)
            if got["seconds"] else 0.0,
            "client_cpu_percent": round(100 * got.get("cpu_seconds", 0) / got["seconds"], 1)
            if got["seconds"] else None}


def measure(prof: Profile, rate: float, duration: float, unpaced: float,
            hands: tuple[int, ...] = (1,), foxglove: bool = False,
            hands_per_process: int | None = None) -> dict:
    """The idle baseline, then for each number of hands N (served by ``sim serve``,
    ``hands_per_process`` to a process; by default all N by one) the paced run, the loop
    thread's system calls, (``foxglove``) the paced run with the live view and a subscribed
    client, and (``unpaced`` > 0) the unpaced run, with the goals."""
    import tempfile

    if foxglove:
        from deltoctl.record.foxglove_live import load_foxglove

        load_foxglove()  # the extra is there, before any device is started
    results: dict[str, Any] = {"profile": prof.name, "python": sys.version.split()[0],
                               "hands_per_process": hands_per_process,
                               "idle_loop": _idle_loop(rate, duration), "hands": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for n in hands:
            runs = {"paced": (rate, duration, False), "syscalls": (rate, min(duration, 2.0)),
                    "paced_foxglove": (rate, duration, True) if foxglove else None,
                    "unpaced": (0.0, unpaced, False) if unpaced > 0 else None}
            results["hands"][str(n)] = _hands_runs(prof, n, hands_per_process or n, Path(tmp),
                                                   {k: v for k, v in runs.items() if v})
    results["goals"] = _goals(results["hands"], hands)
    return results


def _hands_runs(prof: Profile, n: int, per_process: int, tmp: Path,
                runs: dict[str, tuple]) -> dict[str, Any]:
    """``n`` hands served for the runs (name: rate, duration and, but for ``syscalls``,
    whether with the live view), one after the other; their emulators stopped after."""
    import contextlib

    from deltoctl.core.system import System

    with contextlib.ExitStack() as stack:
        procs: list[subprocess.Popen] = []
        stack.callback(_stop, procs)
        endpoints = _serve_hands(prof, n, per_process, tmp, procs)
        targets = [f"hand{i + 1}={endpoints[i]}" for i in range(n)]
        report: dict[str, Any] = {"endpoints": endpoints}
        with System(robot_of(prof, n), targets) as system:
            for name, (rate, duration, *live) in runs.items():
                mcap = tmp / f"{name}-{n}.mcap"
                report[name] = _syscalls(system, rate, duration, mcap) if name == "syscalls" \
                    else _run(system, rate, duration, mcap, foxglove=live[0])
    return report


def _stop(procs: list[subprocess.Popen]) -> None:
    for proc in procs:
        proc.terminate()
    for proc in procs:
        proc.wait(timeout=5)


def _goals(runs: dict[str, dict], hands: tuple[int, ...]) -> dict[str, bool]:
    """The paced goals for the most hands run; unpaced, one hand's rate, and two hands
    against one (I/O overlapped, not in series)."""
    most = runs[str(max(hands))]["paced"]
    goals = {f"{max(hands)}_hands_rate_ge_99_5_percent": most["achieved_fraction"] >= 0.995,
             f"{max(hands)}_hands_p99_lateness_le_0_5_ms": most["lateness_p99_ms"] <= 0.5}
    live = runs[str(max(hands))].get("paced_foxglove")
    if live is not None:
        goals[f"{max(hands)}_hands_foxglove_rate_ge_99_5_percent"] = \
            live["achieved_fraction"] >= 0.995
    unpaced = {n: r["unpaced"]["real_rate"] for n, r in runs.items() if "unpaced" in r}
    if "1" in unpaced:
        goals["unpaced_1_hand_ge_5_khz"] = unpaced["1"] >= 5000
        if "2" in unpaced:
            goals["unpaced_2_hands_ge_0_8_of_1"] = unpaced["2"] >= 0.8 * unpaced["1"]
    return goals
