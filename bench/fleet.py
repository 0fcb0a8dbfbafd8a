"""Remote robots over Zenoh, measured on loopback in one run:

- the latency a remote verb adds: ``deltoctl --robot R identify --json`` against the same
  verb run on the robot's computer (both whole processes, interleaved), p50 and p99; and the
  part the network and the agent take alone (one caller session, no interpreter start-up);
- ``deltoctl fleet run identify`` on N simulated agents behind one router (goal ≤ 3 s at 20);
- the deadman: how long after a caller freezes (SIGSTOP, as a partition) its remote jog's
  joint stops moving, read from the simulator itself (goal ≤ 250 ms);
- optionally, a remote record at 1 kHz from 4 agents by one caller process: how many of the
  cycles the robots ran reached the files, with their original timestamps (goal ≥ 99.9 %).

    python bench/fleet.py [--runs N] [--agents N] [--stops N] [--stream] [--json]
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import re
import signal
import statistics
import struct
import subprocess
import tempfile
import threading
import time
from pathlib import Path

from deltoctl.fleet import lab, zenoh_module
from deltoctl.fleet.remote_call import RemoteCall

JOINT = "rj_dg_2_2"
PROFILES = ("dg-5f-right", "dg-3f-m", "bioscara-arm", "rrbot-gpio", "dg-4f")


def pct(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(q / 100 * (len(ordered) - 1)))]


def env() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if not k.startswith("DELTOCTL_")}


def timed(command: list[str]) -> float:
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, env=env(), stdin=subprocess.DEVNULL)
    elapsed = time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(command)}: exit {done.returncode}\n{done.stderr!r}")
    return elapsed


def latency(tmp: Path, runs: int) -> dict:
    port = lab.free_port()
    agent = lab.AgentProcess("lat", "dg-5f-right", ["--listen", lab.endpoint(port)],
                             cwd=str(tmp)).wait_ready()
    config = lab.write_config(tmp / "lat.json5", "client", connect=[lab.endpoint(port)])
    zenoh = zenoh_module()
    session = zenoh.open(zenoh.Config.from_file(str(config)))
    try:
        links = lab.info(session, "lat")["links"]
        dc = lab.deltoctl_command()
        remote_cmd = [*dc, "--zenoh-config", str(config), "--robot", "lat", "identify", "--json"]
        local_cmd = [*dc, *links, "identify", "--json"]
        remote, local = [], []
        for _ in range(runs):
            remote.append(timed(remote_cmd))
            local.append(timed(local_cmd))
        calls, overhead = [], []
        for _ in range(runs):
            time.sleep(0.05)
            call = RemoteCall(session, "lat", ["identify", "--json"], lambda _: None,
                              lambda _: None)
            start = time.perf_counter()
            code = call.run()
            calls.append(time.perf_counter() - start)
            assert code == 0
            # the agent logs how long the verb's process took, fork to exit
            _until(lambda c=call: any(f"{c.rid}: identify: exit" in ln for ln in agent.log), 5)
            line = next(ln for ln in agent.log if f"{call.rid}: identify: exit" in ln)
            verb = float(re.search(r"after ([0-9.]+) s", line).group(1))  # type: ignore[union-attr]
            overhead.append(calls[-1] - verb)
        added = [r - loc for r, loc in zip(remote, local)]
        ms = lambda xs, q: round(pct(xs, q) * 1e3, 1)  # noqa: E731
        return {"runs": runs,
                "local_ms": {"p50": ms(local, 50), "p99": ms(local, 99)},
                "remote_ms": {"p50": ms(remote, 50), "p99": ms(remote, 99)},
                "added_ms": {"p50": ms(added, 50), "p99": ms(added, 99)},
                "remote_call_in_session_ms": {"p50": ms(calls, 50), "p99": ms(calls, 99)},
                "network_and_agent_ms": {"p50": ms(overhead, 50), "p99": ms(overhead, 99)}}
    finally:
        session.close()
        agent.stop()


def fleet_run(tmp: Path, count: int, repeats: int = 3) -> dict:
    router = lab.Router()
    agent_config = lab.write_config(tmp / "agent.json5", "client", connect=[router.endpoint])
    config = lab.write_config(tmp / "caller.json5", "client", connect=[router.endpoint])
    started = time.perf_counter()
    agents = [lab.AgentProcess(f"robot-{i:02d}", PROFILES[i % len(PROFILES)], [], cwd=str(tmp),
                               config=agent_config) for i in range(count)]
    try:
        for a in agents:
            a.wait_ready(120)
        ready = time.perf_counter() - started
        time.sleep(3.0)  # let the start-up settle: measure the verb, not the machine's boot
        walls = []
        for _ in range(repeats):
            start = time.perf_counter()
            done = subprocess.run([*lab.deltoctl_command(), "--zenoh-config", str(config),
                                   "fleet", "run", "identify", "--json"],
                                  capture_output=True, text=True, env=env(),
                                  stdin=subprocess.DEVNULL)
            walls.append(time.perf_counter() - start)
            time.sleep(1.0)
            report = json.loads(done.stdout)
            ok = sum(r["exit_code"] == 0 for r in report["robots"])
            if done.returncode != 0 or ok != count:
                raise RuntimeError(f"fleet run: exit {done.returncode}, {ok}/{count} ok")
        return {"agents": count, "agents_ready_s": round(ready, 2),
                "fleet_run_identify_s": [round(w, 3) for w in walls],
                "best_s": round(min(walls), 3), "median_s": round(statistics.median(walls), 3)}
    finally:
        for a in agents:
            a.stop()
        router.close()


def deadman(tmp: Path, stops: int) -> dict:
    port = lab.free_port()
    agent = lab.AgentProcess("dm", "dg-5f-right", ["--listen", lab.endpoint(port),
                                                   "--allow-unauthenticated-motion"],
                             cwd=str(tmp)).wait_ready()
    config = lab.write_config(tmp / "dm.json5", "client", connect=[lab.endpoint(port)])
    zenoh = zenoh_module()
    session = zenoh.open(zenoh.Config.from_file(str(config)))
    times = []
    try:
        links = lab.info(session, "dm")["links"]
        for _ in range(stops):
            probe = lab.JointProbe("dg-5f-right", lab.targets(links)[0], JOINT)
            try:
                target = "-20deg" if probe.position() > 0.3 else "20deg"
                client = subprocess.Popen(
                    [*lab.deltoctl_command(), "--zenoh-config", str(config), "--robot", "dm",
                     "jog", JOINT, target, "--velocity", "4deg", "--yes"],
                    stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env(),
                    stdin=subprocess.DEVNULL)
                _until(probe.moving, 20)
                time.sleep(0.3)
                client.send_signal(signal.SIGSTOP)
                frozen = time.monotonic()
                _until(lambda p=probe: p.still(0.1), 5)
                times.append(probe.last_change() - frozen)
                client.send_signal(signal.SIGCONT)
                client.wait(15)
            finally:
                probe.close()
        ms = [round(t * 1e3, 1) for t in times]
        return {"deadline_ms": 200, "stops": len(ms), "stop_ms": ms,
                "p50_ms": pct(ms, 50), "max_ms": max(ms)}
    finally:
        session.close()
        agent.stop()


def stream(tmp: Path, seconds: float = 5.0, rate: float = 1000.0, count: int = 4) -> dict:
    """A remote record at ``rate`` from ``count`` agents by one caller process (one Zenoh
    session, a RemoteRecord per robot, as ``deltoctl --robot R record`` runs it): of the
    cycles the robots ran (each stream says how many), how many reached the files, read back
    from them with their original (the robot's) timestamps."""
    from deltoctl.fleet.remote_record import RemoteRecord

    router = lab.Router()
    agent_config = lab.write_config(tmp / "sa.json5", "client", connect=[router.endpoint])
    agents = [lab.AgentProcess(f"s{i}", "dg-5f-right", [], cwd=str(tmp), config=agent_config)
              for i in range(count)]
    zenoh = zenoh_module()
    session = zenoh.open(zenoh.Config.from_file(
        str(lab.write_config(tmp / "sc.json5", "client", connect=[router.endpoint]))))
    try:
        for a in agents:
            a.wait_ready(120)
        time.sleep(2.0)  # let the start-up settle
        records = [RemoteRecord(session, f"s{i}", tmp / f"s{i}.mcap", rate, seconds, [])
                   for i in range(count)]
        codes: dict[int, int | str] = {}

        def record(i: int) -> None:
            try:
                codes[i] = records[i].run()
            except Exception as exc:  # said in the report
                codes[i] = f"{type(exc).__name__}: {exc}"

        cpu = time.process_time()
        started = time.time_ns()
        threads = [threading.Thread(target=record, args=(i,)) for i in range(count)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        ended = time.time_ns()
        cpu = time.process_time() - cpu
        ran = {i: r.robot_cycles or 0 for i, r in enumerate(records)}
        in_file, ordered = {}, True
        periods: list[int] = []
        for i in range(count):
            stamps = _stamps(tmp / f"s{i}.mcap")
            in_file[i] = len(stamps)
            ordered &= all(a < b for a, b in itertools.pairwise(stamps))
            ordered &= not stamps or (started <= stamps[0] and stamps[-1] <= ended)
            periods += [b - a for a, b in itertools.pairwise(stamps)]
        return {"agents": count, "rate_hz": rate, "seconds": seconds, "exit_codes": codes,
                "cycles_run_by_the_robots": ran, "cycles_in_the_files": in_file,
                "in_files_of_run_pct": round(
                    100 * sum(in_file.values()) / max(1, sum(ran.values())), 3),
                "robots_real_rate_hz": {i: r.summary()["real_rate"]
                                        for i, r in enumerate(records)},
                "timestamps_increasing_and_in_window": ordered,
                "period_ms": {"p50": round(pct(periods, 50) / 1e6, 3),
                              "p99": round(pct(periods, 99) / 1e6, 3)} if periods else None,
                "caller_cpu_s_per_s": round(cpu / seconds, 2)}
    finally:
        session.close()
        for a in agents:
            a.stop()
        router.close()


def _stamps(path: Path) -> list[int]:
    """The /joint_states log times of a recording, checked against each message's header
    stamp (both are the robot's cycle time)."""
    from mcap.reader import make_reader

    stamps = []
    with open(path, "rb") as f:  # CDR: a 4-byte encapsulation, then the header's stamp
        for _, _, message in make_reader(f).iter_messages(topics=["/joint_states"]):
            sec, nsec = struct.unpack_from("<iI", message.data, 4)
            if sec * 1_000_000_000 + nsec != message.log_time:
                raise RuntimeError(f"{path}: a header stamp differs from its log time")
            stamps.append(message.log_time)
    return stamps


def _until(predicate, timeout: float) -> None:  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise RuntimeError("timed out")
        time.sleep(0.01)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=30, help="remote/local pairs")
    parser.add_argument("--agents", type=int, default=20)
    parser.add_argument("--stops", type=int, default=10, help="deadman trials")
    parser.add_argument("--stream", action="store_true",
                        help="the 1 kHz remote record from 4 agents too")
    parser.add_argument("--only-stream", action="store_true",
                        help="only the remote record (skip latency, deadman, fleet run)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        if not args.only_stream:
            results["latency"] = latency(Path(tmp), args.runs)
            results["deadman"] = deadman(Path(tmp), args.stops)
            results["fleet_run"] = fleet_run(Path(tmp), args.agents)
        if args.stream or args.only_stream:
            results["stream"] = stream(Path(tmp))
    if args.json:
        print(json.dumps(results, indent=2))
        return
    if "latency" in results:
        _print_verbs(results)
    if "stream" in results:
        st = results["stream"]
        print(f"remote record {st['rate_hz']:g} Hz × {st['agents']} agents for "
              f"{st['seconds']:g} s by one caller: {st['in_files_of_run_pct']} % of the cycles "
              f"the robots ran reached the files ({sum(st['cycles_in_the_files'].values())} of "
              f"{sum(st['cycles_run_by_the_robots'].values())}); original timestamps "
              f"increasing and in the window: {st['timestamps_increasing_and_in_window']}; "
              f"period p50 {st['period_ms'] and st['period_ms']['p50']} ms, p99 "
              f"{st['period_ms'] and st['period_ms']['p99']} ms; caller CPU "
              f"{st['caller_cpu_s_per_s']} s/s; exit codes {st['exit_codes']}")


def _print_verbs(results: dict) -> None:
    lat, dm, fr = results["latency"], results["deadman"], results["fleet_run"]
    print(f"remote verb (identify, {lat['runs']} runs): local p50 {lat['local_ms']['p50']} ms, "
          f"remote p50 {lat['remote_ms']['p50']} ms; added p50 {lat['added_ms']['p50']} ms, "
          f"p99 {lat['added_ms']['p99']} ms; one call in a session p50 "
          f"{lat['remote_call_in_session_ms']['p50']} ms, p99 "
          f"{lat['remote_call_in_session_ms']['p99']} ms, of which Zenoh and the agent p50 "
          f"{lat['network_and_agent_ms']['p50']} ms, p99 {lat['network_and_agent_ms']['p99']} ms")
    print(f"deadman: joint stopped {dm['p50_ms']} ms (p50), {dm['max_ms']} ms (max) after the "
          f"caller froze; deadline {dm['deadline_ms']} ms; {dm['stops']} trials")
    print(f"fleet run identify on {fr['agents']} agents: best {fr['best_s']} s, median "
          f"{fr['median_s']} s (agents ready in {fr['agents_ready_s']} s)")


if __name__ == "__main__":
    main()
