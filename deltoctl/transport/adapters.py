"""The adapters a robot hangs on, as the kernel and udev lay them out: serial adapters
(/sys/class/tty, /sys/bus/usb-serial, /dev/serial/by-id), CAN interfaces (/sys/class/net, and
``ip -details -json link`` for what only netlink tells) and I2C adapters
(/sys/class/i2c-adapter).

Every path is read under a root: ``/`` on a robot's computer, or the directory that
``DELTOCTL_SYSFS_ROOT`` names (a tree of the same layout, e.g. in tests). Nothing is opened
but sysfs files and directory links; no byte reaches a device.
"""

from __future__ import annotations

import contextlib
import os
import re
from dataclasses import asdict, dataclass, field
from typing import Any

from deltoctl.errors import InvalidInput, Unreachable

ROOT_ENV = "DELTOCTL_SYSFS_ROOT"
ARPHRD_CAN = "280"  # /sys/class/net/*/type of a CAN interface
SYNC_LATENCY_MS = 1  # what ROBOTIS and LeRobot tell users to set an FTDI's latency timer to

# USB IDs of the adapters robot builders hang servo and CAN buses on, each with where it was
# confirmed (the manual's docs/guides/adapters.md lists the same)
KNOWN: dict[tuple[str, str], tuple[str, str]] = {
    ("0403", "6014"): ("FTDI FT232H (ROBOTIS U2D2)", "robot projects' udev rules for the U2D2"),
    ("0403", "6001"): ("FTDI FT232R USB-serial", "public udev rules for FT232R adapters"),
    ("1a86", "55d3"): ("WCH CH343 (Waveshare/Feetech servo boards)",
                       "SO-101 (LeRobot) udev rules for the servo boards"),
    ("1a86", "7523"): ("WCH CH340 (Feetech/serial servo boards)",
                       "robot projects' udev rules for CH340 servo boards"),
    ("10c4", "ea60"): ("Silicon Labs CP210x", "robot projects' udev rules (CP2102 adapters)"),
    ("1d50", "606f"): ("candleLight / CANable (gs_usb)",
                       "python-can's gs_usb docs; Linux gs_usb driver (USB_GSUSB_1_VENDOR_ID)"),
    ("0c72", "000c"): ("PEAK PCAN-USB", "PEAK driver headers (PCAN_USB_PRODUCT_ID 0x000c)"),
    ("0c72", "0012"): ("PEAK PCAN-USB FD", "PEAK driver headers (PCAN_USBFD_PRODUCT_ID 0x0012)"),
}
# rates a driver has been seen to refuse (termios EINVAL), named before a scan iterates into
# them: CDC-ACM adapters (the CH343 boards bind to cdc_acm) refuse 250,000 and 128,000
REFUSED_BAUDS: dict[str, tuple[int, ...]] = {"cdc_acm": (128_000, 250_000)}
# the highest rate a driver's chips set (FTDI H-series: 12 Mbaud; the others 3 Mbaud)
FTDI_HIGH_SPEED = {"6010", "6011", "6014"}


def root() -> str:
    """The root under which sysfs and /dev are read: DELTOCTL_SYSFS_ROOT, or /."""
    return os.environ.get(ROOT_ENV) or "/"


def under(base: str, path: str) -> str:
    return os.path.join(base, path.lstrip("/"))


def _read(path: str) -> str | None:
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            return f.read().strip()
    except OSError:
        return None


def _listdir(path: str) -> list[str]:
    try:
        return sorted(os.listdir(path))
    except OSError:
        return []


# -- serial adapters --------------------------------------------------------------------------

