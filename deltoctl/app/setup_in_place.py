"""``deltoctl setup --in-place``: the servos found on a bus (IDs unique, but not the
profile's) paired with its joints — as ``--map`` says, then at the joint's ID with its model,
then the only one of a model — and the ID and rate changes ordered so that no two servos ever
share an ID (a temporary free ID where two swap or a chain closes)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from deltoctl.app.setup_rows import step as _step
from deltoctl.errors import InvalidInput, Refused
from deltoctl.servo.addressing import Addresser, Wanted

if TYPE_CHECKING:
    from deltoctl.app.setup import Bus


def match(bus: Bus, found: list[dict[str, Any]], mapping: dict[int, str]
          ) -> tuple[list[tuple[dict[str, Any], Wanted]], list[Wanted]]:
    """Found servos paired with the block's joints: as ``mapping`` says, then at the joint's
    ID with its model, then the only one of a model; ambiguity is InvalidInput (--map), a servo
    that is no joint's or of another model is Refused, as is an ID answering at two rates
    (two servos, which an ID alone cannot tell apart)."""
    _one_rate_per_id(bus, found)
    by_id = {s["id"]: s for s in found}  # one servo per ID, checked above
    pairs = _mapped(bus, by_id, mapping)
    left = [w for w in bus.wanted if w not in pairs.values()]
    for w in list(left):
        servo = by_id.get(w.id)
        if servo is not None and w.id not in pairs and servo["model"] == w.model:
            pairs[w.id] = w
            left.remove(w)
    _by_model(bus, found, pairs, left)
    for device_id, w in pairs.items():
        _same_model(w, by_id[device_id])
    return [(by_id[i], w) for i, w in pairs.items()], [w for w in bus.wanted
                                                        if w not in pairs.values()]


def _one_rate_per_id(bus: Bus, found: list[dict[str, Any]]) -> None:
    rates: dict[int, set[int]] = {}
    for s in found:
        rates.setdefault(s["id"], set()).add(s["baud"])
    for device_id, bauds in sorted(rates.items()):
        if len(bauds) > 1:
            at = " and ".join(str(b) for b in sorted(bauds))
            raise Refused(f"{bus.block}: ID {device_id} answers at {at} baud: two servos "
                          "share the ID: nothing was written",
                          "give one of them another ID alone first (setup JOINT, the "
                          "other unplugged)")


def _mapped(bus: Bus, by_id: dict[int, dict[str, Any]], mapping: dict[int, str]
            ) -> dict[int, Wanted]:
    """The pairs ``--map`` gives for this block's joints; an ID where none answers is
    InvalidInput."""
    joints = {w.joint: w for w in bus.wanted}
    pairs: dict[int, Wanted] = {}
    for device_id, joint in mapping.items():
        if joint not in joints:
            continue
        if device_id not in by_id:
            raise InvalidInput(f"--map {device_id}={joint}: no servo answers at ID {device_id}"
                               f" on {bus.url}")
        pairs[device_id] = joints[joint]
    return pairs


def _same_model(w: Wanted, servo: dict[str, Any]) -> None:
    if (w.model and servo["model"] != w.model) or servo["protocol"] != w.protocol:
        raise Refused(f"{w.joint}: the servo at ID {servo['id']} is a {servo['model']} "
                      f"({servo['protocol']}); the profile says a {w.model or 'servo'} "
                      f"({w.protocol}): nothing was written")


def _by_model(bus: Bus, found: list[dict[str, Any]], pairs: dict[int, Wanted],
              left: list[Wanted]) -> None:
    """The rest paired by model: one servo and one joint of a model go together."""
    loose = [s for s in found if s["id"] not in pairs]
    for model in sorted({s["model"] for s in loose}):
        servos = [s for s in loose if s["model"] == model]
        joints = [w for w in left if w.model in (model, "")]
        if len(servos) == 1 and len(joints) == 1:
            pairs[servos[0]["id"]] = joints[0]
            left.remove(joints[0])
        elif servos and joints:
            ids = ", ".join(str(s["id"]) for s in servos)
            raise InvalidInput(f"{bus.block}: {model} servos at IDs {ids} could be any of "
                               f"{', '.join(w.joint for w in joints)}",
                               hint="say which with --map ID=JOINT (repeatable)")
        else:
            ids = ", ".join(str(s["id"]) for s in servos)
            raise Refused(f"{bus.block}: the {model} at ID {ids} is no joint of the profile: "
                          "setup does not write to it; nothing was written",
                          "disconnect it, or --map ID=JOINT if it is one")


def ordered_steps(bus: Bus, found: list[dict[str, Any]],
                  matched: list[tuple[dict[str, Any], Wanted]]) -> list[dict[str, Any]]:
    """Torque off, then the ID changes in an order where no two servos share an ID (a
    temporary free ID breaks a cycle), then the rates at the new IDs."""
    occupied = {s["id"] for s in found}
    moving = {s["id"]: (s, w) for s, w in matched if (s["id"], s["baud"]) != (w.id, w.baud)}
    pending = {i: w.id for i, (s, w) in moving.items() if i != w.id}
    for i, target in pending.items():
        if target in occupied and target not in pending:
            raise Refused(f"{bus.block}: ID {target}, {moving[i][1].joint}'s, is held by a "
                          "servo that stays: nothing was written")
    steps = [_step(w.joint, "torque off", i, s["baud"]) for i, (s, w) in moving.items()]
    baud_of = {i: s["baud"] for i, (s, _) in moving.items()}
    joint_of = {i: w.joint for i, (_, w) in moving.items()}
    while pending:
        ready = [i for i, t in pending.items() if t not in occupied]
        start = ready[0] if ready else next(iter(pending))
        target = pending[start] if ready else _free_id(bus, occupied)
        steps.append(_step(joint_of[start], "id", start, baud_of[start], target))
        occupied.discard(start)
        occupied.add(target)
        baud_of[target], joint_of[target] = baud_of.pop(start), joint_of.pop(start)
        final = pending.pop(start)
        if target != final:
            pending[target] = final
    return steps + _rate_steps(bus, matched, moving)


def _rate_steps(bus: Bus, matched: list[tuple[dict[str, Any], Wanted]],
                moving: dict[int, tuple[dict[str, Any], Wanted]]) -> list[dict[str, Any]]:
    """The rates, each servo at its new ID: none onto an ID and rate another servo holds."""
    held = {(w.id, s["baud"]) for s, w in matched}  # every servo at its new ID, old rate
    steps = []
    for s, w in moving.values():
        if s["baud"] == w.baud:
            continue
        if (w.id, w.baud) in held:
            raise Refused(f"{bus.block}: ID {w.id} at {w.baud} baud, {w.joint}'s, is held by "
                          "another servo: nothing was written")
        held.discard((w.id, s["baud"]))
        held.add((w.id, w.baud))
        steps.append(_step(w.joint, "baud", w.id, s["baud"], w.baud))
    return steps


def _free_id(bus: Bus, occupied: set[int]) -> int:
    """A temporary ID no servo holds and no joint wants: the highest of the family's range."""
    low, high = bus.family.address_range or (0, 252)
    wanted = {w.id for w in bus.wanted}
    return next(i for i in range(min(high, 252), low, -1)
                if i not in occupied and i not in wanted)


def run_step(port: Any, addresser: Addresser, step: dict[str, Any]) -> None:
    action, at = step["action"], step["at_id"]
    if action == "torque off":
        addresser.prepare(port, at)
    elif action == "id":
        addresser.write_id(port, at, step["value"])
    elif action == "baud":
        addresser.write_baud(port, at, step["value"])
