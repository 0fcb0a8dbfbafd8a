"""``deltoctl doctor [-p PROFILE]``: what stops a bring-up, found before any byte is sent.

One line per check, ✔ or ✘, and for each ✘ the fix to type: the profile is valid; every bus
has a target; a serial port or I2C bus is there, this user may open it and no process holds
it; a TCP target has a route from this host (a Delto's link-local 169.254.x.x address needs
one on the host too) and accepts a connection. Exit 0 only when every check passes: 2 when
the profile or a target is invalid, 4 when a device cannot be reached or opened.
"""

from __future__ import annotations

import contextlib
import os
from typing import Annotated, Any

import typer

from deltoctl.cli.context import Options, options
from deltoctl.cli.output import emit_json, say
from deltoctl.errors import UNREACHABLE, USAGE, DeltoctlError

SERIAL_GLOBS = ("/dev/ttyUSB*", "/dev/ttyACM*", "/dev/ttySC*", "/dev/ttyAMA*")
LINK_LOCAL = "169.254."


def register(app: typer.Typer) -> None:
    app.command("doctor")(doctor)


def check(name: str, subject: str, ok: bool, detail: str, fix: str | None = None,
          code: int = UNREACHABLE) -> dict[str, Any]:
    """One check's result; ``code`` is the exit code it stands for when it fails."""
    return {"check": name, "subject": subject, "ok": ok, "detail": detail,
            "fix": None if ok else fix, "exit_code": 0 if ok else code}


def doctor(
    ctx: typer.Context,
    timeout: Annotated[float, typer.Option(
        "--timeout", help="Seconds to wait for each TCP target to accept a connection.")] = 1.0,
) -> None:
    """Check the set-up before a bring-up: profile, ports, buses, routes, targets.

    One line per check with the fix to type; exit 0 only when all pass. Without -p: the
    host's serial ports and I2C buses, or the -t URLs."""
    opts = options(ctx)
    results: list[dict[str, Any]] = []
    profile = None
    with contextlib.ExitStack() as stack:
        if opts.profile:
            profile = _profile_check(opts, results)
        targets = _targets(opts, profile, stack, results) if profile else _bare(opts)
        if not opts.profile and not targets:
            results += _host_checks()
        for bus, (url, families) in targets.items():
            results += url_checks(bus, url, families, timeout)
    _render(opts, profile, results)
    failed = [r["exit_code"] for r in results if not r["ok"]]
    if failed:
        raise typer.Exit(USAGE if USAGE in failed else max(failed))


def _render(opts: Options, profile: Any, results: list[dict[str, Any]]) -> None:
    if opts.json:
        emit_json({"profile": getattr(profile, "name", opts.profile),
                   "ok": all(r["ok"] for r in results), "checks": results})
        return
    width = max([len(r["subject"]) for r in results] + [0])
    for r in results:
        say(f"{'✔' if r['ok'] else '✘'} {r['subject']:<{width}}  {r['check']}: {r['detail']}")
        if r["fix"]:
            say(f"  {'':<{width}}  fix: {r['fix']}")
    passed = sum(r["ok"] for r in results)
    say(f"{passed} of {len(results)} checks passed")


# -- the profile and its targets ------------------------------------------------------------

def _profile_check(opts: Options, results: list[dict[str, Any]]) -> Any:
    try:
        prof = opts.load_profile()
    except DeltoctlError as exc:
        results.append(check("profile", str(opts.profile), False, exc.message,
                             f"deltoctl profile validate {opts.profile}", USAGE))
        return None
    c = prof.counts()
    note = f"; {len(prof.warnings)} warning(s)" if prof.warnings else ""
    results.append(check("profile", prof.name, True, f"valid: {c['joints']} joints, "
                         f"{c['sensors']} sensors, {c['gpios']} GPIOs{note}"))
    return prof


