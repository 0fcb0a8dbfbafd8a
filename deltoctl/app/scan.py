"""``deltoctl scan``: what answers on a serial link, at every rate and in every protocol the
installed servo families speak, with no profile. Each family declares its probes (its
descriptor's ``scan``); they run in one order: the common rates first (1 Mbps, 57,600), every
broadcast before any per-ID sweep. Unless ``every`` is asked, the scan stops at the first
servo found, a sweep's too (a box of parts is one servo at a time, at the factory's ID first) —
a sweep runs only once no broadcast found one. The bus time is the time spent on the link.
A link of another kind (a URL whose scheme a family's ``link_scan`` takes: a CAN bus) is
that family's to scan, reported alike."""

from __future__ import annotations

import time
from typing import Any

from deltoctl import registry
from deltoctl.errors import InvalidInput, Unreachable

COMMON = (1_000_000, 57_600)


def target_of(port_or_url: str) -> str:
    """A serial URL from a port path or a serial URL; anything else is a usage error."""
    from deltoctl.transport.serial_port import parse_serial_url

    url = f"serial://{port_or_url}" if port_or_url.startswith("/") else port_or_url
    if url.startswith("usb:") or url.startswith("serial:"):
        parse_serial_url(url)
        return url
    others = sorted({f"{scheme}://" for f in registry.families().values() if f.link_scan
                     for scheme in f.schemes})
    raise InvalidInput(f"{port_or_url!r} is not a link scan takes: a port (/dev/ttyUSB0), a "
                       f"serial:// or usb: target{''.join(', ' + o for o in others)}")


def link_scanner(port_or_url: str) -> Any:
    """The scan of the family whose link the URL names (its scheme), or None."""
    scheme, sep, _ = port_or_url.partition("://")
    if not sep:
        return None
    for family in registry.families().values():
        found = family.link_scanner(scheme)
        if found is not None:
            return found
    return None


def ordered(probes: list[Any]) -> list[Any]:
    """Broadcasts, then a PING to the factory's ID, then sweeps of every ID; in each, the
    common rates first, then the faster."""
    def key(p: Any) -> tuple:
        common = COMMON.index(p.baud) if p.baud in COMMON else len(COMMON)
        return (p.stage, common, -p.baud)
    return sorted(probes, key=key)


def scan(port_or_url: str, wait: float = 0.01, every: bool = False) -> dict[str, Any]:
    """Run the probes of every installed family on the link: the servos found, the probes
    run, the rates the adapter refused, the bus time (s)."""
    from deltoctl.transport.serial_port import open_serial

    other = link_scanner(port_or_url)
    if other is not None:
        return other(port_or_url, wait, every)
    url = target_of(port_or_url)
    probes = all_probes()
    port = open_serial(url, timeout=0.002)
    start = time.perf_counter()
    try:
        found, refused, ran = run_probes(port, probes, wait, every)
    finally:
        port.close()
    seconds = time.perf_counter() - start
    if not found:
        raise Unreachable(f"nothing answers on {url} ({ran} probes, {seconds:.3f} s)",
                          hint="check the power and the wiring (GND, data), then scan again")
    return {"target": url, "servos": found, "probes": ran, "of": len(probes),
            "refused_bauds": sorted(set(refused)), "bus_seconds": round(seconds, 3),
            "colliding": sorted({f["id"] for f in found if f["colliding"] and
                                 f["id"] is not None})}


def all_probes() -> list[Any]:
    """Every installed family's probes, in the order they run."""
    probes = ordered([p for f in registry.families().values() for p in f.scan_probes()])
    if not probes:
        raise InvalidInput("no installed family scans a serial link")
    return probes


def run_probes(port: Any, probes: list[Any], wait: float,
               every: bool) -> tuple[list[dict[str, Any]], list[int], int]:
    """The probes on an open port (its rate set for each): what answered, the rates the
    adapter refused, how many probes ran. Unless ``every``, up to the first that answers."""
    found: list[dict[str, Any]] = []
    refused: list[int] = []
    ran = 0
    for probe in probes:
        if found and not every:
            break
        try:
            port.baudrate = probe.baud
        except (OSError, ValueError):
            refused.append(probe.baud)
            continue
        ran += 1
        found += [f for f in (s.as_dict() for s in probe.run(port, wait, not every))
                  if f["id"] is None or f not in found]
    return found, refused, ran
