"""Servo bus verbs: ``torque on|off [JOINT|GROUP]``, ``reboot [JOINT|GROUP]`` and
``register get|set JOINT [ITEM [VALUE]]`` (the control table by name)."""

from typing import Annotated, Any

import typer

from deltoctl.cli.completions import complete_register_items, complete_target
from deltoctl.cli.confirm import confirm
from deltoctl.cli.context import options
from deltoctl.cli.device_cmd import finish, on_robot, open_robot
from deltoctl.cli.motion_cmd import complete_joint
from deltoctl.cli.output import emit_json, say, table
from deltoctl.errors import DeviceError, InvalidInput


def _complete_state(incomplete: str) -> list[str]:
    return [s for s in ("on", "off") if s.startswith(incomplete)]


TargetArg = Annotated[str, typer.Argument(
    autocompletion=complete_target,
    help="A joint, a group (head, left_arm, right_arm, arms, left_leg, right_leg, legs) "
         "or all.")]


def register(root: typer.Typer) -> None:
    root.command("torque")(torque)
    root.command("reboot")(reboot)
    registers = typer.Typer(help="Read and write a servo's control table by item name.",
                            no_args_is_help=True)
    registers.command("get")(register_get)
    registers.command("set")(register_set)
    root.add_typer(registers, name="register")


JointArg = Annotated[str, typer.Argument(help="The servo's joint.",
                                         autocompletion=complete_joint)]


def register_get(
    ctx: typer.Context,
    joint: JointArg,
    items: Annotated[list[str] | None, typer.Argument(
        autocompletion=complete_register_items,
        help="Items to read (default: the whole table, in one read).")] = None,
) -> None:
    """Read control table items of one servo."""
    from deltoctl.render.config import register_table

    opts = options(ctx)
    with open_robot(opts) as robot:
        result = robot.registers(joint, items or [])
    if opts.json:
        emit_json({"joint": joint, "id": result["id"],
                   "values": {i["item"]: i["value"] for i in result["items"]}})
    else:
        table(*register_table(joint, result))
    finish(robot)


def register_set(
    ctx: typer.Context,
    joint: JointArg,
    item: Annotated[str, typer.Argument(autocompletion=complete_register_items,
                                        help="The item, e.g. return_delay_time.")],
    value: Annotated[int, typer.Argument(help="The raw value.")],
) -> None:
    """Write one control table item and read it back (asks first: a write can move)."""
    def write(robot: Any) -> dict[str, Any]:
        confirm(ctx, f"write {item} = {value} to {robot.servo_named(joint)}")
        return {"joint": joint, "item": item, "value": robot.write_register(joint, item, value)}

    on_robot(ctx, write, lambda done, _: [f"{joint}: {item} = {done['value']}"])


def torque(
    ctx: typer.Context,
    state: Annotated[str, typer.Argument(autocompletion=_complete_state, help="on or off.")],
    target: TargetArg = "all",
) -> None:
    """Switch servo torque on or off for a joint or a group."""
    from deltoctl.app.robot import joints_named, select_joints

    opts = options(ctx)
    if state not in ("on", "off"):
        raise InvalidInput(f"state must be on or off, got {state!r}")
    profile = opts.load_profile()
    joints = select_joints(profile, target, "torque", opts.hardware)
    confirm(ctx, f"switch torque {state} for {joints_named(target, joints)}: " + (
        "they hold their position" if state == "on"
        else "they go limp, and an arm under gravity falls"))
    on_robot(ctx, lambda robot: {"torque": state, "joints": robot.torque(joints, state == "on")},
             lambda done, _: [f"torque {state}: {len(done['joints'])} joint(s)"], profile=profile)


def reboot(ctx: typer.Context, target: TargetArg = "all") -> None:
    """Reboot servos (clears a shutdown after a hardware error; torque comes back off)."""
    from deltoctl.app.robot import joints_named, select_joints

    opts = options(ctx)
    profile = opts.load_profile()
    joints = select_joints(profile, target, "reboot", opts.hardware)
    confirm(ctx, f"reboot the servos of {joints_named(target, joints)}: their torque goes off, "
                 "an arm under gravity falls")
    with open_robot(opts, profile=profile) as robot:
        done = robot.reboot(joints)
    if opts.json:
        emit_json({"rebooted": done})
    else:
        say(f"rebooted {len(done)} of {len(joints)} joint(s)")
    missing = sorted(set(joints) - set(done))
    if missing:
        raise DeviceError(f"no reboot acknowledgement from {', '.join(missing)}")
    finish(robot)
