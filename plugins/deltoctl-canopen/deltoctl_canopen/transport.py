"""``can://INTERFACE/CHANNEL?bitrate=N`` targets: any python-can interface by name.

    can://socketcan/can0?bitrate=1000000     a SocketCAN interface (the bitrate is set by ip link)
    can://virtual/bench                      python-can's in-process bus
    can://udp_multicast/239.74.163.2         python-can's UDP multicast bus
    can://localhub/127.0.0.1:40123           the local hub the emulator serves (this machine only)

A URL is untrusted input: the interface must be one python-can knows, the query holds only
``bitrate`` (a CAN rate) — nothing else reaches ``can.Bus``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from deltoctl.errors import InvalidInput, Unreachable
from deltoctl.transport import Transport

SCHEME = "can"
BITRATES = (10_000, 20_000, 50_000, 100_000, 125_000, 250_000, 500_000, 800_000, 1_000_000)
DEFAULT_BITRATE = 1_000_000
QUERY_KEYS = ("bitrate",)


@dataclass(frozen=True)
class CanTarget:
    interface: str
    channel: str
    bitrate: int = DEFAULT_BITRATE
    bitrate_given: bool = False

    @property
    def url(self) -> str:
        return f"{SCHEME}://{self.interface}/{self.channel}?bitrate={self.bitrate}"


def parse_can_url(url: str) -> CanTarget:
    from urllib.parse import parse_qs

    from deltoctl.transport import split_url

    parts = split_url(url)
    if parts.scheme != SCHEME or not parts.netloc:
        raise InvalidInput(f"{url!r}: a CAN target is can://INTERFACE/CHANNEL (e.g. "
                           "can://socketcan/can0?bitrate=1000000)")
    interface, channel = parts.netloc, parts.path.lstrip("/")
    if not channel:
        raise InvalidInput(f"{url!r}: no channel (can://{interface}/CHANNEL)")
    known = _interfaces()
    if interface not in known:
        from deltoctl.suggest import did_you_mean

        raise InvalidInput(f"{url!r}: python-can has no interface {interface!r}"
                           f"{did_you_mean(interface, known)}")
    try:
        query = parse_qs(parts.query, strict_parsing=bool(parts.query))
    except ValueError:
        raise InvalidInput(f"{url!r}: the query is KEY=VALUE&…") from None
    unknown = sorted(set(query) - set(QUERY_KEYS))
    if unknown:
        raise InvalidInput(f"{url!r}: unknown option {', '.join(unknown)} "
                           f"(a CAN target takes: {', '.join(QUERY_KEYS)})")
    bitrate, given = DEFAULT_BITRATE, "bitrate" in query
    if given:
        text = query["bitrate"][-1]
        if not text.isdigit() or int(text) not in BITRATES:
            rates = ", ".join(str(b) for b in BITRATES)
            raise InvalidInput(f"{url!r}: bitrate {text!r} is not a CANopen bit rate ({rates})")
        bitrate = int(text)
    if interface == "localhub":
        from deltoctl_canopen.hub import loopback_address

        try:
            loopback_address(channel)
        except ValueError as exc:
            raise InvalidInput(f"{url!r}: {exc}") from None
    return CanTarget(interface, channel, bitrate, given)


def _interfaces() -> list[str]:
    from can.interfaces import VALID_INTERFACES

    return sorted(VALID_INTERFACES)


def open_bus(target: CanTarget) -> Any:
    """A python-can bus for the target; one that cannot be opened is Unreachable (exit 4)."""
    import can

    kwargs: dict[str, Any] = {"interface": target.interface, "channel": target.channel}
    if target.bitrate_given and target.interface not in ("socketcan", "virtual", "localhub",
                                                         "udp_multicast"):
        kwargs["bitrate"] = target.bitrate  # those set no rate of their own
    try:
        return can.Bus(**kwargs)
    except (can.CanError, OSError, ValueError, ImportError) as exc:
        raise Unreachable(f"cannot open {target.url}: {exc}",
                          hint="check the interface (ip link show) and the channel") from None


def open_link(url: str, **options: Any) -> Any:
    return open_bus(parse_can_url(url))


def _checks(target: Any) -> list[dict[str, Any]]:
    """doctor: the URL, the interface present (SocketCAN: the network interface, up, at the
    target's bit rate and not bus-off), and a bus that opens."""
    from deltoctl.errors import DeltoctlError
    from deltoctl.transport.doctor import check

    try:
        parsed = parse_can_url(target.url)
    except DeltoctlError as exc:
        return [check("can bus", target.bus, False, exc.message, None, exc.exit_code)]
    if parsed.interface == "socketcan":
        problem = _interface_problem(target.bus, parsed)
        if problem is not None:
            return [problem]
    try:
        open_bus(parsed).shutdown()
    except DeltoctlError as exc:
        return [check("can bus", target.bus, False, exc.message, exc.hint)]
    return [check("can bus", target.bus, True, f"{parsed.interface} bus {parsed.channel} opens")]


def _interface_problem(bus: str, parsed: CanTarget) -> dict[str, Any] | None:
    """What keeps a SocketCAN interface from running the target's bus, with the command that
    brings it up at the target's rate; None when nothing does (as far as sysfs and netlink
    tell)."""
    from deltoctl.errors import FAILED
    from deltoctl.transport.adapters import can_fix, can_interface
    from deltoctl.transport.doctor import check

    name, rate = parsed.channel, parsed.bitrate
    found = can_interface(name)
    fix = can_fix(name, rate)
    if found is None:
        return check("can bus", bus, False, f"no network interface {name}",
                     f"plug the adapter in (deltoctl ports lists them), then: {fix}")
    virtual = found.kind == "vcan"
    if not found.up:
        return check("can bus", bus, False, f"{name} is down",
                     f"sudo ip link set {name} up" if virtual else fix)
    if found.state == "BUS-OFF":
        return check("can bus", bus, False, f"{name} is bus-off (tx errors {found.tx_errors})",
                     f"check the bit rate, termination and wiring, then: {fix}", FAILED)
    if not virtual and parsed.bitrate_given and found.bitrate and found.bitrate != rate:
        return check("can bus", bus, False, f"{name} runs at {found.bitrate} bit/s, the "
                     f"target at {rate}", fix, FAILED)
    return None


TRANSPORT = Transport(SCHEME, "can://INTERFACE/CHANNEL?bitrate=N", parse_can_url, open_link,
                      _checks)
