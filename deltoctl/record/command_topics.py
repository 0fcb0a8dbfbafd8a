"""The names a recording of commands uses: the /joint_commands topic, and each joint's
setpoint as ``<joint>/position_command``, ``<joint>/velocity_command``,
``<joint>/effort_command`` (``jog --record`` writes them, ``replay`` reads them)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from deltoctl.core.driver import SETPOINT_FIELDS

if TYPE_CHECKING:
    from deltoctl.profile.model import Component, Profile

COMMANDS_TOPIC = "/joint_commands"
STATES_TOPIC = "/joint_states"
COMMAND_SUFFIX = "_command"


def command_key(joint: str, field: str) -> str:
    """The interface name a setpoint is recorded under: ``j1/position_command``."""
    return f"{joint}/{field}{COMMAND_SUFFIX}"


def commanded_joints(profile: Profile) -> list[Component]:
    """The joints /joint_commands carries: a position state and a position, velocity or
    effort command interface (mimic joints follow another one: never commanded)."""
    return [j for j in profile.joints() if j.state("position") and j.mimic is None
            and any(j.command(f) for f in SETPOINT_FIELDS)]
