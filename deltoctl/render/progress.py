"""Progress bars on stderr while a person watches (rich)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rich.progress import Progress


def started_bar(transient: bool = True, elapsed: bool = False) -> Progress:
    """A started bar on stderr; ``elapsed``: the time so far instead of the time left."""
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    columns = ((TextColumn("{task.description}"), BarColumn(), TimeElapsedColumn()) if elapsed
               else Progress.get_default_columns())
    bar = Progress(*columns, console=Console(stderr=True), transient=transient)
    bar.start()
    return bar


def advancing(bar: Progress | None, label: str) -> Callable[[float], None] | None:
    """A task named ``label`` on ``bar`` and what moves it to a fraction done; None without
    a bar."""
    if bar is None:
        return None
    task = bar.add_task(label, total=1.0)
    return lambda fraction: bar.update(task, completed=fraction)


def recording_task(bar: Progress, output: Path,
                   duration: float | None) -> Callable[[float, int, float | None], None]:
    """A recording's task on ``bar`` (against ``duration``), and what updates its status
    line: the cycles so far, the file's size and the link."""
    from deltoctl.render.recording import recording_status

    task = bar.add_task(f"recording {output.name}", total=duration)

    def show(seconds: float, cycles: int, link: float | None) -> None:
        size = output.stat().st_size if output.exists() else 0
        bar.update(task, completed=seconds,
                   description=recording_status(output.name, cycles, size, link))

    return show


def stages(bar: Progress | None, name: str,
           line: Callable[[str], None] | None) -> Callable[[str, float], None]:
    """What shows a sequence's stages as they run: a task named ``name`` on ``bar`` when
    there is one, else a line each told to ``line`` (none with ``line`` None)."""
    task = bar.add_task(name, total=1.0) if bar is not None else None

    def said(label: str, fraction: float) -> None:
        if bar is not None and task is not None:
            bar.update(task, completed=fraction, description=f"{name}: {label}")
        elif line is not None and label != "done":
            line(f"{name}: {label}")

    return said


class HomingBars:
    """Homing while a person watches: a bar per joint that runs its routine (else its steps
    told to ``line``, unless that is None), then one for the way to the home pose, started
    when that begins. ``started(transient)``: a started bar, or None when nobody watches."""

    def __init__(self, started: Callable[[bool], Progress | None], joints: list[str],
                 line: Callable[[str], None] | None) -> None:
        self.started = started
        self.line = line
        self.bar = started(False) if joints else None
        self.tasks = {j: self.bar.add_task(f"{j}: waiting", total=1.0)
                      for j in joints} if self.bar else {}
        self.posing = False

    def show(self, name: str, status: str, fraction: float) -> None:
        if self.bar is not None:
            self.bar.update(self.tasks[name], completed=fraction,
                            description=f"{name}: {status}")
        elif self.line is not None:
            self.line(f"{name}: {status}")

    def move(self, fraction: float) -> None:
        if not self.posing:
            self.stop()
            self.posing = True
            self.bar = self.started(True)
            self.tasks = {"home": self.bar.add_task("home", total=1.0)} if self.bar else {}
        if self.bar is not None:
            self.bar.update(self.tasks["home"], completed=fraction)

    def stop(self) -> None:
        if self.bar is not None:
            self.bar.stop()
            self.bar = None
