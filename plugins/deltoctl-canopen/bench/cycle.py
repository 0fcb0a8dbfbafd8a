"""A 1 kHz SYNC cycle of two emulated CiA 402 axes, and the SDO round trip.

The drives run in a `sim serve` process of their own (the local hub between the processes);
this process is the master, on canopen's own client: each cycle sends both axes' RPDO1
(controlword, target position) and a SYNC, then waits for both TPDO1s (statusword, position).
Reported: the rate achieved, the lateness p99 of the cycle starts, the cycle's round trip
against the wire time of its five frames at 1 Mbit/s (a classic 8-byte frame is at most 135
bits), and the SDO round trip (an expedited read of 0x6041).

    .venv/bin/python plugins/deltoctl-canopen/bench/cycle.py [--seconds 5] [--rate 1000]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import threading
import time

FRAME_BITS, BITRATE = 135, 1_000_000


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q / 100 * len(ordered)))] if ordered else 0.0


def main() -> None:
    import canopen

    from deltoctl_canopen.hub import HubBus
    from deltoctl_canopen.nodes import GENERIC_EDS, PROFILES

    parser = argparse.ArgumentParser()
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--rate", type=float, default=1000.0)
    args = parser.parse_args()
    serve = subprocess.Popen([sys.executable, "-m", "deltoctl", "sim", "serve",
                              str(PROFILES / "cia402-two-axis.yaml"), "--json"],
                             stdout=subprocess.PIPE, text=True)
    try:
        url = json.loads(serve.stdout.readline())["endpoint"]
        network = canopen.Network(HubBus(channel=url.split("/")[3].split("?")[0]))
        network.connect()
        nodes = [network.add_node(i, str(GENERIC_EDS)) for i in (2, 3)]
        sdo = []
        for _ in range(500):
            t0 = time.perf_counter()
            nodes[0].sdo.upload(0x6041, 0)
            sdo.append(time.perf_counter() - t0)
        network.nmt.state = "OPERATIONAL"
        time.sleep(0.1)
        got = threading.Semaphore(0)
        for node in nodes:
            network.subscribe(0x180 + node.id, lambda *a: got.release())
        period = 1.0 / args.rate
        late, trips, missed = [], [], 0
        start = time.perf_counter()
        cycles = int(args.seconds * args.rate)
        rpdo = (0x0F).to_bytes(2, "little") + (0).to_bytes(4, "little")
        for k in range(cycles):
            due = start + k * period
            while (now := time.perf_counter()) < due:
                if due - now > 0.0003:
                    time.sleep(due - now - 0.0002)
            late.append(now - due)
            for node in nodes:
                network.send_message(0x200 + node.id, rpdo)
            network.send_message(0x080, b"")
            ok = got.acquire(timeout=period) and got.acquire(timeout=period)
            missed += not ok
            trips.append(time.perf_counter() - now)
        elapsed = time.perf_counter() - start
        network.disconnect()
    finally:
        serve.terminate()
        serve.wait(5)
    wire = 5 * FRAME_BITS / BITRATE
    print(json.dumps({
        "rate_requested_hz": args.rate, "rate_achieved_hz": round(cycles / elapsed, 1),
        "cycles": cycles, "tpdo_missed": missed,
        "lateness_p50_ms": round(percentile(late, 50) * 1e3, 3),
        "lateness_p99_ms": round(percentile(late, 99) * 1e3, 3),
        "cycle_round_trip_p50_ms": round(percentile(trips, 50) * 1e3, 3),
        "cycle_round_trip_p99_ms": round(percentile(trips, 99) * 1e3, 3),
        "wire_time_of_cycle_ms": round(wire * 1e3, 3),
        "round_trip_p50_over_wire": round(percentile(trips, 50) / wire, 2),
        "sdo_round_trip_p50_ms": round(percentile(sdo, 50) * 1e3, 3),
        "sdo_round_trip_p99_ms": round(percentile(sdo, 99) * 1e3, 3),
        "sdo_wire_time_ms": round(2 * FRAME_BITS / BITRATE * 1e3, 3),
    }, indent=1))


if __name__ == "__main__":
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    main()
