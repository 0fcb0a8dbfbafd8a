"""``bench loop``: the Delto read+write cycle against ``sim serve`` in another process,
recording to MCAP, the time per cycle split by stage; beside it, the same loop idle."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

from deltoctl.errors import DeviceError
from deltoctl.profile.model import Profile


def _serve(profile: str) -> tuple[subprocess.Popen, str]:
    import json

    proc = subprocess.Popen([sys.executable, "-m", "deltoctl", "sim", "serve", profile,
                             "--json"], stdout=subprocess.PIPE, text=True)
    line = proc.stdout.readline() if proc.stdout else ""
    if not line:
        proc.kill()
        raise DeviceError("sim serve did not start")
    return proc, json.loads(line)["endpoint"]


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


def _run(session, rate: float, duration: float, mcap_path: Path) -> dict:  # type: ignore[no-untyped-def]
    from deltoctl.core.loop import CycleLoop
    from deltoctl.record.recorder_process import RecorderProcess

    driver = session.driver
    timing = {"codec": 0.0, "socket": 0.0, "recording": 0.0, "write": 0.0}
    driver.timing = timing
    efforts = {j.name: 0.0 for j in session.hw.joints}
    recorder = RecorderProcess(mcap_path, session.profile, {})
    loop = CycleLoop(rate, duration)
    cpu0 = time.process_time()
    ticks = _cpu_ticks()
    try:
        for _ in loop:
            values = driver.read()
            t0 = time.perf_counter()
            driver.write_efforts(efforts)
            t1 = time.perf_counter()
            recorder.write(values, time.time_ns())
            t2 = time.perf_counter()
            timing["write"] += t1 - t0
            timing["recording"] += t2 - t1
        cpu = time.process_time() - cpu0
        steal = _steal_percent(ticks, _cpu_ticks())
    finally:
        recorder.close(loop.stats.summary())
        driver.timing = None
    stats = loop.stats.summary()
    n = max(stats["cycles"], 1)
    return {
        **stats,
        "achieved_fraction": round(stats["real_rate"] / rate, 4) if rate else None,
        "cpu_us_per_cycle": round(cpu / n * 1e6, 1),
        "recorder_process_cpu_us_per_cycle": round(recorder.cpu_seconds / n * 1e6, 1),
        "stage_us_per_cycle": {k: round(v / n * 1e6, 1) for k, v in timing.items()},
        "mcap_bytes": mcap_path.stat().st_size,
        "mcap_messages": sum(recorder.counts.values()),
        "cpu_steal_percent": steal,
        "errors": driver.stats["errors"],
    }


def measure(prof: Profile, rate: float, duration: float, unpaced: float) -> dict:
    """The idle baseline, the paced run and (``unpaced`` > 0) the unpaced run, with the
    issue's goals."""
    import tempfile

    from deltoctl.core.session import Session

    proc, endpoint = _serve(str(prof.source))
    results = {"profile": prof.name, "endpoint": endpoint, "python": sys.version.split()[0],
               "idle_loop": _idle_loop(rate, duration)}
    try:
        with tempfile.TemporaryDirectory() as tmp, Session(prof, [endpoint]) as session:
            results["paced"] = _run(session, rate, duration, Path(tmp) / "paced.mcap")
            if unpaced > 0:
                results["unpaced"] = _run(session, 0.0, unpaced, Path(tmp) / "unpaced.mcap")
    finally:
        proc.terminate()
        proc.wait(timeout=5)
    paced = results["paced"]
    results["goals"] = {
        "achieved_rate_ge_99_5_percent": paced["achieved_fraction"] >= 0.995,
        "p99_lateness_le_0_5_ms": paced["lateness_p99_ms"] <= 0.5,
    }
    if "unpaced" in results:
        results["goals"]["unpaced_ge_5_khz"] = results["unpaced"]["real_rate"] >= 5000
    return results
