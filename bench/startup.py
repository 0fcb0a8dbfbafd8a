"""Start-up cost of deltoctl, side by side with its floor (``import typer``) in one run.

Every line of a bring-up script pays it. Runs the commands interleaved, N times each, with
stdout piped (as a script sees it), and prints medians and ratios to the baseline.

    python bench/startup.py [--runs N] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=15)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    deltoctl = shutil.which("deltoctl") or f"{sys.prefix}/bin/deltoctl"
    commands = {
        "baseline: python -c 'import typer'": [sys.executable, "-c", "import typer"],
        "deltoctl --version": [deltoctl, "--version"],
        "deltoctl profile list": [deltoctl, "profile", "list"],
        "deltoctl profile list --json": [deltoctl, "profile", "list", "--json"],
    }
    cold = "deltoctl profile list (cold cache)"
    commands[cold] = commands["deltoctl profile list"]
    # modules compiled once, as an installed package's are (pip compiles them): a shell that
    # sets PYTHONDONTWRITEBYTECODE would otherwise time deltoctl's compiling, not typer's
    compiled = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    for cmd in commands.values():
        subprocess.run(cmd, capture_output=True, check=True, env=compiled)
    times: dict[str, list[float]] = {name: [] for name in commands}
    for _ in range(args.runs):
        for name, cmd in commands.items():
            env = compiled
            if name == cold:  # every profile parsed, as on the first run after a change
                env = dict(compiled, XDG_CACHE_HOME=tempfile.mkdtemp())
            start = time.perf_counter()
            subprocess.run(cmd, capture_output=True, check=True, env=env)
            times[name].append(time.perf_counter() - start)
    base = statistics.median(times[next(iter(commands))])
    rows = [{"command": name, "median_ms": round(statistics.median(t) * 1e3, 1),
             "min_ms": round(min(t) * 1e3, 1), "ratio": round(statistics.median(t) / base, 2)}
            for name, t in times.items()]
    if args.json:
        print(json.dumps({"runs": args.runs, "results": rows}, indent=2))
        return
    print(f"start-up, {args.runs} runs each, stdout piped (goal: ratio <= 1.30)")
    for r in rows:
        print(f"  {r['command']:<40} median {r['median_ms']:7.1f} ms  "
              f"min {r['min_ms']:7.1f} ms  ratio {r['ratio']:.2f}")


if __name__ == "__main__":
    main()
