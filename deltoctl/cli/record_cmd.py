"""``deltoctl record OUT.mcap``: interface values to MCAP (ROS 2 encoding)."""

import contextlib
import json
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Annotated, Any

import typer

from deltoctl.cli.context import options
from deltoctl.cli.device_cmd import (
    AllowMismatch,
    DurationOpt,
    LinkWatch,
    RateOpt,
    check_loop,
    finish,
    open_system,
)
from deltoctl.cli.output import emit_json, info, progress, warn
from deltoctl.core.runner import Sink
from deltoctl.errors import DeviceError, InvalidInput

SHOW_PERIOD = 0.25  # s between updates of the status line people watch


def _status(output: Path, cycles: int, link: float | None) -> str:
    """The status line people watch (the time so far is the bar's, against --duration)."""
    size = output.stat().st_size if output.exists() else 0
    state = "" if link is None else " · link up" if link else " · [red]link lost[/]"
    return f"recording {output.name}: {cycles} cycles, {size / 1e6:.1f} MB{state}"


def create_output(path: Path) -> None:
    """The file a recording goes to, created empty; one that cannot be is invalid input."""
    try:
        path.open("wb").close()
    except OSError as exc:
        raise InvalidInput(f"cannot write {path}: {exc.strerror}") from None


@contextlib.contextmanager
def new_output(path: Path) -> Iterator[None]:
    """``create_output`` before anything opens; the file is removed again when what follows
    fails before writing to it (an unreachable device, a refused move)."""
    create_output(path)
    try:
        yield
    except BaseException:
        with contextlib.suppress(OSError):
            if path.stat().st_size == 0:
                path.unlink()
        raise


def recording_metadata(system: Any) -> tuple[Any, dict[str, dict[str, str]]]:
    """The profile of the blocks driven, and the metadata a recording of them carries: that
    profile (YAML), each block's identity, deltoctl's version."""
    import dataclasses

    from deltoctl import __version__
    from deltoctl.profile.exporter import to_yaml

    recorded = dataclasses.replace(system.profile, hardware=[m.hw for m in system])
    identities = {m.name: {"family": m.family.name, "target": m.url,
                           "simulated": m.simulated is not None, **m.driver.identify()}
                  for m in system.able("identify")}
    return recorded, {
        "profile": {"name": recorded.name, "yaml": to_yaml(recorded)},
        "identify": {name: json.dumps(ident, default=str) for name, ident in identities.items()},
        "deltoctl": {"version": __version__},
    }


FoxgloveOpt = Annotated[bool, typer.Option(
    "--foxglove", help="Serve the live values to Foxglove too (WebSocket, the topics and "
                       "messages of a recording); needs pip install 'deltoctl\\[foxglove]'.")]
FoxglovePortOpt = Annotated[int, typer.Option(
    "--foxglove-port", metavar="PORT", help="The Foxglove WebSocket port (0: any free one).")]
FoxgloveHostOpt = Annotated[str, typer.Option(
    "--foxglove-host", metavar="ADDRESS",
    help="The address to serve Foxglove on; another than loopback serves the robot's data to "
         "other machines.")]
FoxgloveOriginOpt = Annotated[list[str] | None, typer.Option(
    "--foxglove-origin", metavar="ORIGIN",
    help="Also let in browser pages of this origin (repeatable, e.g. http://localhost:8080 for "
         "a self-hosted Foxglove); by default only Foxglove's own (https://app.foxglove.dev, "
         "the desktop app) and clients that send no Origin.")]


@contextlib.contextmanager
def foxglove_live(enabled: bool, host: str, port: int,
                  origins: list[str] | None = None) -> Iterator[Any]:
    """With --foxglove, the Foxglove sink, its address and port checked before the devices
    are opened (the server starts with ``start_foxglove``, and stops on the way out); else
    None."""
    if not enabled:
        yield None
        return
    from deltoctl.record.foxglove_live import FoxgloveLive, is_local

    with FoxgloveLive(host, port, origins=tuple(origins or ())) as live:
        if not is_local(host):
            warn(f"--foxglove-host {host}: the robot's data is served beyond this machine, to "
                 f"anyone who reaches port {port or 'chosen'} there")
        yield live
    if live.error:
        warn(f"the live view stopped: {live.error}")
    if live.dropped:
        info(f"Foxglove: {live.dropped} cycles not sent (the live view fell behind)")
    if live.gate.refused:
        info(f"Foxglove: {live.gate.refused} connection(s) refused for their origin "
             "(a web page that is not Foxglove; --foxglove-origin lets one in)")


def start_foxglove(live: Any, profile: Any, extra_states: tuple[str, ...],
                   gpio_type: str = "group-values") -> None:
    """The server, with the robot's topics; where it is said on stderr."""
    live.begin(profile, extra_states, gpio_type)
    info(f"Foxglove: connect to {live.url} (Open connection → Foxglove WebSocket)")


