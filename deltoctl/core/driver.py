"""What every driver offers the verbs, beyond ros2_control's configure / read / write / stop /
cleanup: the optional parts, with the defaults a driver keeps unless it has better."""

from __future__ import annotations

from deltoctl.core.loop import CommLoop
from deltoctl.errors import Unreachable


class Driver:
    family = ""
    extra_states: tuple[str, ...] = ()  # per-joint values beyond the profile's interfaces
    probe = False  # opened only to look at the bus (detect): nothing answering is no error

    def round_trip(self) -> None:
        """The smallest exchange with the device: what `connect` times."""
        self.read()  # type: ignore[attr-defined]

    def comm_loops(self) -> list[CommLoop]:
        """Bus loops that run at their own rates inside the verb's cycle."""
        return []

    def check_motion(self, joints: list[str]) -> None:
        """Raise Refused when these joints may not move now (before anyone is asked)."""

    def roll_call(self, missing: list[str], answered: bool, parts: str, hint: str) -> None:
        """After configure's pings of a bus: nothing answering is unreachable (exit 4) unless
        the verb only probes the bus (``detect``); parts missing are a warning."""
        hw, url = self.hw, self.url  # type: ignore[attr-defined]
        if not answered and not self.probe:
            raise Unreachable(f"no {parts} of {hw.name!r} answers on {url}", hint=hint)
        if missing:
            self.warnings.append(  # type: ignore[attr-defined]
                f"{hw.name}: no answer from {', '.join(missing)}")
