"""``deltoctl setup``: the servos of a profile's buses given the IDs and rates the profile
says, as a procedure — planned, confirmed by the caller, applied, verified at the new
settings. Bus-level: no System is opened (a box of new parts answers at no joint's ID).

- *One at a time* (new servos, all at the factory's ID): the part connected alone is found at
  any rate and protocol (the scan's probes), its model checked against the joint's, then torque
  off, ID (once the target ID is free at both rates), rate (the family's exchanges,
  deltoctl.servo.addressing), verified at the new ID and rate by a PING, a model read and a
  present-position read (alike servos at one ID garble it). Colliding replies or two servos
  answering: refused, named, nothing written.
- *In place* (IDs unique but not the profile's): the servos found on the bus matched to joints
  (same ID and model, one of a model, or as the caller maps them), the ID changes ordered so no
  two servos ever share an ID (a temporary free ID where two swap or a chain closes), then the
  rates, then verified.

Once a servo answers at its ID and rate, the items its joint's params pin (Operating Mode …)
are read, written where they differ and read back, under ``config restore``'s rules
(deltoctl.app.setup_items); their values and permissions are checked before anything is
written. A servo no joint of the profile is, or an ID no joint has, is never written. The bus
time is the time spent on the links.

A block on a link of a family's own (CANopen drives on a CAN bus: node IDs by LSS) is set up
one joint at a time through its family's ``link_setup`` (deltoctl.app.setup_link); the rows
and steps are of the same shape (deltoctl.app.setup_rows), the in-place pairing and ordering
of servos is deltoctl.app.setup_in_place."""

from __future__ import annotations

import contextlib
import functools
import re
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from deltoctl import registry
from deltoctl.app import setup_items, setup_link
from deltoctl.app.setup_in_place import match, ordered_steps, run_step
from deltoctl.app.setup_link import LinkBus, addressed_blocks, connect_lines, link_buses
from deltoctl.app.setup_rows import Outcome
from deltoctl.app.setup_rows import row as _row
from deltoctl.app.setup_rows import step as _step
from deltoctl.app.setup_rows import verified as _verified
from deltoctl.core.link_setup import LinkJoint
from deltoctl.errors import DeviceError, InvalidInput, Refused, Unreachable
from deltoctl.servo.addressing import Addresser, Addressing, Wanted, free_wait

WAIT = 0.01  # s a probe waits for a reply
FACTORY_RESET = "factory-reset"  # the --allow a factory reset needs


def _timed(method: Callable[..., Outcome]) -> Callable[..., Outcome]:
    """A procedure of Setup whose outcome carries the bus time spent so far."""
    @functools.wraps(method)
    def run(self: Setup, *args: Any, **kwargs: Any) -> Outcome:
        outcome = method(self, *args, **kwargs)
        outcome.bus_seconds = self.bus_seconds
        return outcome

    return run


@dataclass
class Bus:
    """A servo bus block: its target, its family's addressing, what each joint wants."""

    block: str
    bus: str  # the profile's name of the bus
    family: registry.Family
    url: str
    addressing: Addressing
    wanted: list[Wanted]


