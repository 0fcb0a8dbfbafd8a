"""ros2_control's hardware lifecycle: unconfigured → inactive → active → finalized."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from deltoctl import trace
from deltoctl.errors import DeltoctlError

UNCONFIGURED, INACTIVE, ACTIVE, FINALIZED = "unconfigured", "inactive", "active", "finalized"

_TRANSITIONS = {
    "configure": (UNCONFIGURED, INACTIVE),
    "activate": (INACTIVE, ACTIVE),
    "deactivate": (ACTIVE, INACTIVE),
    "cleanup": (INACTIVE, UNCONFIGURED),
    "shutdown": (None, FINALIZED),
}


class Lifecycle:
    """Tracks the state and the transitions taken; a failed transition goes through on_error
    back to unconfigured, as ros2_control does."""

    def __init__(self, name: str = "") -> None:
        self.name = name  # the block's, for the -v log
        self.state = UNCONFIGURED
        self.history: list[str] = [UNCONFIGURED]

    def transition(self, name: str, action: Callable[[], Any] | None = None) -> Any:
        start, end = _TRANSITIONS[name]
        if start is not None and self.state != start:
            raise DeltoctlError(f"cannot {name} from {self.state}")
        try:
            result = action() if action else None
        except BaseException:
            self.state = UNCONFIGURED
            self.history.append(f"error→{UNCONFIGURED}")
            trace.lifecycle(self.name, f"{name} failed", UNCONFIGURED)
            raise
        self.state = end
        self.history.append(end)
        trace.lifecycle(self.name, name, end)
        return result
