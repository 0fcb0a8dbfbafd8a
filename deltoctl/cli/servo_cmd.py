"""Servo bus verbs: ``torque on|off [JOINT|GROUP]`` and ``reboot [JOINT|GROUP]``."""

from typing import Annotated, Any

import typer

from deltoctl.cli.context import options
from deltoctl.cli.device_cmd import open_session
from deltoctl.cli.output import emit_json, info
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
        info(text)
