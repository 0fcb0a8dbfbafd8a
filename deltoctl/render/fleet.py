"""The fleet for people: the robots ``fleet list`` finds, a ``fleet run`` (its live table while
the robots run, its outcome, its robots' reports), and the file a remote ``record`` wrote."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rich.table import Table

    from deltoctl.fleet.fleet_run import Job


def identity_text(identity: dict[str, Any]) -> str:
    """Each block as its family shows its identity (``Family.identity_fields``: model,
    firmware, parts …); a family not installed here, or one declaring none, by its name."""
    from deltoctl import registry

    if "error" in identity:
        return f"identify failed: {identity['error']}"
    parts = []
    for block, fields in identity.items():
        family = registry.get(str(fields.get("family")))
        shown = [template.format(fields[key]).split(" (0x")[0]  # a model's number: too long
                 for key, template in (family.identity_fields if family else ())
                 if fields.get(key) not in (None, "")]
        parts.append(f"{block}: {' '.join(shown) or fields.get('family')}")
    return "; ".join(parts)


def list_rows(robots: Sequence[dict[str, Any]]) -> list[list[str]]:
    """``fleet list``'s table: robot, profile, identity, state, motion."""
    return [[r["robot"], r["profile"], identity_text(r.get("identity", {})), r["state"],
             r.get("motion", "?")] for r in robots]


def run_rows(jobs: Sequence[Job]) -> list[list[Any]]:
    """A fleet run's outcome: robot, profile, exit code, seconds, lines run, result."""
    return [[j.robot, j.profile, j.code, f"{j.seconds():.2f}", f"{j.done}/{len(j.lines)}",
             "ok" if j.code == 0 else j.last_error()] for j in jobs]


def report_rows(doc: dict[str, Any]) -> list[list[str]]:
    """A fleet report's robots: each one's verdict and the checks it failed (or its error)."""
    return [[r["robot"], r["verdict"], ", ".join(r["failed"]) or r["error"] or ""]
            for r in doc["robots"]]


def not_received_text(robot: str, result: dict[str, Any]) -> str:
    """The cycles a robot ran that a remote record did not receive."""
    loop = result["loop"]
    return (f"robot {robot}: {loop['cycles_not_received']} of its {loop['robot_cycles']} "
            "cycles did not arrive (the gaps are marked on /diagnostics)")


def run_table(jobs: Sequence[Job]) -> Table:
    """A fleet run as it goes: each robot, what it runs now, its lines done, its seconds."""
    from rich.table import Table

    t = Table(title="fleet run", title_justify="left")
    for column in ("robot", "profile", "now", "lines", "seconds"):
        t.add_column(column)
    for j in jobs:
        t.add_row(j.robot, j.profile, j.state, f"{j.done}/{len(j.lines)}", f"{j.seconds():.1f}")
    return t


@contextlib.contextmanager
def live_run(jobs: Sequence[Job], shown: bool = True) -> Iterator[Callable[[], None] | None]:
    """The fleet run's live table on stderr while the block runs, when ``shown``; yields what
    redraws it (None when not shown)."""
    if not shown:
        yield None
        return
    from rich.console import Console
    from rich.live import Live

    live = Live(run_table(jobs), console=Console(stderr=True), auto_refresh=False)
    live.start()
    try:
        yield lambda: live.update(run_table(jobs), refresh=True)
    finally:
        live.stop()