@dataclass
class SerialAdapter:
    device: str  # the node to open: /dev/ttyUSB0 (under the root)
    name: str  # ttyUSB0
    by_id: list[str] = field(default_factory=list)
    by_path: list[str] = field(default_factory=list)
    vid: str | None = None
    pid: str | None = None
    manufacturer: str | None = None
    product: str | None = None
    serial: str | None = None
    driver: str | None = None  # the kernel module bound: ftdi_sio, ch341, cdc_acm, cp210x …
    latency_timer_ms: int | None = None  # FTDI only
    known: str | None = None  # what KNOWN calls it
    max_baud: int | None = None
    refused_bauds: list[int] = field(default_factory=list)
    access: bool = False  # this user may read and write the node
    owner: str | None = None  # user:group mode
    holders: list[str] = field(default_factory=list)

    @property
    def stable(self) -> str:
        """The path that survives a reboot: its /dev/serial/by-id link, else the node."""
        return self.by_id[0] if self.by_id else self.device

    @property
    def usb(self) -> str | None:
        """``usb:VID:PID[:SERIAL]``, the target that names this adapter."""
        if not self.vid or not self.pid:
            return None
        return f"usb:{self.vid}:{self.pid}" + (f":{self.serial}" if self.serial else "")

    def refuses(self, baud: int) -> str | None:
        """Why this adapter's driver cannot run ``baud``; None when it can (as far as known)."""
        if baud in self.refused_bauds:
            return (f"{self.driver} adapters refuse {baud} baud (termios EINVAL): use an FTDI "
                    "or CP210x adapter for that rate")
        if self.max_baud and baud > self.max_baud:
            return f"{self.driver} on this chip sets at most {self.max_baud} baud"
        return None

    def as_dict(self) -> dict[str, Any]:
        return {**asdict(self), "stable": self.stable, "usb": self.usb}


def _usb_ancestor(start: str) -> tuple[str | None, str | None]:
    """(the USB interface, the USB device) above a tty's device directory."""
    interface = device = None
    path = start
    for _ in range(6):
        if interface is None and os.path.exists(os.path.join(path, "bInterfaceNumber")):
            interface = path
        if os.path.exists(os.path.join(path, "idVendor")):
            device = path
            break
        parent = os.path.dirname(path)
        if parent == path:
            break
        path = parent
    return interface, device


def _driver(path: str | None) -> str | None:
    if path is None:
        return None
    link = os.path.join(path, "driver")
    return os.path.basename(os.path.realpath(link)) if os.path.islink(link) else None


def _chain(path: str) -> list[str]:
    """The names a path's links lead through, one link at a time (udev's by-id link names
    ../../ttyUSB0, which may itself be a link, as in a laid-out tree over a pseudo-terminal)."""
    names = [os.path.basename(path)]
    for _ in range(8):
        try:
            target = os.readlink(path)
        except OSError:
            break
        path = os.path.normpath(os.path.join(os.path.dirname(path), target))
        names.append(os.path.basename(path))
    return names


def _links(base: str, folder: str) -> dict[str, list[str]]:
    """tty name → the udev links in /dev/serial/FOLDER that point to it."""
    found: dict[str, list[str]] = {}
    directory = under(base, f"/dev/serial/{folder}")
    for name in _listdir(directory):
        link = os.path.join(directory, name)
        for target in _chain(link)[1:2]:
            found.setdefault(target, []).append(link)
    return found


_LEGACY = re.compile(r"^ttyS\d+$")


def serial_adapters(base: str | None = None, holders: bool = True) -> list[SerialAdapter]:
    """Every USB serial adapter (and on-board UART with a driver of its own, ttySC/ttyAMA) the
    kernel has, with what sysfs and udev tell of it."""
    base = base or root()
    by_id, by_path = _links(base, "by-id"), _links(base, "by-path")
    found = []
    tty = under(base, "/sys/class/tty")
    for name in _listdir(tty):
        dev = os.path.join(tty, name, "device")
        if not os.path.exists(dev):
            continue
        real = os.path.realpath(dev)
        interface, usb = _usb_ancestor(real)
        driver = _driver(interface) or _driver(real)
        if usb is None and (driver in (None, "serial8250", "port") or _LEGACY.match(name)):
            continue  # the PC's legacy UARTs: none is an adapter
        found.append(_adapter(base, name, real, usb, driver, by_id.get(name, []),
                              by_path.get(name, [])))
    if holders and found:
        held = holders_of_each([a.device for a in found])
        for a in found:
            a.holders = held[a.device]
    return found


