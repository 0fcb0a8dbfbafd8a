"""Cycle sinks every front end shares: the lost-link policy of a stream or a recording."""

from __future__ import annotations

from typing import TYPE_CHECKING

from deltoctl.core.runner import Sink
from deltoctl.errors import Unreachable

if TYPE_CHECKING:
    from deltoctl.core.system import System


class LinkWatch(Sink):
    """Counts link losses per block; at the end, a block whose link is still down is
    unreachable (exit 4), and one that came back is a warning."""

    def __init__(self, system: System) -> None:
        self.system = system
        self.keys = {m.status_key: m for m in system}
        self.up = dict.fromkeys(self.keys, True)
        self.losses: dict[str, int] = {}

    def frame(self, t_ns: int, values: dict[str, float]) -> None:
        if values.get("system/connection_status") == 1.0 and all(self.up.values()):
            return
        for key, m in self.keys.items():
            up = values.get(key) == 1.0
            if self.up[key] and not up:
                self.losses[m.name] = self.losses.get(m.name, 0) + 1
            self.up[key] = up

    def finish(self) -> None:
        down = [self.keys[k].name for k, up in self.up.items() if not up]
        if down:
            raise Unreachable(f"the link to {', '.join(down)} was lost and did not come back")
        for name, n in self.losses.items():
            self.system.notes.append(f"{name}: the link was lost {n} time(s) and came back")
