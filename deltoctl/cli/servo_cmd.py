"""Servo bus verbs: ``torque on|off [JOINT|GROUP]``, ``reboot [JOINT|GROUP]`` and
``register get|set JOINT [ITEM [VALUE]]`` (the control table by name)."""

from typing import Annotated, Any

import typer

from deltoctl.cli.context import options
from deltoctl.cli.device_cmd import finish, open_robot
from deltoctl.cli.output import emit_json, say, table
from deltoctl.errors import DeviceError, InvalidInput

# groups that gather other groups (MH5's torque_control)
NESTED = {"arms": ("left_arm", "right_arm"), "legs": ("left_leg", "right_leg")}


def _complete_target(ctx: typer.Context, incomplete: str) -> list[str]:
    """The profile's joint groups (their ``group`` param, and arms/legs), all, and joints."""
    from deltoctl.cli.profile_cmd import _completion_profile

    prof = _completion_profile(ctx)
    if prof is None:
        return []
    joints = list(prof.joints())
    groups = {str(j.params["group"]) for j in joints if j.params.get("group")}
    groups |= {name for name, halves in NESTED.items() if set(halves) <= groups}
    names = [*sorted(groups), "all", *(j.name for j in joints)]
    return [n for n in names if n.startswith(incomplete)]


def _complete_state(incomplete: str) -> list[str]:
    return [s for s in ("on", "off") if s.startswith(incomplete)]


def _complete_item(ctx: typer.Context, incomplete: str) -> list[str]:
    from deltoctl.cli.profile_cmd import complete_register_items

    return complete_register_items(ctx, incomplete)


TargetArg = Annotated[str, typer.Argument(
    autocompletion=_complete_target,
    help="A joint, a group (head, left_arm, right_arm, arms, left_leg, right_leg, legs) "
         "or all.")]


def select_joints(profile: Any, target: str, capability: str) -> list[str]:
    """The joints of the blocks that offer ``capability`` named by a joint, a group (the
    joints' ``group`` param, and arms/legs) or ``all``."""
    from deltoctl import registry

    def offers(hw: Any) -> bool:
        family = registry.of_block(profile.family_of(hw), hw.plugin)
        return family is not None and capability in family.capabilities

    joints = [j for hw in profile.hardware if offers(hw) for j in hw.joints]
    if not joints:
        raise InvalidInput(f"{profile.name} has no joints with {capability}")
    if target == "all":
        return [j.name for j in joints]
    groups = set(NESTED.get(target, (target,)))
    chosen = [j.name for j in joints if j.name == target or j.params.get("group") in groups]
    if not chosen:
        from deltoctl.suggest import did_you_mean

        known = sorted({j.params.get("group", "") for j in joints} | set(NESTED) - {""})
        near = did_you_mean(target, [*known, "all", *(j.name for j in joints)])
        groups = f" (groups: {', '.join(known)}, all)"
        raise InvalidInput(f"{target!r} is neither a joint nor a group of {profile.name}"
                           + (near or groups))
    return chosen


def register(root: typer.Typer) -> None:
    root.command("torque")(torque)
    root.command("reboot")(reboot)
    registers = typer.Typer(help="Read and write a servo's control table by item name.",
                            no_args_is_help=True)
    registers.command("get")(register_get)
    registers.command("set")(register_set)
    root.add_typer(registers, name="register")


def _complete_joint(ctx: typer.Context, incomplete: str) -> list[str]:
    from deltoctl.cli.profile_cmd import complete_part

    return complete_part(ctx, incomplete)


JointArg = Annotated[str, typer.Argument(help="The servo's joint.",
                                         autocompletion=_complete_joint)]


def register_get(
    ctx: typer.Context,
    joint: JointArg,
    items: Annotated[list[str] | None, typer.Argument(
        autocompletion=_complete_item,
        help="Items to read (default: the whole table, in one read).")] = None,
) -> None:
    """Read control table items of one servo."""
    opts = options(ctx)
    with open_robot(opts) as robot:
        result = robot.registers(joint, items or [])
    if opts.json:
        emit_json({"joint": joint, "id": result["id"],
                   "values": {i["item"]: i["value"] for i in result["items"]}})
    else:
        table(f"{joint} (ID {result['id']})", ["address", "item", "value", "access"],
              [[i["address"], i["item"], i["value"], i["access"]] for i in result["items"]])
    finish(robot.system)


def register_set(
    ctx: typer.Context,
    joint: JointArg,
    item: Annotated[str, typer.Argument(autocompletion=_complete_item,
                                        help="The item, e.g. return_delay_time.")],
    value: Annotated[int, typer.Argument(help="The raw value.")],
) -> None:
    """Write one control table item and read it back (asks first: a write can move)."""
    from deltoctl.cli.motion_cmd import confirm_motion

    opts = options(ctx)
    confirm_motion(opts, f"write {item} = {value} to {joint}")
    with open_robot(opts) as robot:
        after = robot.write_register(joint, item, value)
    _report(opts, {"joint": joint, "item": item, "value": after}, f"{joint}: {item} = {after}")
    finish(robot.system)


def torque(
    ctx: typer.Context,
    state: Annotated[str, typer.Argument(autocompletion=_complete_state, help="on or off.")],
    target: TargetArg = "all",
) -> None:
    """Switch servo torque on or off for a joint or a group."""
    from deltoctl.cli.motion_cmd import confirm_motion

    opts = options(ctx)
    if state not in ("on", "off"):
        raise InvalidInput(f"state must be on or off, got {state!r}")
    profile = opts.load_profile()
    joints = select_joints(profile, target, "torque")
    if state == "on":
        confirm_motion(opts, f"torque on for {len(joints)} joint(s): they hold their position")
    with open_robot(opts, profile=profile) as robot:
        done = robot.torque(joints, state == "on")
    _report(opts, {"torque": state, "joints": done}, f"torque {state}: {len(done)} joint(s)")
    finish(robot.system)


def reboot(ctx: typer.Context, target: TargetArg = "all") -> None:
    """Reboot servos (clears a shutdown after a hardware error; torque comes back off)."""
    opts = options(ctx)
    profile = opts.load_profile()
    joints = select_joints(profile, target, "reboot")
    with open_robot(opts, profile=profile) as robot:
        done = robot.reboot(joints)
    _report(opts, {"rebooted": done}, f"rebooted {len(done)} of {len(joints)} joint(s)")
    missing = sorted(set(joints) - set(done))
    if missing:
        raise DeviceError(f"no reboot acknowledgement from {', '.join(missing)}")
    finish(robot.system)


def _report(opts: Any, data: dict, text: str) -> None:
    if opts.json:
        emit_json(data)
    else:
        say(text)
