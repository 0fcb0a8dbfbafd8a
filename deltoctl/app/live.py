"""The live view in Foxglove that stream and record serve beside their own output: the server
checked before the devices are opened, started with the topics of the blocks driven, and what
it saw said on the way out."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from deltoctl.app.robot import Robot

Say = Callable[[str], None]


@contextlib.contextmanager
def foxglove_live(enabled: bool, host: str, port: int, origins: Sequence[str] | None,
                  warn: Say, notice: Say) -> Iterator[Any]:
    """With ``enabled``, the Foxglove sink, its address and port checked now (the server
    starts with ``start_foxglove``, and stops on the way out); else None. ``warn`` hears what
    the user should know (data served beyond this machine, the view stopped), ``notice`` the
    rest."""
    if not enabled:
        yield None
        return
    from deltoctl.record.foxglove_live import FoxgloveLive

    with FoxgloveLive(host, port, origins=tuple(origins or ())) as live:
        if not live.local:
            warn(f"--foxglove-host {host}: the robot's data is served beyond this machine, to "
                 f"anyone who reaches port {port or 'chosen'} there")
        yield live
    if live.error:
        warn(f"the live view stopped: {live.error}")
    if live.dropped:
        notice(f"Foxglove: {live.dropped} cycles not sent (the live view fell behind)")
    if live.gate.refused:
        notice(f"Foxglove: {live.gate.refused} connection(s) refused for their origin "
               "(a web page that is not Foxglove; --foxglove-origin lets one in)")


def start_foxglove(live: Any, robot: Robot, notice: Say,
                   gpio_type: str = "group-values") -> list[Any]:
    """With a live view (``live``), its server started with the topics of the blocks
    ``robot`` drives, where to connect told to ``notice``, and the view as the loop's sink;
    else no sink."""
    if live is None:
        return []
    from deltoctl.app.recording import driven_profile

    system = robot.system
    live.begin(driven_profile(system), tuple(system.extra_states()), gpio_type)
    notice(f"Foxglove: connect to {live.url} (Open connection → Foxglove WebSocket)")
    return [live]