def _targets(opts: Options, prof: Any, stack: contextlib.ExitStack,
             results: list[dict[str, Any]]) -> dict[str, tuple[str, set[str]]]:
    """bus → (its URL, the families on it), for the selected blocks that use a transport."""
    from deltoctl import registry
    from deltoctl.core.system import parse_targets, select_blocks

    try:
        blocks = select_blocks(prof, opts.hardware)
        named, bare = parse_targets(prof, opts.target)
        if opts.sim:
            from deltoctl.sim.serve import ServeOptions, serve_profile

            named = serve_profile(stack, prof, ServeOptions(), opts.hardware)["buses"]
    except DeltoctlError as exc:
        results.append(check("targets", prof.name, False, exc.message, None, USAGE))
        return {}
    targets: dict[str, tuple[str, set[str]]] = {}
    for hw in blocks:
        family = registry.of_block(prof.family_of(hw), hw.plugin)
        if family is None or not family.schemes:
            continue  # in-process: nothing to reach
        bus = hw.bus or hw.name
        url = named.get(bus) or (bare[0] if bare else prof.buses.get(bus))
        if not url:
            results.append(check("target", bus, False, f"{hw.name} has no URL",
                                 f"deltoctl -p {prof.name} -t {bus}=URL doctor", USAGE))
            continue
        targets.setdefault(bus, (url, set()))[1].add(family.name)
    return targets


def _bare(opts: Options) -> dict[str, tuple[str, set[str]]]:
    """Targets given without a profile, each checked for itself (named by its bus, or by
    the URL)."""
    targets: dict[str, tuple[str, set[str]]] = {}
    for item in opts.target:
        name, found, url = item.partition("=")
        if not found or "://" in name:
            name, url = item, item
        targets[name] = (url, set())
    return targets


# -- one target -------------------------------------------------------------------------------

def url_checks(bus: str, url: str, families: set[str], timeout: float) -> list[dict[str, Any]]:
    """The checks of one bus's URL, by its scheme."""
    scheme = url.partition("://")[0]
    try:
        if scheme == "tcp":
            from deltoctl.transport.tcp import parse_tcp_url

            host, port = parse_tcp_url(url)
            return [*_route(bus, host, port), _reach(bus, host, port, timeout, families)]
        if scheme == "i2c+tcp":
            from deltoctl.transport.i2c import parse_i2c_url

            _, host, port = parse_i2c_url(url)
            return [_reach(bus, host, port, timeout, families)]
        if scheme == "i2c":
            from deltoctl.transport.i2c import parse_i2c_url

            return device_checks(bus, parse_i2c_url(url)[1], "i2c")
        if scheme == "serial":
            from deltoctl.transport.serial_port import parse_serial_url

            path, _, rs485 = parse_serial_url(url)
            return device_checks(bus, path, "serial") + ([_rs485(bus, path)] if rs485 else [])
    except DeltoctlError as exc:
        return [check("target", bus, False, exc.message, None, USAGE)]
    return [check("target", bus, False, f"{url!r}: unknown scheme {scheme!r}",
                  "use tcp://HOST:PORT, serial:///dev/PORT?baud=N or i2c:///dev/i2c-N", USAGE)]


def source_address(host: str, port: int) -> str:
    """The address of this host a packet to ``host`` would leave from. No packet is sent: a
    UDP socket's connect only asks the routing table."""
    import socket

    family = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)[0][0]
    with socket.socket(family, socket.SOCK_DGRAM) as s:
        s.connect((host, port))
        return str(s.getsockname()[0])


def _route(bus: str, host: str, port: int) -> list[dict[str, Any]]:
    import socket

    try:
        source = source_address(host, port)
    except socket.gaierror as exc:
        return [check("route", bus, False, f"cannot resolve {host}: {exc.strerror}",
                      "check the name, or give the IP address", USAGE)]
    except OSError as exc:
        return [check("route", bus, False, f"no route to {host}: {exc.strerror}",
                      _address_fix(host))]
    if host.startswith(LINK_LOCAL) and not source.startswith(LINK_LOCAL):
        return [check("route", bus, False, f"{host} is link-local, but this host would send "
                      f"from {source}: it has no 169.254.x.x address", _address_fix(host))]
    return [check("route", bus, True, f"to {host} from {source}")]


def _address_fix(host: str) -> str:
    if host.startswith(LINK_LOCAL):
        return ("sudo ip addr add 169.254.186.1/16 dev IFACE   (the port cabled to the "
                "device; or set that connection to 'Link-Local Only' in NetworkManager)")
    return f"ip route get {host}   (then give the cabled interface an address on its subnet)"


