"""The bus time of a CANopen box of parts: scan, LSS assignment, and canopen's own tools.

Two factory-new drives of the two-axis profile are served on a local hub in this process; on
canopen's own network over it, measured one after the other:

- ``deltoctl scan`` (``scan_link``) of the bus with both drives unconfigured;
- canopen's own ``LssMaster.fast_scan()`` as it comes (a 0.5 s wait for each reply that does
  not come) finding one drive, and ``lss.find_unconfigured`` finding both;
- the setup of both axes from the profile, one drive connected at a time, as ``deltoctl
  setup JOINT`` does it (found, node ID and bit rate given and stored, identity read back over
  SDO);
- ``deltoctl scan`` of the bus with both drives at their node IDs, and canopen's own
  ``network.scanner.search()`` until it has heard both nodes.

    .venv/bin/python plugins/deltoctl-canopen/bench/lss.py [--json]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import time
from collections.abc import Callable
from typing import Any


def timed(work: Callable[[], Any]) -> tuple[float, Any]:
    start = time.perf_counter()
    result = work()
    return round(time.perf_counter() - start, 3), result


def main() -> None:
    import canopen
    from deltoctl.app.setup import open_setup
    from deltoctl.profile.catalog import load_profile
    from deltoctl.sim.controls import Controls
    from deltoctl.sim.serve import ServeOptions, serve_profile

    from deltoctl_canopen import lss
    from deltoctl_canopen.nodes import PROFILES
    from deltoctl_canopen.scan import scan_link
    from deltoctl_canopen.transport import open_bus, parse_can_url

    parser = argparse.ArgumentParser()
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    profile = load_profile(str(PROFILES / "cia402-two-axis.yaml"))
    figures: dict[str, Any] = {}
    with contextlib.ExitStack() as stack:
        controls = Controls()
        url = serve_profile(stack, profile, ServeOptions(factory_new=True),
                            controls=controls)["endpoint"]
        figures["scan, 2 drives without a node ID"] = scan_link(url)["bus_seconds"]
        network = canopen.Network(open_bus(parse_can_url(url)))
        network.connect()
        stack.callback(network.disconnect)
        seconds, (ok, _) = timed(network.lss.fast_scan)
        network.lss.send_switch_state_global(network.lss.WAITING_STATE)
        figures["canopen LssMaster.fast_scan(), 1 drive found"] = seconds if ok else None
        figures["lss.find_unconfigured, 2 drives"] = timed(
            lambda: lss.find_unconfigured(network))[0]
        controls.run("disconnect all")
        total = 0.0
        with open_setup(profile, [f"can0={url}"]) as run:
            for w in run.joints():
                controls.run(f"connect {w.joint}")
                seconds, _ = timed(lambda w=w: run.apply_one(w.joint, run.plan_one(w.joint)))
                figures[f"setup {w.joint} (node {w.id})"] = seconds
                total += seconds
        figures["setup, both axes"] = round(total, 3)
        figures["scan, 2 nodes at their node IDs"] = scan_link(url)["bus_seconds"]
        scanner = network.scanner
        scanner.reset()

        def search() -> None:
            scanner.search()
            while len(scanner.nodes) < 2:
                time.sleep(0.001)

        figures["canopen network.scanner.search(), until both heard"] = timed(search)[0]
    if args.json:
        print(json.dumps(figures))
        return
    for name, value in figures.items():
        print(f"{name:55} {value} s")


if __name__ == "__main__":
    main()
