"""A long recording, and how fast `deltoctl info` and `deltoctl plot` read it.

Writes an hour (``--minutes 60``) of a DG-5F-R at 1 kHz faster than real time: the recorder
(McapRecorder into McapFile, as the recorder process writes) fed synthetic values, with a
link lost for 5 s at half time, a 50 ms stall of the loop and the loop statistics once a
second, as `record` writes them. Then it times, each as a command of its own (start-up
included):

- ``deltoctl info FILE`` (the figure to keep: ≤ 5 s for an hour at 1 kHz),
- ``deltoctl plot FILE rj_dg_1_1/position --out plot.png`` (≤ 10 s).

    python bench/long_recording.py [--minutes 60] [--out /tmp/deltoctl-1h.mcap] [--keep]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

RATE = 1000
LOST_FOR = 5.0  # s of lost link, at half time
STALL = 0.05  # s without cycles, at three quarters
RUN = "import sys; from deltoctl.cli import main; sys.argv[0] = 'deltoctl'; main.main()"


def _keys(profile) -> list[str]:  # type: ignore[no-untyped-def]
    keys = [f"{c.name}/{i.name}" for _, c in profile.components() for i in c.state_interfaces]
    keys += [f"{hw.name}/connection_status" for hw in profile.hardware]
    return [*keys, "system/connection_status"]


def _rows(n_keys: int) -> list[list[float]]:
    """A second of smooth values (a sine per interface), cycled through."""
    return [[math.sin(2 * math.pi * (i / RATE) + k) for k in range(n_keys - 2)] + [1.0, 1.0]
            for i in range(RATE)]


def write(path: Path, minutes: float) -> dict[str, float]:
    from deltoctl.profile.catalog import load_profile
    from deltoctl.record.mcap_recorder import OK, McapFile, McapRecorder

    profile = load_profile("dg-5f-right")
    keys = _keys(profile)
    rows = _rows(len(keys))
    down = [math.nan] * (len(keys) - 2) + [0.0, 0.0]
    cycles = int(minutes * 60 * RATE)
    lost = range(cycles // 2, cycles // 2 + int(LOST_FOR * RATE))
    stall_at = cycles * 3 // 4
    out = McapFile(str(path))
    recorder = McapRecorder(out, profile, {"deltoctl": {"version": "bench"}})
    recorder.set_keys(keys)
    t0 = time.time_ns()
    period = 1_000_000_000 // RATE
    started = time.perf_counter()
    skip = 0
    for i in range(cycles):
        if i == stall_at:
            skip = int(STALL * 1e9)
        t_ns = t0 + i * period + skip
        recorder.write_row(list(down if i in lost else rows[i % RATE]), t_ns)
        if i % RATE == RATE - 1:
            recorder.diagnostics(t_ns, [(OK, "loop", "record loop", _loop(i + 1))])
    recorder.close(_loop(cycles), t0 + cycles * period + skip)
    out.close()
    seconds = time.perf_counter() - started
    return {"cycles": cycles, "messages": sum(recorder.counts.values()),
            "bytes": path.stat().st_size, "write_s": round(seconds, 1)}


def _loop(cycles: int) -> dict[str, float]:
    return {"requested_rate": float(RATE), "real_rate": 999.9, "cycles": cycles,
            "deadline_misses": 1, "lateness_p50_ms": 0.02, "lateness_p99_ms": 0.13,
            "period_jitter_p50_ms": 0.01, "period_jitter_p99_ms": 0.12}


def timed(*args: str) -> tuple[float, str]:
    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", RUN, *args], capture_output=True, text=True)
    seconds = time.perf_counter() - started
    if done.returncode:
        raise SystemExit(f"deltoctl {' '.join(args)} failed ({done.returncode}): {done.stderr}")
    return seconds, done.stdout


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=60.0)
    parser.add_argument("--out", type=Path,
                        default=Path(tempfile.gettempdir()) / "deltoctl-1h.mcap")
    parser.add_argument("--keep", action="store_true", help="keep the file afterwards")
    parser.add_argument("--reuse", action="store_true", help="time an existing file")
    args = parser.parse_args()
    figures: dict[str, object] = {}
    if not (args.reuse and args.out.exists()):
        figures.update(write(args.out, args.minutes))
    try:
        subprocess.run(["cat", str(args.out)], stdout=subprocess.DEVNULL)  # a warm page cache
        info_s, report = timed("info", str(args.out), "--json")
        described = json.loads(report)
        png = args.out.with_suffix(".png")
        plot_s, _ = timed("plot", str(args.out), "rj_dg_1_1/position", "--out", str(png))
        figures.update({
            "file": str(args.out), "bytes": described["bytes"],
            "messages": described["messages"], "duration_s": described["duration_s"],
            "link_losses": len(described["link_losses"]), "gaps": len(described["gaps"]),
            "info_s": round(info_s, 2), "plot_one_interface_s": round(plot_s, 2)})
    finally:
        if not args.keep:
            os.unlink(args.out)
    print(json.dumps(figures, indent=2))


if __name__ == "__main__":
    main()
