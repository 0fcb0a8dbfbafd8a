"""Recording a robot: every block's state interfaces at a fixed rate to MCAP (ROS 2
encoding), written by a process of its own; the metadata a recording carries; the file a
recording goes to."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import re
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from deltoctl.app.sinks import LinkWatch
from deltoctl.core.runner import Sink, check_loop
from deltoctl.errors import DeviceError, InvalidInput

if TYPE_CHECKING:
    from deltoctl.core.system import System
    from deltoctl.fleet.remote_record import Recorded
    from deltoctl.profile.model import Profile

SHOW_PERIOD = 0.25  # s between two calls of a recording's ``show``
# what a recording shows as it goes: seconds so far, cycles, the link's state (None: unknown)
Show = Callable[[float, int, "float | None"], None]


SERIAL = "{serial}"  # in a recording's name: the serial (else the address) of each block
TIME = "{time}"  # in a recording's name: when it started, UTC (20261125T211400Z)


def block_serial(name: str, target: str | None, identity: Mapping[str, Any]) -> str:
    """A block's part of ``{serial}``: the serial number its device reports (``serial`` or
    ``serial_number`` in its identity), else its target's address (``127.0.0.1-502``,
    ``ttyUSB0``, ``i2c-1``), else the block's name (an in-process mock); safe in a file name."""
    serial = identity.get("serial") or identity.get("serial_number")
    if not serial and target:
        where = target.partition("://")[2].partition("?")[0] or target
        serial = where.rstrip("/").rsplit("/", 1)[-1] if "/" in where else where
    return re.sub(r"[^A-Za-z0-9._-]+", "-", str(serial or name)).strip("-.") or name


def output_path(template: Path, serials: Sequence[str] = ()) -> Path:
    """A recording's file name with ``{time}`` filled (UTC, compact) and, given the blocks'
    serials, ``{serial}`` (joined by ``+``); only the name is filled, never the directory."""
    name = template.name.replace(TIME, time.strftime("%Y%m%dT%H%M%SZ", time.gmtime()))
    if serials:
        name = name.replace(SERIAL, "+".join(serials))
    return template.with_name(name)


def system_serials(system: System) -> list[str]:
    """Each driven block's part of ``{serial}``."""
    return [block_serial(m.name, m.url, m.driver.identify() if m.can("identify") else {})
            for m in system]


def planned_output(template: Path, force: bool = False) -> Path:
    """A recording's file before anything opens: ``{time}`` filled, and refused (exit 2) when
    its directory is missing or it exists without ``force`` (a ``{serial}`` name is judged once
    the blocks answer)."""
    path = output_path(template)
    if not path.parent.is_dir():
        raise InvalidInput(f"cannot write {path}: {path.parent} is not a directory")
    if SERIAL not in path.name:
        refuse_existing(path, force)
    return path


def refuse_existing(path: Path, force: bool) -> None:
    """An existing file (without ``force``) is invalid input: a recording never overwrites
    one unasked."""
    if path.is_dir():
        raise InvalidInput(f"cannot write {path}: it is a directory")
    if not force and (path.exists() or path.is_symlink()):
        raise InvalidInput(f"{path} exists: a recording does not overwrite a file",
                           "pass --force to overwrite it, or put {time} in the name")


def identified_output(template: Path, identities: Mapping[str, Mapping[str, Any]],
                      force: bool = False) -> Path:
    """A remote record's file once the robot's blocks are identified (``identities``: block →
    its identity, with its ``target``): ``{serial}`` filled as a local record fills it; refused
    when it exists (without ``force``)."""
    path = template
    if SERIAL in path.name:
        path = output_path(path, [block_serial(block, ident.get("target"), ident)
                                  for block, ident in identities.items()])
    refuse_existing(path, force)
    return path


def create_output(path: Path, force: bool = False) -> None:
    """The file a recording goes to, created empty; one that exists (without ``force``) or
    cannot be written is invalid input."""
    refuse_existing(path, force)
    try:
        path.open("wb" if force else "xb").close()
    except FileExistsError:
        refuse_existing(path, force)
    except OSError as exc:
        raise InvalidInput(f"cannot write {path}: {exc.strerror}") from None


@contextlib.contextmanager
def new_output(path: Path, system: System | None = None,
               force: bool = False) -> Iterator[Path]:
    """``create_output`` before the recording starts (``{serial}`` filled from ``system``);
    yields the file's path. The file is removed again when what follows fails before writing
    to it (an unreachable device, a refused move)."""
    if system is not None and SERIAL in path.name:
        path = output_path(path, system_serials(system))
    create_output(path, force)
    try:
        yield path
    except BaseException:
        with contextlib.suppress(OSError):
            if path.stat().st_size == 0:
                path.unlink()
        raise


def driven_profile(system: System) -> Profile:
    """The profile of the blocks the System drives (``--hardware`` narrows it)."""
    return dataclasses.replace(system.profile, hardware=[m.hw for m in system])


def recording_metadata(system: System) -> tuple[Profile, dict[str, dict[str, str]]]:
    """The profile of the blocks driven, and the metadata a recording of them carries: that
    profile (YAML), each block's identity, deltoctl's version."""
    from deltoctl.profile.exporter import to_yaml
    from deltoctl.version import __version__

    recorded = driven_profile(system)
    identities = {m.name: {"family": m.family.name, "target": m.url,
                           "simulated": m.simulated is not None, **m.driver.identify()}
                  for m in system.able("identify")}
    return recorded, {
        "profile": {"name": recorded.name, "yaml": to_yaml(recorded)},
        "identify": {name: json.dumps(ident, default=str) for name, ident in identities.items()},
        "deltoctl": {"version": __version__},
    }