def _adapter(base: str, name: str, real: str, usb: str | None, driver: str | None,
             by_id: list[str], by_path: list[str]) -> SerialAdapter:
    attr = (lambda key: _read(os.path.join(usb, key))) if usb else (lambda key: None)
    a = SerialAdapter(device=under(base, f"/dev/{name}"), name=name, by_id=by_id,
                      by_path=by_path, vid=attr("idVendor"), pid=attr("idProduct"),
                      manufacturer=attr("manufacturer"), product=attr("product"),
                      serial=attr("serial"), driver=driver)
    latency = _read(os.path.join(real, "latency_timer"))
    a.latency_timer_ms = int(latency) if latency and latency.isdigit() else None
    a.known = KNOWN.get((a.vid or "", a.pid or ""), (None, ""))[0]
    a.refused_bauds = list(REFUSED_BAUDS.get(driver or "", ()))
    if driver == "ftdi_sio":
        a.max_baud = 12_000_000 if a.pid in FTDI_HIGH_SPEED else 3_000_000
    _access(a)
    return a


def _access(a: SerialAdapter) -> None:
    import grp
    import pwd

    try:
        st = os.stat(a.device)
    except OSError:
        return
    a.access = os.access(a.device, os.R_OK | os.W_OK)
    try:
        user = pwd.getpwuid(st.st_uid).pw_name
    except KeyError:
        user = str(st.st_uid)
    try:
        group = grp.getgrgid(st.st_gid).gr_name
    except KeyError:
        group = str(st.st_gid)
    a.owner = f"{user}:{group} {st.st_mode & 0o777:o}"


def adapter_of(path: str, base: str | None = None) -> SerialAdapter | None:
    """The adapter behind a serial path (the node, a by-id link, a symlink), or None."""
    adapters = {a.name: a for a in serial_adapters(base, holders=False)}
    return next((adapters[n] for n in _chain(path) if n in adapters), None)


ENUMERATED = re.compile(r"^tty(USB|ACM)\d+$")  # names the kernel hands out in plug-in order


def stable_targets(url: str, a: SerialAdapter) -> list[str]:
    """The target URLs that name the adapter itself, with the URL's query: its by-id link,
    its usb:VID:PID[:SERIAL]."""
    query = url.partition("?")[2]
    tail = f"?{query}" if query else ""
    return [f"serial://{p}{tail}" for p in a.by_id[:1]] + ([a.usb + tail] if a.usb else [])


# -- usb:VID:PID[:SERIAL] ---------------------------------------------------------------------

_HEX4 = re.compile(r"^[0-9a-fA-F]{4}$")


def parse_usb(spec: str) -> tuple[str, str, str | None]:
    """``usb:VID:PID[:SERIAL]`` → (vid, pid, serial), lower-case hex; InvalidInput else."""
    parts = spec.split(":", 3)
    if len(parts) < 3 or parts[0] != "usb" or not all(map(_HEX4.match, parts[1:3])) \
            or (len(parts) == 4 and not parts[3]):
        raise InvalidInput(f"{spec!r} is not a USB adapter (expected usb:VID:PID[:SERIAL], "
                           "VID and PID four hex digits each, e.g. usb:0403:6014)")
    return parts[1].lower(), parts[2].lower(), parts[3] if len(parts) == 4 else None


def resolve_usb(spec: str, base: str | None = None) -> str:
    """The port of the one adapter ``usb:VID:PID[:SERIAL]`` matches (its by-id link where it
    has one). None matches: Unreachable (exit 4) listing the adapters there are; more than
    one: InvalidInput (exit 2) listing those that match, each with its serial."""
    vid, pid, serial = parse_usb(spec)
    adapters = serial_adapters(base, holders=False)
    matches = [a for a in adapters if a.vid == vid and a.pid == pid
               and (serial is None or a.serial == serial)]
    if len(matches) == 1:
        return matches[0].stable
    if not matches:
        present = "; ".join(_label(a) for a in adapters) or "none"
        raise Unreachable(f"no serial adapter matches {spec} (adapters here: {present})",
                          hint="plug it in, or list them: deltoctl ports")
    raise InvalidInput(f"{spec} matches {len(matches)} adapters: "
                       + "; ".join(_label(a) for a in matches),
                       hint="add the serial number: " + ", ".join(
                           a.usb or a.device for a in matches))


