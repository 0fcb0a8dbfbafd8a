"""What ``deltoctl doctor`` checks of a link, before any byte of a protocol is sent: the pieces
each transport's ``checks`` puts together (a device node present, this user may open it, no
process holds it; a route to a TCP host and a connection it accepts).

A check is a dict: check, subject, ok, detail, the fix to type, and the exit code it stands
for when it fails.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, Any

from deltoctl.errors import FAILED, UNREACHABLE, USAGE, WARNINGS
from deltoctl.transport import Check, Target

if TYPE_CHECKING:
    from deltoctl.transport.adapters import SerialAdapter

LINK_LOCAL = "169.254."


def check(name: str, subject: str, ok: bool, detail: str, fix: str | None = None,
          code: int = UNREACHABLE) -> Check:
    """One check's result; ``code`` is the exit code it stands for when it fails."""
    return {"check": name, "subject": subject, "ok": ok, "detail": detail,
            "fix": None if ok else fix, "exit_code": 0 if ok else code}


# -- a TCP host -------------------------------------------------------------------------------

def source_address(host: str, port: int) -> str:
    """The address of this host a packet to ``host`` would leave from. No packet is sent: a
    UDP socket's connect only asks the routing table."""
    import socket

    family = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)[0][0]
    with socket.socket(family, socket.SOCK_DGRAM) as s:
        s.connect((host, port))
        return str(s.getsockname()[0])


def route(bus: str, host: str, port: int) -> Check:
    import socket

    try:
        source = source_address(host, port)
    except socket.gaierror as exc:
        return check("route", bus, False, f"cannot resolve {host}: {exc.strerror}",
                     "check the name, or give the IP address", USAGE)
    except OSError as exc:
        return check("route", bus, False, f"no route to {host}: {exc.strerror}",
                     _address_fix(host))
    if host.startswith(LINK_LOCAL) and not source.startswith(LINK_LOCAL):
        return check("route", bus, False, f"{host} is link-local, but this host would send "
                     f"from {source}: it has no 169.254.x.x address", _address_fix(host))
    return check("route", bus, True, f"to {host} from {source}")


def _address_fix(host: str) -> str:
    if host.startswith(LINK_LOCAL):
        return ("sudo ip addr add 169.254.186.1/16 dev IFACE   (the port cabled to the "
                "device; or set that connection to 'Link-Local Only' in NetworkManager)")
    return f"ip route get {host}   (then give the cabled interface an address on its subnet)"


def reach(target: Target, host: str, port: int) -> Check:
    """A TCP connect, closed at once: nothing of the protocol is sent."""
    import socket
    import time

    bus = target.bus
    start = time.perf_counter()
    try:
        socket.create_connection((host, port), timeout=target.timeout).close()
    except ConnectionRefusedError:
        fix = "; ".join(target.hints) or f"check that the device listens on port {port}"
        return check("reachable", bus, False, f"{host}:{port} refused the connection", fix)
    except OSError as exc:
        return check("reachable", bus, False, f"no connection to {host}:{port} within "
                     f"{target.timeout:g} s ({exc.strerror or exc})",
                     f"check power and cable, then: ping {host}")
    ms = (time.perf_counter() - start) * 1e3
    return check("reachable", bus, True, f"{host}:{port} accepts connections ({ms:.1f} ms)")


# -- a device node ----------------------------------------------------------------------------

def device_checks(bus: str, path: str, kind: str, missing_fix: str,
                  exclusive: bool = False) -> list[Check]:
    """A device node (a serial port, an I2C bus): present, this user may open it, and (a
    port one process holds at a time) no process holds it."""
    import stat

    try:
        st = os.stat(path)
    except OSError:
        return [check("present", bus, False, f"{path} does not exist", missing_fix)]
    results = [check("present", bus, stat.S_ISCHR(st.st_mode),
                     f"{path} is {'a' if stat.S_ISCHR(st.st_mode) else 'not a'} device",
                     f"give the {kind} device's path")]
    results.append(_permission(bus, path, st, kind))
    if exclusive:
        holders = holders_of(path)
        results.append(check("free", bus, not holders,
                             f"held by {', '.join(holders)}" if holders else "no process holds it",
                             f"close it, or: kill {holders[0].split()[0]}" if holders else None))
    return results