class RecordSink(Sink):
    """Frames to the recorder process; the loop's and buses' statistics to /diagnostics once a
    second; ``show`` told how it goes a few times a second."""

    def __init__(self, recorder: Any, show: Show | None = None) -> None:
        self.recorder, self.show = recorder, show
        self.started = self.next_show = time.monotonic()
        self.cycles = 0

    def frame(self, t_ns: int, values: dict[str, float]) -> None:
        self.recorder.write(values, t_ns)
        self.cycles += 1
        if self.show is not None and time.monotonic() >= self.next_show:
            now = time.monotonic()
            self.next_show = now + SHOW_PERIOD
            self.show(now - self.started, self.cycles, values.get("system/connection_status"))

    def periodic(self, t_ns: int, stats: Any, comm_loops: list[Any]) -> None:
        from deltoctl.record.mcap_recorder import OK, WARN

        self.recorder.diagnostics(t_ns, [
            (OK, "loop", "record loop", stats.summary()),
            *((OK if not c.errors else WARN, c.name, "bus loop", c.report())
              for c in comm_loops)])

    def close(self, stats: Any) -> None:
        self.recorder.close(stats.summary())


def record_from_robot(zenoh_config: str | None, robot: str, params: Mapping[str, Any],
                      hardware: Sequence[str], err: Callable[[bytes], None],
                      opened: Callable[[Path], None]) -> Recorded:
    """``--robot ROBOT record FILE``: the robot's stream recorded to FILE on this computer, by
    the record's options ``params`` (as ``deltoctl record`` parses them), of the blocks
    ``hardware`` names (all if none); ``opened`` is told the file once it is created."""
    from deltoctl.fleet.remote_record import record_remote

    output = planned_output(Path(params["output"]), params["force"])
    return record_remote(
        zenoh_config, robot, output, params["rate"], params["duration"],
        [f"--hardware={h}" for h in hardware], params["gpio_type"],
        params["allow_model_mismatch"], err, opened=opened,
        name=lambda template, identities: identified_output(template, identities,
                                                            params["force"]))


def check_record_options(rate: float, duration: float | None, gpio_type: str) -> None:
    """A recording's rate, duration and /gpio type, wherever its file is written."""
    from deltoctl.record.ros2_msgs import GPIO_TYPES

    check_loop(rate, duration)
    if gpio_type not in GPIO_TYPES:
        raise InvalidInput(f"--gpio-type {gpio_type!r}: one of {', '.join(GPIO_TYPES)}")


def check_record(output: Path, rate: float, duration: float | None, gpio_type: str) -> None:
    """A recording's options, checked before any device is opened."""
    check_record_options(rate, duration, gpio_type)
    if not output.parent.is_dir():
        raise InvalidInput(f"cannot write {output}: {output.parent} is not a directory")


def record(system: System, output: Path, rate: float, duration: float | None,
           gpio_type: str = "group-values", sinks: Sequence[Sink] = (),
           show: Show | None = None, force: bool = False) -> tuple[dict[str, Any], LinkWatch]:
    """Record until ``duration`` passes or an interrupt (the file is valid either way);
    ``sinks`` see every cycle too. ``output`` may hold ``{time}`` and ``{serial}``; an existing
    file is refused unless ``force``. Returns the result and the lost-link watch, whose
    ``finish()`` says how the links ended (Unreachable when one is still down)."""
    from deltoctl.core.runner import run_cycles
    from deltoctl.record.recorder_process import RecorderProcess

    output = output_path(output, system_serials(system) if SERIAL in output.name else ())
    check_record(output, rate, duration, gpio_type)
    create_output(output, force)
    recorded, metadata = recording_metadata(system)
    with RecorderProcess(output, recorded, metadata, tuple(system.extra_states()),
                         gpio_type=gpio_type) as recorder:
        links = LinkWatch(system)
        stats = run_cycles(system, rate, duration, [RecordSink(recorder, show), links, *sinks])
    if recorder.error:  # a write failed or the file was removed: the message says what is left
        raise DeviceError(recorder.error)
    return {"output": str(output), "messages": recorder.counts,
            "link_losses": recorder.link_losses, "loop": stats.summary()}, links


def recorded_moves(system: System, output: Path,
                   moves: Callable[[], dict[str, Any]]) -> dict[str, Any]:
    """Run ``moves`` (a move procedure returning its report) while every move loop's cycles,
    states and setpoints, go to ``output`` (for ``deltoctl replay``); the report gains
    ``recording``."""
    from deltoctl.app.replay import CommandLog
    from deltoctl.record.recorder_process import RecorderProcess

    profile, metadata = recording_metadata(system)
    with RecorderProcess(output, profile, metadata, tuple(system.extra_states()),
                         commands=True) as recorder:
        with CommandLog(system, recorder) as log:
            report = moves()
        recorder.close()  # the move loops have no loop statistics of their own to write
    if recorder.error:  # a write failed or the file was removed: the message says what is left
        raise DeviceError(recorder.error)
    report["recording"] = {"output": str(output), "cycles": log.rows,
                           "messages": recorder.counts}
    return report
