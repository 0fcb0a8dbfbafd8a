"""The control-table items a profile pins, set by ``deltoctl setup`` once a servo answers at
its ID and rate. A servo joint's params named after its family's items (ROBOTIS'
dynamixel_hardware_interface convention: ``Operating Mode: 5``, a servo gpio's merged in)
are pinned items; its other params are its plugin's. Each pinned value is checked against
the item's documented range and the permission a safety setting needs before setup writes
anything; after the addressing, the items that differ on the servo are written and read back
through ``config restore``'s own plan and writes (deltoctl.app.config), under its rules."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from deltoctl.app import config
from deltoctl.errors import InvalidInput, Refused

ACTION = "item"  # a setup step writing one pinned item

STATUS = {"verified": "set"}  # config restore's word → setup's (as a joint's row says)
Rules = Mapping[str, config.Rule]  # item → documented range and its --allow


def pinned(w: Any, rules: Rules) -> dict[str, int]:
    """The items ``w`` (a Wanted) pins and their values; a value that is not an integer
    within the item's documented range is InvalidInput (exit 2), before anything is written."""
    pins = {}
    for name, text in w.params.items():
        if name not in rules:
            continue  # the plugin's param, not an item
        try:
            value = int(str(text).strip())
        except ValueError:
            raise InvalidInput(f"{w.joint}: the profile pins {name} {text!r}: not an integer: "
                               "nothing was written") from None
        low, high, _ = rules[name]
        if (low is not None and value < low) or (high is not None and value > high):
            raise InvalidInput(f"{w.joint}: the profile pins {name} {value}, outside the item's "
                               f"documented range {_bound(low)}..{_bound(high)}: nothing was "
                               "written")
        pins[name] = value
    return pins


def _bound(value: int | None) -> str:
    return "" if value is None else str(value)


def planned(wanted: Sequence[Any], rules: Mapping[str, Rules],
            allow: Sequence[str]) -> list[dict[str, Any]]:
    """The item steps of ``wanted`` (rules by block), their values not read yet; a pinned
    safety setting whose --allow is not given is Refused (exit 5) here, before anything is
    written."""
    permitted = {config.permission(a) for a in allow}
    steps, needs = [], {}
    for w in wanted:
        for name, value in pinned(w, rules[w.block]).items():
            steps.append(step(w, name, None, value))
            need = rules[w.block][name][2]
            if need and need not in permitted:
                needs.setdefault(need, []).append(f"{w.joint}'s {name}")
    if needs:
        flags = " and ".join(f"--allow {n}" for n in needs)
        what = ", ".join(p for parts in needs.values() for p in parts)
        raise Refused(f"the profile pins {what}: safety setting(s), written only with {flags}: "
                      "nothing was written", f"check the profile's values, then pass {flags}")
    return steps


def step(w: Any, item: str, was: Any, value: int) -> dict[str, Any]:
    """One pinned item of the servo at ``w``'s ID and rate: ``was`` read there (None: not
    yet), ``value`` the profile's."""
    return {"joint": w.joint, "action": ACTION, "at_id": w.id, "at_baud": w.baud,
            "item": item, "from": was, "to": value, "verified": False}


def apply(profile: Any, target: str, block: str, family: str, wanted: Sequence[Any],
          steps: Sequence[dict[str, Any]], allow: Sequence[str]) -> list[dict[str, Any]]:
    """The item ``steps`` of ``wanted``'s servos (on ``block``, a ``family`` block at
    ``target``) read, those that differ written, each read back: the steps with what was
    read (``from``) and ``status`` (already set, verified). A refusal of ``config restore``
    (a permission, torque on) is Refused before any item is written."""
    from deltoctl.app.robot import open_robot

    joints = {w.joint: w for w in wanted}
    mine = [s for s in steps if s["action"] == ACTION and s["joint"] in joints]
    if not mine:
        return []
    values = {(block, s["joint"], s["item"]): config.Value(s["to"]) for s in mine}
    snap = config.Snapshot(str(profile.source or profile.name), profile.name, {block: family},
                           values, {})
    with open_robot(profile, [target], hardware=[block]) as robot:
        _settings_only(mine, config.read_live(robot.system)[0].get(block, {}))
        rows = robot.config_restore(snap, allow)
    by_key = {(r["part"], r["item"]): r for r in rows}
    done = []
    for s in mine:
        row = by_key.get((s["joint"], s["item"]))
        out = step(joints[s["joint"]], s["item"], s["to"] if row is None else row["live"],
                   s["to"])
        out["status"] = "already set" if row is None else STATUS.get(row["status"], row["status"])
        out["verified"] = row is None or row["status"] == "verified"
        done.append(out)
    config.restore_outcome(rows)  # an item not verified: DeviceError (exit 1)
    return done


def _settings_only(steps: Sequence[dict[str, Any]], live: Mapping[str, Any]) -> None:
    """InvalidInput (exit 2, no item written) for a pinned item that is no setting: a reading
    or a command, or one setup sets itself (ID, baud rate)."""
    for s in steps:
        entry = live.get("parts", {}).get(s["joint"], {}).get(s["item"], {})
        if entry.get("state") or entry.get("fixed"):
            raise InvalidInput(f"{s['joint']}: the profile pins {s['item']}, which is not a "
                               "setting setup writes (a reading or a command, or the servo's "
                               "address on its bus): no item was written",
                               hint=f"remove {s['item']} from {s['joint']}'s params")
