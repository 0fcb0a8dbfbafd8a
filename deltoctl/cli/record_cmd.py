"""``deltoctl record OUT.mcap``: interface values to MCAP (ROS 2 encoding)."""

import time
from pathlib import Path
from typing import Annotated

import typer

from deltoctl.cli.context import options
from deltoctl.cli.device_cmd import AllowMismatch, DurationOpt, RateOpt, finish, open_session
from deltoctl.cli.output import emit_json, info, progress
from deltoctl.errors import WARNINGS, InvalidInput

STATS_PERIOD = 1.0  # s between loop-statistics diagnostics
SHOW_PERIOD = 0.25  # s between updates of the status line people watch


def _status(output: Path, cycles: int, link: float | None) -> str:
    """The status line people watch (the time so far is the bar's, against --duration)."""
    size = output.stat().st_size if output.exists() else 0
    state = "" if link is None else " · link up" if link else " · [red]link lost[/]"
    return f"recording {output.name}: {cycles} cycles, {size / 1e6:.1f} MB{state}"


def _create(path: Path) -> None:
    try:
        path.open("wb").close()
    except OSError as exc:
        raise InvalidInput(f"cannot write {path}: {exc.strerror}") from None


def record(
    ctx: typer.Context,
    output: Annotated[Path, typer.Argument(help="The .mcap file to write.")],
    rate: RateOpt = 100.0,
    duration: DurationOpt = None,
    allow_model_mismatch: AllowMismatch = False,
) -> None:
    """Record every state interface; Ctrl-C, SIGTERM or --duration end with a valid file."""
    import signal

    from deltoctl import __version__
    from deltoctl.core.loop import CycleLoop
    from deltoctl.profile.exporter import to_yaml
    from deltoctl.record.mcap_recorder import OK, WARN
    from deltoctl.record.recorder_process import RecorderProcess

    opts = options(ctx)
    if rate <= 0:
        raise InvalidInput("--rate must be positive")
    if not output.parent.is_dir():
        raise InvalidInput(f"cannot write {output}: {output.parent} is not a directory")
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    # the file is created once the device answers: an unreachable device leaves no empty file
    with open_session(opts, allow_model_mismatch) as session:
        _create(output)
        driver = session.driver
        ident = {k: str(v) for k, v in driver.identity.as_dict().items()}
        recorder = RecorderProcess(output, session.profile, {
            "profile": {"name": session.profile.name, "yaml": to_yaml(session.profile)},
            "identify": {**ident, "target": session.url},
            "deltoctl": {"version": __version__},
        }, driver.extra_states)
        loop = CycleLoop(rate, duration)
        comm_loops = driver.comm_loops()  # a bus's own loops (Dynamixel)
        bar = progress(opts, elapsed=True)
        task = bar.add_task(f"recording {output.name}", total=duration) if bar else None
        next_show = time.monotonic()
        next_stats = next_show + STATS_PERIOD
        try:
            for _ in loop:
                before = driver.stats["errors"]
                values = driver.read()
                loop.stats.packets += 1
                loop.stats.errors += driver.stats["errors"] - before
                recorder.write(values, time.time_ns())
                now = time.monotonic()
                if bar is not None and now >= next_show:
                    next_show = now + SHOW_PERIOD
                    bar.update(task, completed=now - loop.stats.started, description=_status(
                        output, loop.stats.cycles, values.get("system/connection_status")))
                if now >= next_stats:
                    next_stats += STATS_PERIOD
                    recorder.diagnostics(time.time_ns(), [
                        (OK, "loop", "record loop", loop.stats.summary()),
                        *((OK if not c.errors else WARN, c.name, "bus loop", c.report())
                          for c in comm_loops)])
        except KeyboardInterrupt:
            pass
        finally:
            if bar is not None:
                bar.stop()
            summary = loop.stats.summary()
            recorder.close(summary)
    result = {"output": str(output), "messages": recorder.counts,
              "link_losses": recorder.link_losses, "loop": summary}
    if opts.json:
        emit_json(result)
    elif not opts.quiet:
        info(f"wrote {output}: {sum(recorder.counts.values())} messages on "
             f"{len(recorder.counts)} topics, {summary['cycles']} cycles at "
             f"{summary['real_rate']} Hz")
    if recorder.link_losses:
        info(f"warning: the link was lost {recorder.link_losses} time(s); the gaps are marked "
             "on /diagnostics")
    finish(session)  # exit 3 on the driver's warnings (a servo that never answered)
    if recorder.link_losses:
        raise typer.Exit(WARNINGS)


def register(root: typer.Typer) -> None:
    root.command("record")(record)
