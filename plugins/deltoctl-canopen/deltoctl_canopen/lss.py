"""Layer setting services (CiA 305) on a CAN bus, through canopen's ``LssMaster``: the drives
that have no node ID yet (``find_unconfigured``), a node ID and bit rate given to one by its
LSS address and stored (``assign``), what answers at node IDs (``configured_nodes``), and what
a profile wants of them (``plan``) and which drive is a joint's (``locate``), for ``deltoctl
setup`` (deltoctl_canopen.addressing). Each takes a connected ``canopen.Network``
(``network_at(url)``); none prompts or prints.

canopen's ``fast_scan`` finds the unconfigured drive of lowest LSS address and leaves it in the
configuration state, where a fast scan no longer reaches it: scanning again finds the next one,
and switching every drive back to waiting at the end leaves all as they were. A fast scan waits
for a reply to each of its 132 queries and learns a bit that is 1 from a reply that does not
come, so its time is mostly those waits: here a short one first, and canopen's own when a scan
comes back empty-handed (a reply missed under load is told from no drive left).
"""

from __future__ import annotations

import contextlib
import queue
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any

from deltoctl.errors import DeviceError, InvalidInput, NoAnswer, Refused

from deltoctl_canopen.session import LSS_BITRATES, LSS_FROM_SLAVE, UNCONFIGURED

if TYPE_CHECKING:
    from deltoctl.profile.model import Hardware, Profile

FAST_TIMEOUT = 0.05  # s a fast scan's query waits for a reply, before canopen's own 0.5 s
FIND_WAIT = 0.5  # s to wait for any drive without a node ID to say so (LssMaster's own wait)
BOOT_WAIT = 2.0  # s a drive given a node ID has to answer an SDO read there
MAX_DRIVES = 127
_NON_CONFIGURED = 0x50


@dataclass(frozen=True)
class Identity:
    """A drive's LSS address: its identity object 0x1018:1-4."""

    vendor: int
    product: int
    revision: int
    serial: int

    @property
    def parts(self) -> tuple[int, int, int, int]:
        return (self.vendor, self.product, self.revision, self.serial)

    def as_dict(self) -> dict[str, int]:
        return asdict(self)

    def __str__(self) -> str:
        return (f"vendor {self.vendor:#010x} product {self.product:#010x} "
                f"revision {self.revision:#010x} serial {self.serial:#010x}")


@contextlib.contextmanager
def network_at(url: str) -> Iterator[Any]:
    """canopen's network on the CAN target ``url`` (``can://INTERFACE/CHANNEL``), connected;
    a bus that does not open is Unreachable."""
    import canopen

    from deltoctl_canopen.transport import open_bus, parse_can_url

    network = canopen.Network(open_bus(parse_can_url(url)))
    network.connect()
    try:
        yield network
    finally:
        network.disconnect()


def bit_timing(bitrate: int) -> int:
    """The LSS bit timing index of a bit rate (InvalidInput when the table has none)."""
    for index, rate in LSS_BITRATES.items():
        if rate == bitrate:
            return index
    rates = ", ".join(str(r) for r in LSS_BITRATES.values())
    raise InvalidInput(f"LSS sets no bit rate {bitrate} (it sets {rates})")


# -- finding -----------------------------------------------------------------------------------

def any_unconfigured(network: Any, wait: float = FIND_WAIT) -> bool:
    """Whether a drive without a node ID answers an identify non-configured remote slave."""
    heard: queue.Queue[bytes] = queue.Queue()

    def listen(can_id: int, data: bytes, timestamp: float) -> None:
        heard.put(bytes(data))

    network.subscribe(LSS_FROM_SLAVE, listen)
    try:
        network.lss.send_identify_non_configured_remote_slave()
        deadline = time.monotonic() + wait
        while (left := deadline - time.monotonic()) > 0:
            try:
                if heard.get(timeout=left)[:1] == bytes([_NON_CONFIGURED]):
                    return True
            except queue.Empty:
                break
        return False
    finally:
        network.unsubscribe(LSS_FROM_SLAVE, listen)