def _permission(bus: str, path: str, st: Any, kind: str) -> Check:
    import grp
    import pwd

    user = pwd.getpwuid(os.getuid()).pw_name
    if os.access(path, os.R_OK | os.W_OK):
        return check("permission", bus, True, f"{user} may read and write it")
    try:
        group = grp.getgrgid(st.st_gid).gr_name
    except KeyError:
        group = str(st.st_gid)
    return check("permission", bus, False,
                 f"{user} may not open it (owner {pwd.getpwuid(st.st_uid).pw_name}:{group}, "
                 f"mode {st.st_mode & 0o777:o})",
                 f"sudo usermod -aG {group} {user}   (then log in again; or a udev rule "
                 f"for the {kind} device)")


def holders_of(path: str) -> list[str]:
    """``PID (name)`` of the processes (that this user may see) with ``path`` open."""
    from deltoctl.transport.adapters import holders_of_each

    return holders_of_each([path])[path]


def present_nodes(globs: tuple[str, ...], kind: str, none: str, fix: str,
                  missing_fix: str, exclusive: bool = False) -> list[Check]:
    """The host's device nodes of a kind (doctor with no profile or target), each checked."""
    import glob

    nodes = sorted(p for g in globs for p in glob.glob(g))
    if not nodes:
        return [check("present", kind, False, none, fix)]
    return [c for node in nodes
            for c in device_checks(os.path.basename(node), node, kind, missing_fix, exclusive)]


# -- a serial adapter -------------------------------------------------------------------------

def adapter_checks(target: Target, path: str, adapter: SerialAdapter,
                   baud: int | None) -> list[Check]:
    """What the adapter behind a serial port tells: a name a reboot cannot swap, a rate its
    driver sets, and a latency timer that lets a loop at the asked rate run."""
    results = [_stable(target, path, adapter)]
    if baud is not None:
        why = adapter.refuses(baud)
        results.append(check("baud", target.bus, why is None,
                             why or f"{adapter.driver or 'its driver'} sets {baud} baud",
                             "give the bus a rate the adapter sets, or change the adapter",
                             FAILED))
    if adapter.latency_timer_ms is not None:
        results.append(_latency(target, adapter))
    return results


def _stable(target: Target, path: str, a: SerialAdapter) -> Check:
    from deltoctl.transport.adapters import ENUMERATED, stable_targets

    choices = stable_targets(target.url, a)
    if not ENUMERATED.match(os.path.basename(path)) or not choices:
        return check("stable name", target.bus, True, f"{path}")
    return check("stable name", target.bus, False,
                 f"{path} is named in plug-in order: after a reboot it may be another adapter",
                 "name the adapter instead: " + " or ".join(choices), WARNINGS)


def _latency(target: Target, a: SerialAdapter) -> Check:
    from deltoctl.transport.adapters import SYNC_LATENCY_MS, latency_fix

    ms = a.latency_timer_ms or 0
    if ms <= SYNC_LATENCY_MS:
        return check("latency timer", target.bus, True, f"{ms} ms")
    limit = (f"the adapter holds each short reply up to {ms} ms: a loop that waits for one "
             f"reply a cycle runs at most ~{1000 / ms:.0f} Hz")
    if not target.rate_hz:
        return check("latency timer", target.bus, True, f"{ms} ms: {limit} (a sync loop "
                     f"needs {SYNC_LATENCY_MS} ms: deltoctl doctor --udev-rule)")
    share = min(ms * target.rate_hz / 1000, 1.0)
    return check("latency timer", target.bus, False,
                 f"{ms} ms: {limit}, and waits up to {share:.0%} of each cycle of the "
                 f"{target.rate_hz:g} Hz loop on this bus", latency_fix(a), FAILED)