class Setup:
    """The servo buses of a profile (``buses``: bus → target URL), and the procedures on
    them; ``controls``: the control lines of simulators this process serves (a rehearsal
    connects each part itself)."""

    def __init__(self, profile: Any, buses: Mapping[str, str], hardware: Sequence[str] = (),
                 controls: Any = None, wait: float = WAIT, allow: Sequence[str] = ()) -> None:
        self.profile, self.controls, self.wait, self.allow = profile, controls, wait, allow
        self.buses = _servo_buses(profile, buses, hardware)
        self.links = link_buses(profile, buses, hardware)
        self.bus_seconds = 0.0
        if not self.buses and not self.links:
            raise InvalidInput(f"{profile.name} has no servo bus that setup addresses "
                               "(Dynamixel, Feetech), nor a CANopen bus (node IDs by LSS)")
        # each servo block's item rules: what its joints' params pin (deltoctl.app.setup_items)
        self.rules = {b.block: b.family.config_rule_table() for b in self.buses}

    def item_steps(self, wanted: Sequence[Wanted]) -> list[dict[str, Any]]:
        """The items ``wanted`` pin, unread; a value out of range (exit 2) or a safety setting
        without its --allow (exit 5) refused before anything is written."""
        return setup_items.planned(wanted, self.rules, self.allow)

    def _set_items(self, bus: Bus, wanted: Sequence[Wanted],
                   steps: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
        """The pinned items of ``wanted``'s servos, addressed now: read, written where they
        differ, read back (the bus time of the robot's opening counted)."""
        start = time.perf_counter()
        try:
            return setup_items.apply(self.profile, f"{bus.bus}={bus.url}", bus.block,
                                     bus.family.name, wanted, steps, self.allow)
        finally:
            self.bus_seconds += time.perf_counter() - start

    # -- what the profile wants --------------------------------------------------------------
    def targets(self) -> list[str]:
        """``BUS=URL`` of each servo bus (open_robot's targets, once the servos are set)."""
        return [f"{b.bus}={b.url}" for b in [*self.buses, *self.links]]

    def joints(self) -> list[Wanted | LinkJoint]:
        return [w for bus in [*self.buses, *self.links] for w in bus.wanted]

    def _bus_of(self, joint: str) -> tuple[Bus, Wanted]:
        for bus in self.buses:
            for w in bus.wanted:
                if w.joint == joint:
                    return bus, w
        if any(w.joint == joint for link in self.links for w in link.wanted):
            raise InvalidInput(f"{joint}: a CANopen drive's joint: not a servo's")
        names = ", ".join(w.joint for w in self.joints())
        raise InvalidInput(f"no servo joint {joint!r} in {self.profile.name} (its servo joints: "
                           f"{names}); setup writes only where the profile says")

    def _link_of(self, joint: str) -> tuple[LinkBus, LinkJoint] | None:
        return next(((bus, w) for bus in self.links for w in bus.wanted if w.joint == joint),
                    None)

    def connect_alone(self, joint: str) -> str | None:
        """On this process's simulators, the joint's part made the one to set up (a servo
        alone on the wire; a drive plugged in, the later ones pulled out): the reply; None
        without them."""
        link = self._link_of(joint)
        lines = [f"connect {joint}"] if link is None else connect_lines(*link)
        if link is None:
            self._bus_of(joint)  # one of the profile's servo joints, or InvalidInput
        if self.controls is None or "connect" not in self.controls.words():
            return None
        return [str(self.controls.run(line)) for line in lines][-1]

    def asks_to_connect(self, w: Wanted | LinkJoint) -> bool:
        """Whether ``w``'s part must be connected for its turn (no serial names it)."""
        return getattr(w, "serial", None) is None

    def ask_line(self, joint: str) -> str:
        """What a person is asked before ``joint``'s turn."""
        if self._link_of(joint) is None:
            return f"connect {joint} alone, then Enter: "
        return f"connect {joint}'s drive (those set up may stay connected), then Enter: "

    @contextlib.contextmanager
    def _link(self, bus: LinkBus) -> Iterator[Any]:
        """The link opened; the time it is in use counted (not its opening and closing)."""
        with bus.addressing.open(bus.url) as link:
            start = time.perf_counter()
            try:
                yield link
            finally:
                self.bus_seconds += time.perf_counter() - start

    @contextlib.contextmanager
    def _port(self, url: str, baud: int | None = None) -> Iterator[Any]:
        from deltoctl.transport.serial_port import open_serial

        port = open_serial(url, timeout=0.002)
        start = time.perf_counter()
        try:
            if baud is not None:
                port.baudrate = baud
            yield port
        finally:
            self.bus_seconds += time.perf_counter() - start
            port.close()

    # -- one at a time -----------------------------------------------------------------------
    def find(self, joint: str, walked: Sequence[str] | None = None) -> dict[str, Any]:
        """The one servo connected (the joint's, alone), at any rate and protocol (the
        joint's protocol first, in the scan's order); Refused when replies collide, several
        answer, its model is not the joint's or it answers where another joint's is set up
        (``walked``: the joints a walk has set up, None outside one); Unreachable when nothing
        answers."""
        from deltoctl.app.scan import all_probes, run_probes

        bus, w = self._bus_of(joint)
        probes = sorted(all_probes(), key=lambda p: p.protocol != w.protocol)  # its own first
        with self._port(bus.url) as port:
            found, _, ran = run_probes(port, probes, self.wait, False)
        if not found:
            raise Unreachable(f"{joint}: nothing answers on {bus.url} ({ran} probes)",
                              hint=f"connect {joint}'s servo alone, power it, and run setup "
                                   f"{joint} again")
        _alone(joint, found)
        servo = found[0]
        if servo["protocol"] != w.protocol or (w.model and servo["model"] != w.model):
            raise Refused(f"{joint}: the servo connected is a {servo['model'] or 'servo'} "
                          f"({servo['protocol']}) at ID {servo['id']}; the profile says "
                          f"{joint} is a {w.model or 'servo'} ({w.protocol}): nothing was "
                          "written", f"connect {joint}'s own servo alone")
        self._not_another(w, servo, walked)
        return servo

    def _not_another(self, w: Wanted, servo: dict[str, Any],
                     walked: Sequence[str] | None) -> None:
        """Refused when the servo found answers where another joint's is set up: that
        joint's servo, left connected. Where that is the factory's address too, a new servo
        answers there as well: only a walk, which sets such joints up last, tells them apart
        (the other joint not set up yet: a new one)."""
        at = (servo["id"], servo["baud"])
        other = next((o for o in self.joints() if o.joint != w.joint and (o.id, o.baud) == at
                      and o.protocol == servo["protocol"]), None)
        if other is None:
            return
        if not self._at_factory(other):
            raise Refused(f"{w.joint}: the servo connected answers at ID {at[0]}, {at[1]} "
                          f"baud: {other.joint}'s, set up already: nothing was written",
                          f"unplug {other.joint}'s servo and connect {w.joint}'s alone (a "
                          "servo given the wrong joint's ID: setup --in-place --map ID=JOINT)")
        if walked is None or other.joint in walked:
            raise Refused(f"{w.joint}: the servo connected answers at ID {at[0]}, {at[1]} "
                          f"baud, the factory's and {other.joint}'s: a new servo or "
                          f"{other.joint}'s is not known: nothing was written",
                          f"run setup (each joint in turn, {other.joint} last), or give a new "
                          f"servo alone {w.joint}'s ID with setup --in-place --map "
                          f"{at[0]}={w.joint}")

    def _at_factory(self, w: Wanted | LinkJoint) -> bool:
        """Whether a servo joint's ID and rate are where its protocol's new servos answer."""
        if self._link_of(w.joint) is not None:
            return False
        addresser = self._bus_of(w.joint)[0].addressing.addresser(w.protocol)
        return addresser is not None and (w.id, w.baud) in addresser.factory

    def factory_last(self) -> str | None:
        """What a walk says of the joints it sets up last (None: no such joint)."""
        last = [w.joint for w in self.joints() if self._at_factory(w)]
        if not last:
            return None
        return (f"{', '.join(last)} last: {'its' if len(last) == 1 else 'their'} ID and rate "
                "are the factory's, where each new servo answers")

    def walk_order(self) -> list[Wanted | LinkJoint]:
        """The joints in the profile's order, those whose ID and rate are the factory's last
        (until then a servo there is a new one)."""
        return sorted(self.joints(), key=self._at_factory)

    def _target_free(self, bus: Bus, addresser: Addresser, w: Wanted,
                     servo: dict[str, Any]) -> None:
        """Refused when a servo answers at the joint's ID at the found servo's rate or at the
        joint's (a probe may ask the factory's ID only: one there already is unseen)."""
        rates = [b for b in dict.fromkeys((servo["baud"], w.baud))
                 if (w.id, b) != (servo["id"], servo["baud"])]
        with self._port(bus.url) as port:
            for baud in rates:
                port.baudrate = baud
                try:
                    model = addresser.identify(port, w.id, free_wait(baud) + self.wait)
                except DeviceError:  # several answer: their replies garble
                    model = "servo"
                if model is not None:
                    raise Refused(f"{w.joint}: a servo answers at ID {w.id}, {baud} baud ({model}),"
                                  f" where {w.joint}'s is to go: nothing was written",
                                  f"unplug it (or give it another ID), connect {w.joint}'s "
                                  f"servo alone, then run setup {w.joint} again")

    @_timed
    def plan_one(self, joint: str, reset: str | None = None,
                 walked: Sequence[str] | None = None) -> Outcome:
        """What setting up ``joint``'s servo (connected alone) or drive writes (``walked``:
        see ``find``); nothing is written."""
        link = self._link_of(joint)
        if link is not None:
            return self._plan_link(*link, reset)
        bus, w = self._bus_of(joint)
        addresser = self._addresser(bus, w.protocol)
        if reset is not None:
            _check_reset(bus, addresser, reset)
        servo = self.find(joint, walked)
        self._target_free(bus, addresser, w, servo)
        outcome = Outcome("one at a time", True)
        outcome.joints.append(_row(w, servo, "planned"))
        outcome.steps += _one_steps(w, servo, reset) + self.item_steps([w])
        return outcome

    @_timed
    def apply_one(self, joint: str, plan: Outcome) -> Outcome:
        """Write the plan of ``plan_one`` and verify; the outcome with each joint's status."""
        link = self._link_of(joint)
        if link is not None:
            with self._link(link[0]) as opened:
                done = setup_link.apply_one(opened, *link, plan)
            return done
        bus, w = self._bus_of(joint)
        addresser = self._addresser(bus, w.protocol)
        row = plan.joints[0]
        at_id, at_baud = row["from"]["id"], row["from"]["baud"]
        reset = next((s["value"] for s in plan.steps if s["action"] == "factory reset"), None)
        if reset is not None:
            with self._port(bus.url, at_baud) as port:
                addresser.factory_reset(port, at_id, reset)
            time.sleep(0.05)  # the servo restarts with its factory settings
            servo = self.find(joint, ())  # the servo reset, at the factory's address
            at_id, at_baud = servo["id"], servo["baud"]
        with self._port(bus.url, at_baud) as port:
            _address(port, addresser, at_id, at_baud, w)
            model = addresser.identify(port, w.id)
        done = Outcome("one at a time", False, [dict(row)], _addressing(plan.steps))
        _verified(done.joints[0], w, model, row["from"]["model"])
        done.steps += self._set_items(bus, [w], plan.steps)
        return done

    def _plan_link(self, bus: LinkBus, w: LinkJoint, reset: str | None) -> Outcome:
        if reset is not None:
            raise InvalidInput(f"{bus.block}: {bus.family.name} drives: no factory reset")
        with self._link(bus) as opened:
            outcome = setup_link.plan_one(opened, bus, w)
        return outcome

    def check_reset(self, reset: str | None) -> None:
        """InvalidInput unless every joint's servo can take the factory reset ``reset``."""
        if reset is None:
            return
        for bus in self.buses:
            for protocol in dict.fromkeys(w.protocol for w in bus.wanted):
                _check_reset(bus, self._addresser(bus, protocol), reset)
        for link in self.links:
            raise InvalidInput(f"{link.block}: {link.family.name} drives: no factory reset")

    def wanted_plan(self) -> Outcome:
        """What a walk of every joint will set, before any servo is found."""
        order = self.walk_order()
        return Outcome("one at a time", True, [_row(w, None, "planned") for w in order],
                       self.item_steps([w for w in order if isinstance(w, Wanted)]))

    @_timed
    def walk(self, connect: Callable[[Any, str | None], None], reset: str | None = None,
             done: Callable[[dict[str, Any]], None] | None = None) -> Outcome:
        """Every joint in the walk's order (``walk_order``): ``connect(wanted, reply)`` once
        its part is to be connected (``reply``: this process's simulators connected it, else
        None; not for a part its serial names, all connected at once), then set up and
        verified (``done`` told each joint's row)."""
        self.check_reset(reset)
        outcome = Outcome("one at a time", False)
        walked: list[str] = []
        for w in self.walk_order():
            if self.asks_to_connect(w):
                connect(w, self.connect_alone(w.joint))
            one = self.apply_one(w.joint, self.plan_one(w.joint, reset, walked))
            walked.append(w.joint)
            outcome.joints += one.joints
            outcome.steps += one.steps
            if done is not None:
                done(one.joints[0])
        return outcome

    def _addresser(self, bus: Bus, protocol: str) -> Addresser:
        addresser = bus.addressing.addresser(protocol)
        if addresser is None:
            raise InvalidInput(f"{bus.block}: {bus.family.name} servos do not speak {protocol}")
        return addresser

    # -- in place ----------------------------------------------------------------------------
    @_timed
    def plan_in_place(self, mapping: Mapping[int, str] = ()) -> Outcome:
        """Every servo bus scanned, its servos matched to joints (``mapping``: ID → joint
        where the match is ambiguous), and the ID and rate changes ordered without two servos
        ever at one ID; nothing is written."""
        mapping = dict(mapping)
        if not self.buses:
            raise InvalidInput(f"{self.profile.name}: --in-place readdresses servos; its "
                               "drives are set up by setup (or setup JOINT)")
        for device_id, joint in mapping.items():
            low, high = self._bus_of(joint)[0].family.address_range or (0, 252)
            if not low <= device_id <= high:
                raise InvalidInput(f"--map {device_id}={joint}: ID {device_id} is not "
                                   f"{low}-{high}")
        outcome = Outcome("in place", True)
        for bus in self.buses:
            found = self._scan_bus(bus)
            matched, missing = match(bus, found, mapping)
            for servo, w in matched:
                outcome.joints.append(_row(w, servo, "planned"))
            for w in missing:
                outcome.joints.append(_row(w, None, "missing"))
            outcome.steps += ordered_steps(bus, found, matched)
            outcome.steps += self.item_steps([w for _, w in matched])
        order = [w.joint for w in self.joints()]
        outcome.joints.sort(key=lambda r: order.index(r["joint"]))  # the profile's order
        unknown = set(mapping.values()) - {r["joint"] for r in outcome.joints}
        if unknown:
            raise InvalidInput(f"--map names {', '.join(sorted(unknown))}: no such servo "
                               "joint in the profile")
        return outcome

    def _scan_bus(self, bus: Bus) -> list[dict[str, Any]]:
        """Every servo of the block's protocols on its bus: a broadcast at every rate, a
        sweep (where there is no broadcast) at the profile's rate only."""
        from deltoctl.app.scan import run_probes
        from deltoctl.servo.scan import BROADCAST, SWEEP

        wanted = {(w.protocol, w.baud) for w in bus.wanted}
        protocols = {p for p, _ in wanted}
        probes = [p for p in bus.family.scan_probes() if p.protocol in protocols and (
            p.stage == BROADCAST or (p.stage == SWEEP and (p.protocol, p.baud) in wanted))]
        with self._port(bus.url) as port:
            found, _, _ = run_probes(port, probes, self.wait, True)
        if not found:
            raise Unreachable(f"{bus.block}: nothing answers on {bus.url}",
                              hint="check the power and the wiring, then run setup again")
        colliding = [s for s in found if s["colliding"]]
        if colliding:
            raise Refused(_collision(bus.block, colliding) + ": nothing was written",
                          "give them IDs of their own one at a time first (setup JOINT, "
                          "each servo connected alone)")
        return found

    @_timed
    def apply_in_place(self, plan: Outcome) -> Outcome:
        """Write the plan of ``plan_in_place`` (torque off first, IDs, then rates, the EEPROM
        locked again last), then verify every joint at its new ID and rate."""
        done = Outcome("in place", False, [dict(r) for r in plan.joints],
                       _addressing(plan.steps))
        for bus in self.buses:
            rows = [r for r in done.joints if r["block"] == bus.block and r["from"]]
            steps = [s for s in done.steps if s["joint"] in {r["joint"] for r in rows}]
            self._apply_bus(bus, rows, steps)
        for bus in self.buses:
            present = {r["joint"] for r in done.joints if r["verified"]}
            done.steps += self._set_items(bus, [w for w in bus.wanted if w.joint in present],
                                          plan.steps)
        return done

    def _apply_bus(self, bus: Bus, rows: list[dict[str, Any]],
                   steps: list[dict[str, Any]]) -> None:
        by_joint = {w.joint: w for w in bus.wanted}
        addressers = {r["joint"]: self._addresser(bus, r["from"]["protocol"]) for r in rows}
        with self._port(bus.url) as port:
            for step in steps:
                port.baudrate = step["at_baud"]
                run_step(port, addressers[step["joint"]], step)
            for row in rows:
                w = by_joint[row["joint"]]
                port.baudrate = w.baud
                if any(s["joint"] == w.joint for s in steps):
                    addressers[w.joint].finish(port, w.id)
                model = addressers[w.joint].identify(port, w.id)
                _verified(row, w, model, row["from"]["model"])


# -- helpers: the buses ----------------------------------------------------------------------

def _servo_buses(profile: Any, buses: Mapping[str, str], hardware: Sequence[str]) -> list[Bus]:
    """The selected blocks whose family addresses servos; each joint's rate is the profile's
    bus URL's (the target's where the profile has none)."""
    return [Bus(hw.name, name, family, url, addressing,
                addressing.wanted(profile, hw, profile.buses.get(name) or url))
            for hw, name, family, url, addressing in addressed_blocks(
                profile, buses, hardware, lambda f: f.addressing())]


def _alone(joint: str, found: list[dict[str, Any]]) -> None:
    """Refused (nothing written) unless one servo answered, cleanly."""
    colliding = [s for s in found if s["colliding"]]
    if colliding:
        raise Refused(_collision(joint, colliding) + ": nothing was written",
                      f"connect {joint}'s servo alone (the others unplugged), then run setup "
                      f"{joint} again")
    if len(found) > 1:
        ids = ", ".join(f"ID {s['id']} ({s['model']})" for s in found)
        raise Refused(f"{joint}: several servos answer ({ids}): nothing was written",
                      f"connect {joint}'s servo alone, then run setup {joint} again")


def _collision(where: str, colliding: list[dict[str, Any]]) -> str:
    at = sorted({f"ID {s['id']}" if s["id"] is not None else "an unknown ID" for s in colliding})
    first = colliding[0]
    return (f"{where}: several servos answer at {', '.join(at)} ({first['protocol']}, "
            f"{first['baud']} baud): their replies collide")


def _check_reset(bus: Bus, addresser: Addresser, option: str) -> None:
    if not addresser.reset_options:
        raise InvalidInput(f"{bus.block}: {bus.addressing.no_reset or 'no factory reset'}")
    if option not in addresser.reset_options:
        raise InvalidInput(f"{bus.block}: {addresser.protocol} factory reset takes "
                           f"{', '.join(addresser.reset_options)}, not {option!r}")


def _addressing(steps: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """The steps that address servos (the pinned items' are set once they are addressed)."""
    return [s for s in steps if s["action"] != setup_items.ACTION]


def _one_steps(w: Wanted, servo: dict[str, Any], reset: str | None) -> list[dict[str, Any]]:
    at_id, at_baud = servo["id"], servo["baud"]
    steps = [_step(w.joint, "factory reset", at_id, at_baud, reset)] if reset else []
    if reset or servo["id"] != w.id or servo["baud"] != w.baud:
        steps.append(_step(w.joint, "torque off", at_id, at_baud))
    if reset or servo["id"] != w.id:
        steps.append(_step(w.joint, "id", at_id, at_baud, w.id))
    if reset or servo["baud"] != w.baud:
        steps.append(_step(w.joint, "baud", w.id, at_baud, w.baud))
    return steps


def _address(port: Any, addresser: Addresser, at_id: int, at_baud: int, w: Wanted) -> None:
    """Torque off, ID, rate, EEPROM locked: the servo at (at_id, at_baud) to (w.id, w.baud)."""
    if (at_id, at_baud) == (w.id, w.baud):
        return
    addresser.prepare(port, at_id)
    if at_id != w.id:
        addresser.write_id(port, at_id, w.id)
    if at_baud != w.baud:
        addresser.write_baud(port, w.id, w.baud)
        port.baudrate = w.baud
    addresser.finish(port, w.id)


# -- opening ---------------------------------------------------------------------------------

def target_map(profile: Any, targets: Sequence[str]) -> dict[str, str]:
    """``BUS=URL`` items (or one URL, for a profile of one bus) → {bus: URL}; the names are
    checked as every verb checks them (deltoctl.core.system.parse_targets)."""
    from deltoctl.core.system import parse_targets

    out, bare = parse_targets(profile, list(targets))
    for item in bare:
        if len(profile.buses) != 1:
            raise InvalidInput(f"target {item!r}: name its bus, BUS=URL (buses: "
                               f"{', '.join(profile.buses)})")
        out[next(iter(profile.buses))] = item
    return out


@contextlib.contextmanager
def open_setup(profile: Any, targets: Sequence[str] = (), *,
               sim: bool | Mapping[str, Any] = False, hardware: Sequence[str] = (),
               reuse: bool = False, notice: Callable[[str], None] | None = None,
               warn: Callable[[str], None] | None = None, wait: float = WAIT,
               allow: Sequence[str] = ()) -> Iterator[Setup]:
    """The profile's servo buses ready for setup: at ``targets``, or with ``sim`` on
    simulators this process serves (their control lines then connect each part) or, with
    ``reuse``, on the ``sim serve`` of this profile running for the user; ``allow``: the
    permissions the pinned items' safety settings need (``config restore``'s)."""
    from deltoctl.app.robot import load, serve_simulators
    from deltoctl.sim import running
    from deltoctl.sim.controls import Controls

    prof = load(profile)
    buses = target_map(prof, targets)
    faults = sim if isinstance(sim, Mapping) else {}
    found = running.find(prof, faults, hardware, warn or _quiet) if sim and reuse else None
    controls = None
    with contextlib.ExitStack() as stack:
        if found is not None:
            (notice or _quiet)(f"using {found.name} of {found.profile}; --sim-fresh starts "
                               "one of its own")
            buses.update(target_map(prof, found.targets))
        elif sim:
            controls = Controls()
            blocks = [hw.name for hw in prof.hardware if not hardware or hw.name in hardware]
            buses.update(serve_simulators(stack, prof, blocks, faults, controls))
        yield Setup(prof, buses, hardware, controls, wait, allow)


def _quiet(message: str) -> None:
    pass


def reset_allowed(option: str | None, allow: Sequence[str]) -> None:
    """A factory reset is written only with --allow factory-reset (Refused else); the other
    --allow names are config restore's permissions (for the pinned items)."""
    if option is not None and FACTORY_RESET not in allow:
        raise Refused(f"a factory reset ({option}) erases the servo's settings: not without "
                      f"--allow {FACTORY_RESET}", f"pass --allow {FACTORY_RESET} to reset it")
    from deltoctl.app.config import permission, permission_names

    names = [FACTORY_RESET, *permission_names()]
    unknown = [a for a in allow if permission(a) not in names]
    if unknown:
        raise InvalidInput(f"--allow {unknown[0]!r}: setup permits {FACTORY_RESET} and the "
                           "permissions of config restore (deltoctl config restore --help)")


def parse_map(items: Sequence[str]) -> dict[int, str]:
    """``ID=JOINT`` items → {ID: joint}; another form is InvalidInput naming it."""
    out: dict[int, str] = {}
    for item in items:
        text, sep, joint = item.partition("=")
        if not sep or not re.fullmatch(r"[0-9]{1,4}", text.strip()) or not joint.strip():
            raise InvalidInput(f"--map {item!r}: expected ID=JOINT, e.g. --map 3=elbow_flex")
        if int(text) in out:
            raise InvalidInput(f"--map: ID {int(text)} is mapped twice")
        out[int(text)] = joint.strip()
    return out
