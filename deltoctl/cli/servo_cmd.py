"""Servo bus verbs: ``torque on|off [JOINT|GROUP]``, ``reboot [JOINT|GROUP]`` and
``register get|set JOINT [ITEM [VALUE]]`` (the control table by name)."""

from typing import Annotated, Any

import typer

from deltoctl.cli.context import options
from deltoctl.cli.device_cmd import open_session
from deltoctl.cli.output import emit_json, say, table
from deltoctl.errors import DeviceError, InvalidInput

# groups that gather other groups (MH5's torque_control)
NESTED = {"arms": ("left_arm", "right_arm"), "legs": ("left_leg", "right_leg")}

TargetArg = Annotated[str, typer.Argument(
    help="A joint, a group (head, left_arm, right_arm, arms, left_leg, right_leg, legs) "
         "or all.")]


def select_joints(profile: Any, target: str) -> list[str]:
    joints = [j for j in profile.joints() if profile.family_of(
        next(h for h in profile.hardware if j in h.joints)) == "dynamixel"]
    if not joints:
        raise InvalidInput(f"{profile.name} has no servo joints")
    if target == "all":
        return [j.name for j in joints]
    groups = set(NESTED.get(target, (target,)))
    chosen = [j.name for j in joints if j.name == target or j.params.get("group") in groups]
    if not chosen:
        known = sorted({j.params.get("group", "") for j in joints} | set(NESTED) - {""})
        raise InvalidInput(f"{target!r} is neither a joint nor a group of {profile.name} "
                           f"(groups: {', '.join(known)}, all)")
    return chosen


def register(root: typer.Typer) -> None:
    root.command("torque")(torque)
    root.command("reboot")(reboot)
    registers = typer.Typer(help="Read and write a servo's control table by item name.",
                            no_args_is_help=True)
    registers.command("get")(register_get)
    registers.command("set")(register_set)
    root.add_typer(registers, name="register")


def _item(name: str):  # type: ignore[no-untyped-def]
    """A control table item by name (any case; spaces, - or _) or by address."""
    from deltoctl.families.dynamixel.control_table import XL430

    key = name.lower().replace("_", " ").replace("-", " ")
    for item in XL430:
        if item.name.lower() == key or (name.isdigit() and item.address == int(name)):
            return item
    raise InvalidInput(f"no control table item {name!r} (e.g. return_delay_time, "
                       "present_temperature, goal_position, or an address)")


def _servo(session: Any, joint: str):  # type: ignore[no-untyped-def]
    if session.driver.family != "dynamixel":
        raise InvalidInput("register is for servo buses (the dynamixel family)")
    return session.driver.servo(joint)


JointArg = Annotated[str, typer.Argument(help="The servo's joint.")]


def register_get(
    ctx: typer.Context,
    joint: JointArg,
    items: Annotated[list[str] | None, typer.Argument(
        help="Items to read (default: the whole table, in one read).")] = None,
) -> None:
    """Read control table items of one servo."""
    from deltoctl.families.dynamixel.control_table import XL430

    opts = options(ctx)
    chosen = [_item(i) for i in items or []]
    with open_session(opts) as session:
        bus, device_id = _servo(session, joint)
        if chosen:
            values = {i.name: bus.read_register(device_id, i) for i in chosen}
        else:
            table_bytes = bus.read_table(device_id)
            chosen = list(XL430)
            values = {i.name: int.from_bytes(table_bytes[i.address:i.address + i.size],
                                             "little", signed=i.signed) for i in chosen}
    if opts.json:
        emit_json({"joint": joint, "id": device_id, "values": values})
    else:
        table(f"{joint} (ID {device_id})", ["address", "item", "value", "access"],
              [[i.address, i.name, values[i.name], ("EEPROM " if i.eeprom else "RAM ") +
                i.access] for i in chosen])


def register_set(
    ctx: typer.Context,
    joint: JointArg,
    item: Annotated[str, typer.Argument(help="The item, e.g. return_delay_time.")],
    value: Annotated[int, typer.Argument(help="The raw value.")],
) -> None:
    """Write one control table item and read it back (asks first: a write can move)."""
    from deltoctl.cli.motion_cmd import confirm_motion

    opts = options(ctx)
    chosen = _item(item)
    if chosen.access != "RW":
        raise InvalidInput(f"{chosen.name} is read-only")
    confirm_motion(opts, f"write {chosen.name} = {value} to {joint}")
    with open_session(opts) as session:
        bus, device_id = _servo(session, joint)
        bus.write_register(device_id, chosen, value)
        after = bus.read_register(device_id, chosen)
    if after != value:
        raise DeviceError(f"{chosen.name} reads back {after} after writing {value}")
    _report(opts, {"joint": joint, "id": device_id, "item": chosen.name, "value": after},
            f"{joint}: {chosen.name} = {after}")


def torque(
    ctx: typer.Context,
    state: Annotated[str, typer.Argument(help="on or off.")],
    target: TargetArg = "all",
) -> None:
    """Switch servo torque on or off for a joint or a group."""
    from deltoctl.cli.motion_cmd import confirm_motion

    opts = options(ctx)
    if state not in ("on", "off"):
        raise InvalidInput(f"state must be on or off, got {state!r}")
    profile = opts.load_profile()
    joints = select_joints(profile, target)
    if state == "on":
        confirm_motion(opts, f"torque on for {len(joints)} joint(s): they hold their position")
    with open_session(opts, profile=profile) as session:
        if session.driver.family != "dynamixel":
            raise InvalidInput("torque is for servo buses (the dynamixel family)")
        done = session.driver.set_torque(joints, state == "on")
    _report(opts, {"torque": state, "joints": done}, f"torque {state}: {len(done)} joint(s)")


def reboot(ctx: typer.Context, target: TargetArg = "all") -> None:
    """Reboot servos (clears a shutdown after a hardware error; torque comes back off)."""
    opts = options(ctx)
    profile = opts.load_profile()
    joints = select_joints(profile, target)
    with open_session(opts, profile=profile) as session:
        if session.driver.family != "dynamixel":
            raise InvalidInput("reboot is for servo buses (the dynamixel family)")
        done = session.driver.reboot(joints)
    _report(opts, {"rebooted": done}, f"rebooted {len(done)} of {len(joints)} joint(s)")
    missing = sorted(set(joints) - set(done))
    if missing:
        raise DeviceError(f"no reboot acknowledgement from {', '.join(missing)}")


def _report(opts: Any, data: dict, text: str) -> None:
    if opts.json:
        emit_json(data)
    elif not opts.quiet:
        say(text)
