"""``deltoctl setup`` on a link of a family's own (a CAN bus): each joint's part found through
the family's ``link_setup`` (deltoctl.core.link_setup) — by the serial the profile names, or
the one part without an address —, planned, then given the profile's address and rate, stored,
and verified at the new address. A part that cannot be told from another is refused with
nothing written; one at its address already is left as it is."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from deltoctl import registry
from deltoctl.app.setup_rows import Outcome, row, step, verified
from deltoctl.core.link_setup import LinkAddressing, LinkJoint
from deltoctl.errors import InvalidInput


@dataclass
class LinkBus:
    """A block on a link its family sets up: its target, the family's link addressing and
    what each joint wants."""

    block: str
    bus: str
    family: registry.Family
    url: str
    addressing: LinkAddressing
    wanted: list[LinkJoint]


def addressed_blocks(profile: Any, buses: Mapping[str, str], hardware: Sequence[str],
                     pick: Callable[[registry.Family], Any]
                     ) -> Iterator[tuple[Any, str, registry.Family, str, Any]]:
    """The selected blocks whose family's ``pick`` gives an addressing (a servo family's
    ``addressing()``, a link's ``link_addressing()``): each with its bus's name, its family,
    its target URL (``buses``', else the profile's) and that addressing."""
    from deltoctl.core.system import select_blocks

    for hw in select_blocks(profile, list(hardware)):
        family = registry.of_block(profile.family_of(hw), hw.plugin)
        addressing = pick(family) if family is not None else None
        if addressing is None:
            continue
        name = hw.bus or hw.name
        url = buses.get(name) or profile.buses.get(name)
        if not url:
            raise InvalidInput(f"{hw.name}: no target for bus {name!r}",
                               hint=f"give one: -t {name}=URL")
        yield hw, name, family, url, addressing


def link_buses(profile: Any, buses: Mapping[str, str], hardware: Sequence[str]
               ) -> list[LinkBus]:
    """The selected blocks whose family sets up the parts of their link."""
    return [LinkBus(hw.name, name, family, url, addressing, addressing.joints(profile, hw))
            for hw, name, family, url, addressing in addressed_blocks(
                profile, buses, hardware, lambda f: f.link_addressing())]


def plan_one(link: Any, bus: LinkBus, w: LinkJoint) -> Outcome:
    """What setting up ``w``'s part writes (nothing when it answers at its address)."""
    found = bus.addressing.locate(link, w)
    outcome = Outcome("one at a time", True, [row(w, found, "planned")])
    if found["id"] != w.id:
        outcome.steps.append(step(w.joint, "id", found["id"], found["baud"], w.id))
    if found["baud"] != w.baud:  # the link's rate: the new one is taken at the next power-on
        outcome.steps.append(step(w.joint, "bit rate", w.id, found["baud"], w.baud))
    if outcome.steps:
        outcome.steps.append(step(w.joint, "store", w.id, found["baud"], w.baud))
    return outcome


def apply_one(link: Any, bus: LinkBus, w: LinkJoint, plan: Outcome) -> Outcome:
    """The plan of ``plan_one`` written, then verified at the new address."""
    done = Outcome("one at a time", False, [dict(plan.joints[0])], plan.steps)
    found = done.joints[0]["from"]
    if plan.steps:
        bus.addressing.assign(link, w, found)
    verified(done.joints[0], w, bus.addressing.identify(link, w), found["model"])
    return done


def connect_lines(bus: LinkBus, w: LinkJoint) -> list[str]:
    """The control lines a rehearsal runs so that ``w``'s part is the one without an address
    on the link: the later joints' parts pulled out (unless a serial names each), its own
    plugged in; the parts set up before it may stay, they answer at their addresses."""
    later = bus.wanted[bus.wanted.index(w) + 1:]
    lines = [f"disconnect {o.joint}" for o in later] if w.serial is None else []
    return [*lines, f"connect {w.joint}"]
