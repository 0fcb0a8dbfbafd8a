"""``deltoctl bench loop``: the read+write cycle against ``sim serve`` in another process,
recording to MCAP, with the time per cycle split by stage."""

import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from deltoctl.cli.context import options
from deltoctl.cli.output import emit_json, info
from deltoctl.errors import DeviceError, InvalidInput

if TYPE_CHECKING:
    import subprocess

app = typer.Typer(help="Benchmarks that ship with deltoctl.", no_args_is_help=True)


def _serve(profile: str) -> tuple["subprocess.Popen", str]:
    import json
    import subprocess

    proc = subprocess.Popen([sys.executable, "-m", "deltoctl", "sim", "serve", profile,
                             "--json"], stdout=subprocess.PIPE, text=True)
    line = proc.stdout.readline() if proc.stdout else ""
    if not line:
        proc.kill()
        raise DeviceError("sim serve did not start")
    return proc, json.loads(line)["endpoint"]


def _run(session, rate: float, duration: float, mcap_path: Path) -> dict:  # type: ignore[no-untyped-def]
    from deltoctl.core.loop import CycleLoop
    from deltoctl.record.mcap_recorder import McapRecorder

    driver = session.driver
    timing = {"codec": 0.0, "socket": 0.0, "recording": 0.0, "write": 0.0}
    driver.timing = timing
    efforts = {j.name: 0.0 for j in session.hw.joints}
    with mcap_path.open("wb") as f:
        recorder = McapRecorder(f, session.profile, {})
        loop = CycleLoop(rate, duration)
        cpu0 = time.process_time()
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
        recorder.close()
    driver.timing = None
    stats = loop.stats.summary()
    n = max(stats["cycles"], 1)
    return {
        **stats,
        "achieved_fraction": round(stats["real_rate"] / rate, 4) if rate else None,
        "cpu_us_per_cycle": round(cpu / n * 1e6, 1),
        "stage_us_per_cycle": {k: round(v / n * 1e6, 1) for k, v in timing.items()},
        "mcap_bytes": mcap_path.stat().st_size,
        "errors": driver.stats["errors"],
    }


@app.command("loop")
def bench_loop(
    ctx: typer.Context,
    rate: Annotated[float, typer.Option("--rate", help="Requested cycle rate, Hz.")] = 1000.0,
    duration: Annotated[float, typer.Option("--duration", help="Seconds per run.")] = 10.0,
    unpaced: Annotated[float, typer.Option(
        "--unpaced", help="Seconds of the unpaced run (0: skip).")] = 5.0,
) -> None:
    """A Delto profile (default dg-5f-right: F/T and IO) over loopback TCP, recording to MCAP:
    paced, then unpaced."""
    import os
    import tempfile

    from deltoctl.core.session import Session

    opts = options(ctx)
    if rate <= 0 or duration <= 0 or unpaced < 0:
        raise InvalidInput("--rate and --duration must be positive, --unpaced not negative")
    prof = opts.load_profile(opts.profile or "dg-5f-right")
    proc, endpoint = _serve(str(prof.source))
    results = {"profile": prof.name, "endpoint": endpoint, "python": sys.version.split()[0]}
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
    if opts.json:
        emit_json(results)
        return
    info(f"bench loop: {prof.name} against sim serve at {endpoint} ({os.cpu_count()} CPUs)")
    for name in ("paced", "unpaced"):
        if name not in results:
            continue
        r = results[name]
        info(f"  {name:8} requested {r['requested_rate']:g} Hz, real {r['real_rate']:.1f} Hz"
             + (f" ({100 * r['achieved_fraction']:.2f} %)" if r["achieved_fraction"] else "")
             + f", lateness p50 {r['lateness_p50_ms']:.3f} ms p99 {r['lateness_p99_ms']:.3f} ms"
             f", misses {r['deadline_misses']}, errors {r['errors']}")
        stages = ", ".join(f"{k} {v:.1f}" for k, v in r["stage_us_per_cycle"].items())
        info(f"           µs per cycle: {stages}; CPU {r['cpu_us_per_cycle']:.1f}")
    info("  goals: " + ", ".join(f"{k}={'yes' if v else 'NO'}"
                                 for k, v in results["goals"].items()))


def register(root: typer.Typer) -> None:
    root.add_typer(app, name="bench")