def foxglove_result(live: Any) -> dict[str, Any]:
    return {"url": live.url, "cycles_sent": live.sent, "cycles_dropped": live.dropped}


class RecordSink(Sink):
    """Frames to the recorder process; the loop's and buses' statistics to /diagnostics once a
    second; the status line people watch."""

    def __init__(self, recorder: Any, output: Path, duration: float | None, bar: Any) -> None:
        self.recorder, self.output, self.bar = recorder, output, bar
        self.task = bar.add_task(f"recording {output.name}", total=duration) if bar else None
        self.started = time.monotonic()
        self.next_show = self.started
        self.cycles = 0

    def frame(self, t_ns: int, values: dict[str, float]) -> None:
        self.recorder.write(values, t_ns)
        self.cycles += 1
        if self.bar is not None and time.monotonic() >= self.next_show:
            now = time.monotonic()
            self.next_show = now + SHOW_PERIOD
            self.bar.update(self.task, completed=now - self.started, description=_status(
                self.output, self.cycles, values.get("system/connection_status")))

    def periodic(self, t_ns: int, stats: Any, comm_loops: list[Any]) -> None:
        from deltoctl.record.mcap_recorder import OK, WARN

        self.recorder.diagnostics(t_ns, [
            (OK, "loop", "record loop", stats.summary()),
            *((OK if not c.errors else WARN, c.name, "bus loop", c.report())
              for c in comm_loops)])

    def close(self, stats: Any) -> None:
        try:
            if self.bar is not None:
                self.bar.stop()
        finally:
            self.recorder.close(stats.summary())


def record(
    ctx: typer.Context,
    output: Annotated[Path, typer.Argument(help="The .mcap file to write.")],
    rate: RateOpt = 100.0,
    duration: DurationOpt = None,
    allow_model_mismatch: AllowMismatch = False,
    gpio_type: Annotated[str, typer.Option(
        "--gpio-type", metavar="TYPE",
        help="/gpio's type: group-values (control_msgs/DynamicInterfaceGroupValues, control_msgs "
             "4.7+ on Humble, 5.3+ on Jazzy) or joint-state (control_msgs/DynamicJointState, "
             "every control_msgs).")] = "group-values",
    foxglove: FoxgloveOpt = False,
    foxglove_port: FoxglovePortOpt = 8765,
    foxglove_host: FoxgloveHostOpt = "127.0.0.1",
    foxglove_origin: FoxgloveOriginOpt = None,
) -> None:
    """Record every block's state interfaces; Ctrl-C, SIGTERM, SIGHUP or --duration end with a
    valid file. Exit 4 when a link is down at the end, 3 when one was lost and came back, 1 when
    the file could not be written to the end (disk full, file too large, removed)."""
    from deltoctl.core.runner import interrupted_by_signals, run_cycles
    from deltoctl.record.recorder_process import RecorderProcess

    opts = options(ctx)
    check_loop(rate, duration)
    from deltoctl.record.ros2_msgs import GPIO_TYPES

    if gpio_type not in GPIO_TYPES:
        raise InvalidInput(f"--gpio-type {gpio_type!r}: one of {', '.join(GPIO_TYPES)}")
    if not output.parent.is_dir():
        raise InvalidInput(f"cannot write {output}: {output.parent} is not a directory")
    # the file is created once the devices answer: an unreachable one leaves no empty file;
    # SIGTERM and SIGHUP before the loop interrupt like Ctrl-C, so the file is finished too
    with interrupted_by_signals(), \
            foxglove_live(foxglove, foxglove_host, foxglove_port, foxglove_origin) as live, \
            open_system(opts, allow_model_mismatch) as system:
        create_output(output)
        recorded, metadata = recording_metadata(system)
        sinks: list[Sink] = []
        if live is not None:
            start_foxglove(live, recorded, tuple(system.extra_states()), gpio_type)
            sinks.append(live)
        with RecorderProcess(output, recorded, metadata, tuple(system.extra_states()),
                             gpio_type=gpio_type) as recorder:
            links = LinkWatch(system)
            stats = run_cycles(system, rate, duration, [
                RecordSink(recorder, output, duration, progress(opts, elapsed=True)), links,
                *sinks])
    if recorder.error:  # a write failed or the file was removed: the message says what is left
        raise DeviceError(recorder.error)
    summary = stats.summary()
    result = {"output": str(output), "messages": recorder.counts,
              "link_losses": recorder.link_losses, "loop": summary}
    if live is not None:
        result["foxglove"] = foxglove_result(live)
    if opts.json:
        emit_json(result)
    else:
        info(f"wrote {output}: {sum(recorder.counts.values())} messages on "
             f"{len(recorder.counts)} topics, {summary['cycles']} cycles at "
             f"{summary['real_rate']} Hz")
    if recorder.link_losses:
        info("the gaps are marked on /diagnostics")
    links.finish()
    finish(system)  # exit 3 on warnings (a servo that never answered, a link lost)


def register(root: typer.Typer) -> None:
    root.command("record")(record)