def _label(a: SerialAdapter) -> str:
    return f"{a.device} ({a.usb or 'no USB ID'})"


# -- CAN interfaces ---------------------------------------------------------------------------

@dataclass
class CanInterface:
    name: str
    up: bool
    operstate: str | None = None
    driver: str | None = None
    vid: str | None = None
    pid: str | None = None
    known: str | None = None
    state: str | None = None  # ERROR-ACTIVE, ERROR-PASSIVE, BUS-OFF … (netlink)
    bitrate: int | None = None
    restart_ms: int | None = None
    tx_errors: int | None = None
    rx_errors: int | None = None
    bus_off: int | None = None  # times it went bus-off (netlink's can stats)
    kind: str | None = None  # can, vcan, slcan … (netlink)

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def can_interfaces(base: str | None = None) -> list[CanInterface]:
    """Every CAN network interface: up or down from sysfs; state, bit rate, restart-ms and
    error counters from ``ip -details -json link`` where the ip command is there."""
    base = base or root()
    net = under(base, "/sys/class/net")
    found = []
    for name in _listdir(net):
        folder = os.path.join(net, name)
        if _read(os.path.join(folder, "type")) != ARPHRD_CAN:
            continue
        flags = _read(os.path.join(folder, "flags")) or "0"
        try:
            up = bool(int(flags, 16) & 1)  # IFF_UP
        except ValueError:
            up = False
        real = os.path.realpath(os.path.join(folder, "device"))
        interface, usb = _usb_ancestor(real) if os.path.exists(real) else (None, None)
        vid = _read(os.path.join(usb, "idVendor")) if usb else None
        pid = _read(os.path.join(usb, "idProduct")) if usb else None
        found.append(CanInterface(name, up, _read(os.path.join(folder, "operstate")),
                                  (_driver(interface) or _driver(real)) if usb else None,
                                  vid, pid, KNOWN.get((vid or "", pid or ""), (None, ""))[0]))
    if found:
        details = _ip_details()
        for can in found:
            _add_netlink(can, details.get(can.name, {}))
    return found


def can_interface(name: str, base: str | None = None) -> CanInterface | None:
    return next((c for c in can_interfaces(base) if c.name == name), None)


def _ip_details() -> dict[str, dict[str, Any]]:
    """ifname → its ``ip -details -statistics -json link show`` record; empty where there is
    no ip command."""
    import json
    import shutil
    import subprocess

    ip = shutil.which("ip")
    if ip is None:
        return {}
    try:
        out = subprocess.run([ip, "-details", "-statistics", "-json", "link", "show"],
                             capture_output=True, text=True, timeout=2, check=False).stdout
        records = json.loads(out or "[]")
    except (OSError, ValueError, subprocess.SubprocessError):
        return {}
    return {r["ifname"]: r for r in records if isinstance(r, dict) and "ifname" in r}


def _add_netlink(can: CanInterface, record: dict[str, Any]) -> None:
    info = record.get("linkinfo", {}) if isinstance(record, dict) else {}
    can.kind = info.get("info_kind")
    data = info.get("info_data") or {}
    can.state = data.get("state")
    can.restart_ms = data.get("restart_ms")
    can.bitrate = (data.get("bittiming") or {}).get("bitrate")
    counters = data.get("berr_counter") or {}
    can.tx_errors, can.rx_errors = counters.get("tx"), counters.get("rx")
    can.bus_off = (info.get("info_xstats") or {}).get("bus_off")


def can_fix(name: str, bitrate: int, restart_ms: int = 100) -> str:
    """The commands that bring a CAN interface up at ``bitrate``, restarting itself after a
    bus-off."""
    return (f"sudo ip link set {name} down && sudo ip link set {name} up type can bitrate "
            f"{bitrate} restart-ms {restart_ms}")


# -- I2C adapters -----------------------------------------------------------------------------

def i2c_adapters(base: str | None = None) -> list[dict[str, Any]]:
    """Every I2C adapter: its /dev node, name, and whether the node is there and ours."""
    base = base or root()
    folder = under(base, "/sys/class/i2c-adapter")
    found = []
    for name in _listdir(folder):
        node = under(base, f"/dev/{name}")
        found.append({"name": name, "device": node,
                      "adapter": _read(os.path.join(folder, name, "name")),
                      "present": os.path.exists(node),
                      "access": os.access(node, os.R_OK | os.W_OK)})
    return found