def find_unconfigured(network: Any, timeout: float = FAST_TIMEOUT,
                      wait: float = FIND_WAIT) -> list[Identity]:
    """The LSS addresses of the drives on the bus that have no node ID, lowest first; each
    is left as it was (waiting, unconfigured)."""
    if not any_unconfigured(network, wait):
        return []
    lss = network.lss
    own = type(lss).RESPONSE_TIMEOUT
    found: list[Identity] = []
    try:
        while len(found) < MAX_DRIVES:
            lss.RESPONSE_TIMEOUT = timeout
            ok, parts = lss.fast_scan()
            if not ok and timeout < own:
                lss.RESPONSE_TIMEOUT = own
                ok, parts = lss.fast_scan()
            if not ok or Identity(*parts) in found:
                break
            found.append(Identity(*parts))
    finally:
        lss.RESPONSE_TIMEOUT = own
        lss.send_switch_state_global(lss.WAITING_STATE)
    return found


def configured_nodes(network: Any, wait: float = 0.1, bitrate: int = 1_000_000,
                     describe: bool = True) -> dict[int, dict[str, Any]]:
    """The node IDs that answer canopen's scanner (an SDO read of 0x1000 to each of 1-127,
    and whatever node speaks meanwhile), with each one's identity, name and software version
    read over SDO (``describe``)."""
    from deltoctl_canopen.codec import MAX_FRAME_BITS

    scanner = network.scanner
    scanner.reset()
    scanner.search()
    time.sleep(wait + 2 * 127 * MAX_FRAME_BITS / bitrate)
    while True:  # replies still coming: listen on
        count = len(scanner.nodes)
        time.sleep(wait)
        if len(scanner.nodes) == count:
            break
    nodes = sorted(n for n in scanner.nodes if 1 <= n <= 127)
    return {n: _describe(network, n) if describe else {} for n in nodes}


def _describe(network: Any, node_id: int) -> dict[str, Any]:
    identity = read_identity(network, node_id)
    found: dict[str, Any] = {"identity": identity.as_dict() if identity else None}
    for key, index in (("device_name", 0x1008), ("software", 0x100A)):
        raw = _upload(network, node_id, index, 0)
        found[key] = raw.rstrip(b"\0").decode("latin-1") if raw is not None else None
    return found


def _upload(network: Any, node_id: int, index: int, sub: int) -> bytes | None:
    """One SDO upload with canopen's client; None when the node refuses or says nothing."""
    import canopen

    node = network.nodes.get(node_id)
    added = node is None
    if added:
        node = canopen.RemoteNode(node_id, canopen.ObjectDictionary())
        network.add_node(node)
    try:
        return bytes(node.sdo.upload(index, sub))
    except (canopen.SdoAbortedError, canopen.SdoCommunicationError):
        return None
    finally:
        if added:
            del network[node_id]


def read_identity(network: Any, node_id: int) -> Identity | None:
    """A node's 0x1018:1-4 read with canopen's SDO client (None: it does not answer)."""
    parts = []
    for sub in (1, 2, 3, 4):
        raw = _upload(network, node_id, 0x1018, sub)
        if raw is None:
            return None
        parts.append(int.from_bytes(raw[:4], "little"))
    return Identity(*parts)


# -- assigning ---------------------------------------------------------------------------------

