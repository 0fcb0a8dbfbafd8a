"""What every driver offers the verbs, beyond ros2_control's configure / read / write / stop /
cleanup: the optional parts, with the defaults a driver keeps unless it has better."""

from __future__ import annotations

from deltoctl.core.loop import CommLoop


class Driver:
    family = ""
    extra_states: tuple[str, ...] = ()  # per-joint values beyond the profile's interfaces

    def round_trip(self) -> None:
        """The smallest exchange with the device: what `connect` times."""
        self.read()  # type: ignore[attr-defined]

    def comm_loops(self) -> list[CommLoop]:
        """Bus loops that run at their own rates inside the verb's cycle."""
        return []

    def check_motion(self, joints: list[str]) -> None:
        """Raise Refused when these joints may not move now (before anyone is asked)."""