def _reach(bus: str, host: str, port: int, timeout: float,
           families: set[str]) -> dict[str, Any]:
    """A TCP connect, closed at once: nothing of the protocol is sent."""
    import socket
    import time

    start = time.perf_counter()
    try:
        socket.create_connection((host, port), timeout=timeout).close()
    except ConnectionRefusedError:
        from deltoctl import registry

        hints = [f.refused_hint for f in map(registry.get, sorted(families))
                 if f is not None and f.refused_hint]
        fix = "; ".join(hints) or f"check that the device listens on port {port}"
        return check("reachable", bus, False, f"{host}:{port} refused the connection", fix)
    except OSError as exc:
        return check("reachable", bus, False, f"no connection to {host}:{port} within "
                     f"{timeout:g} s ({exc.strerror or exc})",
                     f"check power and cable, then: ping {host}")
    ms = (time.perf_counter() - start) * 1e3
    return check("reachable", bus, True, f"{host}:{port} accepts connections ({ms:.1f} ms)")


def device_checks(bus: str, path: str, kind: str) -> list[dict[str, Any]]:
    """A serial port or I2C bus: present, this user may open it, and (serial) no process
    holds it."""
    import stat

    try:
        st = os.stat(path)
    except OSError:
        fix = ("plug the adapter in, then: ls /dev/serial/by-id/" if kind == "serial" else
               "sudo modprobe i2c-dev   (Raspberry Pi: dtparam=i2c_arm=on in config.txt)")
        return [check("present", bus, False, f"{path} does not exist", fix)]
    results = [check("present", bus, stat.S_ISCHR(st.st_mode),
                     f"{path} is {'a' if stat.S_ISCHR(st.st_mode) else 'not a'} device",
                     f"give the {kind} device's path")]
    results.append(_permission(bus, path, st, kind))
    if kind == "serial":
        holders = holders_of(path)
        results.append(check("free", bus, not holders,
                             f"held by {', '.join(holders)}" if holders else "no process holds it",
                             f"close it, or: kill {holders[0].split()[0]}" if holders else None))
    return results


def _permission(bus: str, path: str, st: Any, kind: str) -> dict[str, Any]:
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
    real = os.path.realpath(path)
    found = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        if int(pid) == os.getpid():
            continue
        with contextlib.suppress(OSError):
            fds = os.listdir(f"/proc/{pid}/fd")
            if any(_points_to(f"/proc/{pid}/fd/{fd}", real) for fd in fds):
                with open(f"/proc/{pid}/comm") as f:
                    found.append(f"{pid} ({f.read().strip()})")
    return found


def _points_to(link: str, real: str) -> bool:
    try:
        return os.readlink(link) == real
    except OSError:
        return False


def _rs485(bus: str, path: str) -> dict[str, Any]:
    """The kernel's RS-485 mode of the port (TIOCGRS485), read without sending anything."""
    import fcntl
    import struct

    try:
        fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    except OSError as exc:
        return check("rs485", bus, False, f"cannot open {path}: {exc.strerror}", None)
    try:
        flags = struct.unpack("I", fcntl.ioctl(fd, 0x542E, bytes(32))[:4])[0]
    except OSError:
        return check("rs485", bus, True, "no kernel RS-485 mode on this port: the adapter "
                     "must switch direction itself (most USB adapters do)")
    finally:
        os.close(fd)
    state = "on" if flags & 1 else "off (deltoctl turns it on when it opens the port)"
    return check("rs485", bus, True, f"kernel RS-485 mode {state}")


# -- the host, when no profile is named -------------------------------------------------------

def _host_checks() -> list[dict[str, Any]]:
    import glob

    results = []
    ports = sorted(p for g in SERIAL_GLOBS for p in glob.glob(g))
    if not ports:
        results.append(check("present", "serial", False, "no serial adapter (ttyUSB, ttyACM, "
                             "ttySC, ttyAMA)", "plug the USB/RS-485 adapter in, then: "
                             "ls /dev/serial/by-id/"))
    for port in ports:
        results += device_checks(os.path.basename(port), port, "serial")
    buses = sorted(glob.glob("/dev/i2c-*"))
    if not buses:
        results.append(check("present", "i2c", False, "no I2C bus (/dev/i2c-*)",
                             "sudo modprobe i2c-dev   (Raspberry Pi: dtparam=i2c_arm=on)"))
    for bus in buses:
        results += device_checks(os.path.basename(bus), bus, "i2c")
    return results
