"""``deltoctl scan can://…``: the CANopen nodes on a bus and the drives without a node ID.

The nodes: canopen's scanner (an SDO read of 0x1000 to each node ID 1-127, answered or aborted
by every node there, about 30 ms of frames at 1 Mbit/s), then each one's identity, name and
software version read over SDO. The drives with no node ID: LSS identify non-configured remote
slave, and when one answers, LSS fast scans for their addresses (``lss.find_unconfigured``).
"""

from __future__ import annotations

import time
from typing import Any

from deltoctl.errors import Unreachable

PROTOCOL, LSS_PROTOCOL = "CANopen", "CANopen LSS (no node ID)"
MIN_WAIT = 0.05  # s: what an SDO reply takes on any bus, at least, to be waited for


def scan_link(url: str, wait: float = MIN_WAIT, every: bool = False) -> dict[str, Any]:
    """What answers on the CAN bus ``url``, as ``deltoctl scan`` reports it (both searches
    run whatever ``every`` says: neither stops at a first node)."""
    from deltoctl_canopen import lss
    from deltoctl_canopen.transport import parse_can_url

    target = parse_can_url(url)
    with lss.network_at(url) as network:
        start = time.perf_counter()
        nodes = lss.configured_nodes(network, max(wait, MIN_WAIT), target.bitrate)
        unconfigured = lss.find_unconfigured(network, wait=max(wait, lss.FIND_WAIT))
        seconds = time.perf_counter() - start
    found = [_node(n, info, target.bitrate) for n, info in nodes.items()] + \
        [_unconfigured(i, target.bitrate) for i in unconfigured]
    if not found:
        raise Unreachable(f"nothing answers on {target.url} ({seconds:.3f} s)",
                          hint="check the power, the wiring and termination, and the bit rate "
                               "(?bitrate=…), then scan again")
    return {"target": target.url, "servos": found, "probes": 2, "of": 2, "refused_bauds": [],
            "bus_seconds": round(seconds, 3), "colliding": []}


def _node(node_id: int, info: dict[str, Any], bitrate: int) -> dict[str, Any]:
    identity = info.get("identity") or {}
    model = info.get("device_name") or (f"product {identity['product']:#010x}"
                                        if identity else "")
    return {"id": node_id, "model": model, "firmware": info.get("software") or "",
            "baud": bitrate, "protocol": PROTOCOL, "colliding": False, "identity": identity}


def _unconfigured(identity: Any, bitrate: int) -> dict[str, Any]:
    return {"id": None, "model": f"product {identity.product:#010x} serial "
                                 f"{identity.serial:#010x}",
            "firmware": f"revision {identity.revision:#010x}", "baud": bitrate,
            "protocol": LSS_PROTOCOL, "colliding": False, "identity": identity.as_dict()}