def inventory(base: str | None = None) -> dict[str, Any]:
    """What ``deltoctl ports`` shows: every serial adapter, CAN interface and I2C adapter."""
    return {"serial": [a.as_dict() for a in serial_adapters(base)],
            "can": [c.as_dict() for c in can_interfaces(base)],
            "i2c": i2c_adapters(base)}


# -- the udev rule ----------------------------------------------------------------------------

RULES_FILE = "/etc/udev/rules.d/99-deltoctl.rules"


def udev_rule(adapters: list[tuple[str, SerialAdapter]]) -> str:
    """A udev rule per (name, adapter): a /dev/NAME link that names the adapter by its USB
    ID and serial, and (FTDI) the latency timer at 1 ms whenever it is plugged in."""
    lines = ["# deltoctl: stable names and a 1 ms latency timer for the robot's adapters",
             f"# install: sudo deltoctl doctor --write-udev-rule   (or copy to {RULES_FILE};",
             "# then: sudo udevadm control --reload && sudo udevadm trigger)"]
    for name, a in adapters:
        # every string here but the rule's own words comes from the device (sysfs) or the
        # profile: only safe characters reach the rule, a comment line included
        if not _USB_ID.match(a.vid or "") or not _USB_ID.match(a.pid or ""):
            continue
        match = f'ATTRS{{idVendor}}=="{a.vid}", ATTRS{{idProduct}}=="{a.pid}"'
        if a.serial and _SAFE.match(a.serial):  # a serial udev could not match is left out
            match += f', ATTRS{{serial}}=="{a.serial}"'
        what = _UNSAFE_COMMENT.sub("_", f"{name}: {a.known or a.product or 'USB serial adapter'}"
                                        f" ({a.usb})")
        lines.append(f"# {what}")
        lines.append(f'SUBSYSTEM=="tty", {match}, SYMLINK+="{_SAFE_NAME.sub("_", name)}"')
        if a.driver == "ftdi_sio":
            lines.append(f'ACTION=="add", SUBSYSTEM=="usb-serial", DRIVER=="ftdi_sio", {match}, '
                         f'ATTR{{latency_timer}}="{SYNC_LATENCY_MS}"')
    return "\n".join(lines) + "\n"


_SAFE = re.compile(r"^[A-Za-z0-9_.+-]+\Z")
_USB_ID = re.compile(r"^[0-9a-fA-F]{4}\Z")
_UNSAFE_COMMENT = re.compile(r"[^A-Za-z0-9 _.,:;()/+-]")
_SAFE_NAME = re.compile(r"[^A-Za-z0-9_.+-]")


def latency_fix(a: SerialAdapter, base: str | None = None) -> str:
    """The one-off command that sets the adapter's latency timer to 1 ms."""
    path = under(base or root(), f"/sys/bus/usb-serial/devices/{a.name}/latency_timer")
    return (f"echo {SYNC_LATENCY_MS} | sudo tee {path}   (until it is unplugged; for good: "
            "deltoctl doctor --write-udev-rule)")


def holders_of_each(paths: list[str]) -> dict[str, list[str]]:
    """path → ``PID (name)`` of the processes with it open, from one look through /proc."""
    real = {os.path.realpath(p): p for p in paths}
    found: dict[str, list[str]] = {p: [] for p in paths}
    try:
        pids = [p for p in os.listdir("/proc") if p.isdigit() and int(p) != os.getpid()]
    except OSError:
        return found
    for pid in pids:
        with contextlib.suppress(OSError):
            fds = os.listdir(f"/proc/{pid}/fd")
            held = {real[t] for t in (_target(f"/proc/{pid}/fd/{fd}") for fd in fds)
                    if t in real}
            if held:
                with open(f"/proc/{pid}/comm") as f:
                    name = f.read().strip()
                for path in held:
                    found[path].append(f"{pid} ({name})")
    return found


def _target(link: str) -> str | None:
    try:
        return os.readlink(link)
    except OSError:
        return None