def assign(network: Any, identity: Identity, node_id: int, bitrate: int | None = None,
           store: bool = True) -> dict[str, Any]:
    """Give the drive at LSS address ``identity`` (switch state selective: no other drive
    leaves waiting) ``node_id`` (and ``bitrate``, taken at its next power-on) and store them.
    A drive that had no node ID starts at the new one at once, one that had another is reset
    to it; then canopen's SDO client reads its identity at the new node ID. Returns what was
    done."""
    from canopen.lss import LssError

    if not 1 <= node_id <= 127:
        raise InvalidInput(f"node ID {node_id} is not 1-127")
    timing = bit_timing(bitrate) if bitrate is not None else None
    lss = network.lss
    try:
        _select(lss, identity)
        was = lss.inquire_node_id()
        lss.configure_node_id(node_id)
        if timing is not None:
            lss.configure_bit_timing(timing)
        if store:
            lss.store_configuration()
    except LssError as exc:
        raise DeviceError(f"LSS: {exc} (node ID {node_id})",
                          hint="check that the drive is connected and powered") from None
    finally:
        lss.send_switch_state_global(lss.WAITING_STATE)
    if was not in (node_id, UNCONFIGURED):
        network.send_message(0x000, bytes([0x82, was]))  # reset communication: the new ID
    found = _wait_identity(network, node_id)
    if found is None or found != identity:
        raise DeviceError(f"node {node_id}: " + ("no SDO answer after LSS gave it the node ID"
                          if found is None else f"another drive answers ({found})"))
    return {"node_id": node_id, "was": None if was == UNCONFIGURED else was,
            "identity": found.as_dict(), "bitrate": bitrate, "stored": store}


def _select(lss: Any, identity: Identity) -> None:
    from canopen.lss import LssError

    try:
        selected = lss.send_switch_state_selective(*identity.parts)
    except LssError:
        selected = False
    if not selected:
        raise NoAnswer(f"no drive answers at LSS address {identity}",
                       hint="check that it is connected and powered (deltoctl scan lists "
                            "the drives without a node ID)")


def _wait_identity(network: Any, node_id: int) -> Identity | None:
    deadline = time.monotonic() + BOOT_WAIT
    while True:
        found = read_identity(network, node_id)
        if found is not None or time.monotonic() > deadline:
            return found


# -- the profile's plan ------------------------------------------------------------------------

@dataclass(frozen=True)
class Step:
    """One drive to set up: the joint, the node ID and bit rate the profile gives it, and the
    serial that names its drive (None: the drive connected alone)."""

    joint: str
    node_id: int
    bitrate: int
    serial: int | None = None

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def plan(profile: Profile, hw: Hardware) -> list[Step]:
    """The steps of a CANopen block, in the profile's order of its joints."""
    from deltoctl_canopen.nodes import block_nodes, bus_bitrate, joint_serial

    bitrate = bus_bitrate(profile, hw.bus or hw.name)
    joints = {j.name: j for j in hw.joints}
    return [Step(joint, node.node_id, bitrate, joint_serial(profile, joints[joint]))
            for joint, node in block_nodes(profile, hw).items()]


def locate(network: Any, step: Step) -> tuple[Identity, bool]:
    """The drive that is the step's, and whether it answers at its node ID already (with
    its serial, when it names one); else the one without a node ID that has its serial (or
    the only one). Two unnamed drives are Refused, nothing written to them."""
    there = read_identity(network, step.node_id)
    if there is not None and step.serial in (None, there.serial):
        return there, True
    if there is not None:
        raise Refused(f"{step.joint}: node {step.node_id} is taken by the drive with serial "
                      f"{there.serial:#010x}, not {step.serial:#010x}: nothing was written",
                      "give that drive its own node ID first")
    found = find_unconfigured(network)
    chosen = [i for i in found if step.serial in (None, i.serial)]
    if not chosen:
        raise NoAnswer(f"{step.joint}: no drive without a node ID" + (
            f" has serial {step.serial:#010x}" if step.serial is not None else " answers"),
            hint=f"connect {step.joint}'s drive (and power it)")
    if len(chosen) > 1:
        raise Refused(f"{step.joint}: {len(chosen)} drives have no node ID: which is "
                      f"{step.joint}'s is not known: nothing was written",
                      f"connect {step.joint}'s drive alone, or give the joint its drive's "
                      "serial (lss_serial param)")
    return chosen[0], False
