"""A loop's achieved rate against what its serial adapters' latency timers allow: an FTDI
adapter holds a short reply until its latency timer runs out (16 ms unless set), so a loop that
waits for one reply per cycle cannot run faster than one cycle per timer."""

from __future__ import annotations

from collections.abc import Iterable

SHORTFALL = 0.9  # a loop below this share of its asked rate is looked into


def loop_warnings(urls: Iterable[str], asked_hz: float, real_hz: float) -> list[str]:
    """One warning per serial adapter whose latency timer explains a loop that ran below its
    asked rate; none when the loop kept up or no timer is to blame."""
    if not asked_hz or real_hz >= SHORTFALL * asked_hz:
        return []
    from deltoctl.transport.adapters import SYNC_LATENCY_MS, latency_fix
    from deltoctl.transport.serial_port import adapter_of_target

    found = []
    for url in sorted(set(urls)):
        adapter = adapter_of_target(url)
        ms = adapter.latency_timer_ms if adapter is not None else None
        if adapter is None or ms is None or ms <= SYNC_LATENCY_MS or 1000 / ms >= asked_hz:
            continue
        found.append(f"the loop ran at {real_hz:g} Hz of {asked_hz:g} asked: the latency "
                     f"timer of {adapter.device} ({ms} ms) holds each reply, which allows at "
                     f"most ~{1000 / ms:.0f} Hz; set it to {SYNC_LATENCY_MS} ms: "
                     f"{latency_fix(adapter)}")
    return found
