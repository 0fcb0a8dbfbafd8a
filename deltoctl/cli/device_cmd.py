"""The lifecycle verbs on every block of a robot: connect, identify, detect, gpio, stream."""

import contextlib
import time
from collections.abc import Iterator
from typing import Annotated, Any

import typer

from deltoctl.app.robot import check_loop
from deltoctl.app.sinks import LinkWatch
from deltoctl.cli.context import Options, options
from deltoctl.cli.output import (
    emit_json,
    emit_json_line,
    info,
    say,
    stdout_is_terminal,
    table,
    warn,
)
from deltoctl.core.runner import Sink
from deltoctl.errors import WARNINGS, InvalidInput

AllowMismatch = Annotated[bool, typer.Option(
    "--allow-model-mismatch",
    help="Go on when a device reports another model than the profile (exit 3).")]


# why every block runs on a simulator that -t names like a device: set by 'deltoctl agent
# --sim' in the processes that run its verbs, so that their JSON and recordings say simulated
SERVED_SIMULATED: str | None = None


@contextlib.contextmanager
def open_robot(opts: Options, allow_model_mismatch: bool = False, profile: Any = None,
               probe: bool = False) -> Iterator[Any]:
    """The robot of the selected profile's blocks (``--hardware``), configured and active;
    with ``--sim``, each block's simulator is started first. Pass ``profile`` when the verb
    loaded it already; ``probe`` for a verb that looks at a bus where nothing may answer."""
    from deltoctl.app.robot import open_robot as open_app_robot

    with open_app_robot(profile or opts.load_profile(), opts.target, sim=opts.sim,
                        hardware=opts.hardware, allow_model_mismatch=allow_model_mismatch,
                        probe=probe, notice=info, served_by=SERVED_SIMULATED) as robot:
        yield robot


def finish(system: Any, extra: list[str] | None = None) -> None:
    """Exit 3 when the verb finished but with warnings (a block left out, a model mismatch
    allowed, reconnects)."""
    warnings = system.warnings() + (extra or [])
    for w in warnings:
        warn(w)
    if warnings:
        raise typer.Exit(WARNINGS)


def register(app: typer.Typer) -> None:
    app.command("connect")(connect)
    app.command("identify")(identify)
    app.command("detect")(detect)
    app.command("stream")(stream)
    gpio_app = typer.Typer(help="Read and set GPIOs (a Delto's outputs: motor on, grasp, "
                           "release; vacuum, digital and analog IOs).", no_args_is_help=True)
    gpio_app.command("get")(gpio_get)
    gpio_app.command("set")(gpio_set)
    app.add_typer(gpio_app, name="gpio")


def connect(
    ctx: typer.Context,
    count: Annotated[int, typer.Option("--count", "-n", min=1, max=100000,
                                       help="Round trips to time, per block.")] = 20,
    allow_model_mismatch: AllowMismatch = False,
) -> None:
    """Reach every block, time round trips, and run the lifecycle to active and back."""
    opts = options(ctx)
    with open_robot(opts, allow_model_mismatch) as robot:
        result = robot.connect(count)  # each block's lifecycle goes on to its end
    if opts.json:
        emit_json(result)
    else:
        for b, m in zip(result["blocks"], robot.blocks):
            rtt = b["rtt_ms"]
            where = b["target"] or "the in-process mock"
            if m.simulated:
                where = f"its simulator at {where} ({m.simulated})"
            say(f"{b['name']}: connected to {where}: round trip median "
                f"{rtt['median']} ms (min {rtt['min']}, max {rtt['max']}, "
                f"n={b['round_trips']})")
            say(f"{b['name']}: lifecycle " + " → ".join(b["lifecycle"]))
    finish(robot.system)


def identify(ctx: typer.Context, allow_model_mismatch: AllowMismatch = False) -> None:
    """What each block's device says it is (model, firmware, servos, joints), against the
    profile."""
    opts = options(ctx)
    with open_robot(opts, allow_model_mismatch) as robot:
        result = robot.identify()
    if opts.json:
        emit_json(result)
    else:
        for b in result["blocks"]:
            identity_tables({"family": b["family"], "target": b["target"], **b["identity"]},
                            b["name"])
    finish(robot.system)


def identity_tables(ident: dict, title: str | None = None) -> None:
    """Plain fields in one table; each list of parts (joints, servos) in a table of its own,
    one row per part; nested groups recursively."""
    flat = [[k, v] for k, v in ident.items() if not isinstance(v, dict)]
    if flat:
        table(title, ["field", "value"], flat)
    for key, value in ident.items():
        if not isinstance(value, dict):
            continue
        name = f"{title} {key}" if title else key
        rows = list(value.values())
        if rows and all(isinstance(r, dict) and not any(isinstance(x, dict) for x in r.values())
                        for r in rows):
            columns = list(dict.fromkeys(c for r in rows for c in r))
            table(name, ["name", *columns],
                  [[part, *(r.get(c, "") for c in columns)] for part, r in value.items()])
        elif rows and not any(isinstance(r, dict) for r in rows):
            table(name, ["field", "value"], [[k, v] for k, v in value.items()])
        else:
            identity_tables(value, name)


def detect(ctx: typer.Context, allow_model_mismatch: AllowMismatch = False) -> None:
    """What is on each block's device or bus (sensors, GPIO, servos, I2C devices), against
    the profile."""
    opts = options(ctx)
    with open_robot(opts, allow_model_mismatch, probe=True) as robot:
        result = robot.detect()
    if opts.json:
        emit_json(result)
    else:
        for b in result["blocks"]:
            say(b["summary"])
            if "grid" in b["details"]:
                typer.echo(b["details"]["grid"])
            if b["checks"]:
                table(b["name"], ["check", "profile", "device", "match"],
                      [[c["what"], c["profile"], c["device"], "yes" if c["match"] else "NO"]
                       for c in b["checks"]])
    finish(robot.system)


def gpio_get(ctx: typer.Context) -> None:
    """Read every GPIO state interface of every block."""
    opts = options(ctx)
    profile = opts.load_profile()
    if not any(hw.gpios for hw in profile.hardware):
        raise InvalidInput(f"{profile.name} has no GPIO")
    with open_robot(opts, profile=profile) as robot:
        gpio = robot.gpio()
    if opts.json:
        emit_json(gpio)
    else:
        table(None, ["interface", "value"], [[n, f"{v:g}"] for n, v in gpio.items()])
    finish(robot.system)


_ON = {"on": 1.0, "true": 1.0, "off": 0.0, "false": 0.0}


def _complete_gpio(ctx: typer.Context, incomplete: str) -> list[str]:
    """The profile's GPIO command interfaces."""
    from deltoctl.cli.profile_cmd import _completion_profile

    prof = _completion_profile(ctx)
    names = [] if prof is None else [n for hw in prof.hardware for c in hw.gpios
                                     for n in c.interface_names("command")]
    return [n for n in names if n.startswith(incomplete)]


def gpio_set(
    ctx: typer.Context,
    name: Annotated[str, typer.Argument(
        autocompletion=_complete_gpio,
        help="A GPIO command interface, e.g. gpio/output_2 (Delto: motor on, grasp, release), "
             "flange_vacuum/vacuum; output_2 alone when the profile has one GPIO 'gpio'.")],
    value: Annotated[str, typer.Argument(help="on, off or a number.")],
) -> None:
    """Set one GPIO output and read it back (a Delto's three outputs travel together)."""
    import math

    opts = options(ctx)
    try:
        number = _ON[value.lower()] if value.lower() in _ON else float(value)
    except ValueError:
        raise InvalidInput(f"value must be on, off or a number, got {value!r}") from None
    if not math.isfinite(number):
        raise InvalidInput(f"value must be finite, got {value!r}")
    with open_robot(opts) as robot:
        after = robot.set_gpio(name, number)
    if opts.json:
        emit_json(after)
    else:
        say(f"{robot.gpio_output(name)} = {number:g}")
    finish(robot.system)


LIVE_PERIOD = 0.05  # s between redraws of the live table: people read at most 20 a second
RateOpt = Annotated[float, typer.Option("--rate", "-r", help="Samples per second.")]
DurationOpt = Annotated[float | None, typer.Option(
    "--duration", "-d", help="Stop after this many seconds (default: Ctrl-C or SIGTERM).")]


def stream_grids(names: list[str]) -> dict[str, list[list[str]]]:
    """The tactile grids among streamed interfaces: each part whose streamed interfaces are
    all ``cell_<row>_<col>`` of a full grid → its interface names, row by row."""
    from deltoctl.record.cdr import grid_cells

    parts: dict[str, list[str]] = {}
    for name in names:
        part, _, interface = name.rpartition("/")
        parts.setdefault(part, []).append(interface)
    grids = {}
    for part, interfaces in parts.items():
        grid = grid_cells(interfaces) if interfaces[0].startswith("cell_") else None
        if grid is not None:
            rows, cols, cells = grid
            grids[part] = [[f"{part}/{c}" for c in cells[r * cols:(r + 1) * cols]]
                           for r in range(rows)]
    return grids


def _cell(value: float | None) -> float | int | None:
    """A cell as JSON: an integer reading as an integer."""
    return int(value) if isinstance(value, float) and value.is_integer() else value


class LinesSink(Sink):
    """NDJSON frames on stdout: ``{"t": ns, "values": {...}}``, and with tactile sensors
    ``"grids": {sensor: [[cell, ...], ...]}``, each grid as its rows (row 0 first)."""

    def __init__(self, names: list[str]) -> None:
        self.names = names
        self.samples = 0
        self.grids = stream_grids(names)

    def frame(self, t_ns: int, values: dict[str, float]) -> None:
        self.samples += 1
        line: dict[str, Any] = {"t": t_ns, "values": {n: values.get(n) for n in self.names}}
        if self.grids:
            line["grids"] = {part: [[_cell(values.get(n)) for n in row] for row in rows]
                             for part, rows in self.grids.items()}
        emit_json_line(line)


class LiveSink(LinesSink):
    """The live table on a terminal, redrawn at most 20 times a second."""

    def __init__(self, names: list[str], rate: float) -> None:
        from rich.live import Live

        super().__init__(names)
        self.rate = rate
        self.shown = 0.0
        self.live = Live(auto_refresh=False)
        self.live.start()

    def frame(self, t_ns: int, values: dict[str, float]) -> None:
        self.samples += 1
        if time.monotonic() - self.shown >= LIVE_PERIOD:
            sample = {n: values.get(n) for n in self.names}
            self.live.update(live_tables(sample, f"{self.samples} samples at {self.rate:g} Hz"),
                             refresh=True)
            self.shown = time.monotonic()

    def close(self, _: Any) -> None:
        self.live.stop()


def stream(
    ctx: typer.Context,
    rate: RateOpt = 50.0,
    duration: DurationOpt = None,
    interfaces: Annotated[list[str] | None, typer.Option(
        "--interfaces", "-i", help="Glob(s) of interface names, e.g. 'rj_dg_1_*/position'.")]
        = None,
    allow_model_mismatch: AllowMismatch = False,
    foxglove: Annotated[bool, typer.Option(
        "--foxglove", help="Serve the values to Foxglove too (WebSocket, the topics and messages "
                           "of a recording); needs pip install 'deltoctl\\[foxglove]'.")] = False,
    foxglove_port: Annotated[int, typer.Option(
        "--foxglove-port", metavar="PORT", help="The Foxglove WebSocket port (0: any free "
                                                "one).")] = 8765,
    foxglove_host: Annotated[str, typer.Option(
        "--foxglove-host", metavar="ADDRESS", help="The address to serve Foxglove on; another "
        "than loopback serves the robot's data to other machines.")] = "127.0.0.1",
    foxglove_origin: Annotated[list[str] | None, typer.Option(
        "--foxglove-origin", metavar="ORIGIN", help="Also let in browser pages of this origin "
        "(repeatable); by default only Foxglove's own and clients that send no Origin.")]
        = None,
) -> None:
    """Stream every block's state interfaces: a live table on a terminal, NDJSON with --json
    or when piped; with --foxglove, to Foxglove as well (every interface, whatever -i picks).
    Exit 4 when a link is down at the end, 3 when one was lost and came back."""
    import dataclasses

    from deltoctl.cli.record_cmd import foxglove_live, start_foxglove
    from deltoctl.core.runner import run_cycles

    opts = options(ctx)
    check_loop(rate, duration)
    with foxglove_live(foxglove, foxglove_host, foxglove_port, foxglove_origin) as live, \
            open_robot(opts, allow_model_mismatch) as robot:
        system = robot.system
        names = robot.interfaces(interfaces or [])
        sink = (LinesSink(names) if opts.json or not stdout_is_terminal()
                else LiveSink(names, rate))
        links = LinkWatch(system)
        sinks: list[Sink] = [sink, links]
        if live is not None:
            start_foxglove(live, dataclasses.replace(system.profile,
                                                     hardware=[m.hw for m in system]),
                           tuple(system.extra_states()))
            sinks.append(live)
        stats = run_cycles(system, rate, duration, sinks)
    info(f"{sink.samples} samples of {len(names)} interfaces")
    if opts.json:  # stdout holds the frames: the stream's document goes to stderr
        emit_json({"samples": sink.samples, "interfaces": len(names),
                   "loop": stats.summary()}, err=True)
    links.finish()
    finish(system)


def heat_maps(sample: dict[str, Any], grids: dict[str, list[list[str]]]) -> Any:
    """Each tactile grid as a small heat map (its cells' values on a dark → red → yellow
    scale, the hottest cell of the sample at the top), side by side; the grids' common name
    above them, each titled by the rest of its name."""
    import os

    from rich.columns import Columns
    from rich.style import Style
    from rich.table import Table
    from rich.text import Text

    top = max([1.0] + [v for rows in grids.values() for row in rows for n in row
                       if isinstance(v := sample.get(n), int | float) and v == v])
    # the names' common start as strings (not as paths), cut after its last _
    common = os.path.commonprefix(list(grids)) if len(grids) > 1 else ""  # noqa: RUF071
    common = common[:common.rfind("_") + 1]
    maps = []
    for part, rows in grids.items():
        t = Table(title=part[len(common):] or part, show_header=False, box=None, padding=0,
                  title_justify="left")
        for _ in rows[0]:
            t.add_column(justify="right", width=6, no_wrap=True)
        for row in rows:
            cells = []
            for name in row:
                v = sample.get(name)
                if not isinstance(v, int | float) or v != v:
                    cells.append(Text("     —"))
                    continue
                f = max(0.0, min(1.0, v / top))
                red, green = min(255, 40 + int(430 * f)), max(0, min(255, int(510 * f) - 255))
                style = Style(bgcolor=f"rgb({red},{green},{int(40 * (1 - f))})",
                              color="black" if f > 0.6 else "white")
                cells.append(Text(f"{v:6.0f}", style=style))
            t.add_row(*cells)
        maps.append(t)
    return Columns(maps, padding=(1, 2), title=common.rstrip("_") or None)


def live_tables(sample: dict[str, Any], title: str) -> Any:
    """One row per part and a column per interface: a table for each set of interfaces
    (joints, F/T sensors, GPIO), so a hand of 20 joints fits on a screen; the links' states in
    the title; each tactile grid as a heat map below. Laid out for the console it is drawn
    on: columns that do not fit its width go to a table of their own below (the part's name
    repeated), so no value is ever cut."""
    from rich import box
    from rich.table import Table

    grids = stream_grids(list(sample))
    parts: dict[str, dict[str, Any]] = {}
    links: dict[str, Any] = {}
    for name, value in sample.items():
        part, _, interface = name.rpartition("/")
        if interface == "connection_status":
            links[part] = value
        elif part not in grids:
            parts.setdefault(part, {})[interface] = value
    overall = links.pop("system", None)
    if overall is not None:
        down = [p for p, v in links.items() if not v]
        title += (" · links up" if overall else
                  f" · [bold red]link lost: {', '.join(down) or 'reconnecting'}[/]")
    sets: dict[tuple[str, ...], list[tuple[str, list[str]]]] = {}
    for part, values in parts.items():
        sets.setdefault(tuple(values), []).append(
            (part, ["—" if v is None else f"{v:.4g}" for v in values.values()]))

    def chunks(columns: tuple[str, ...], rows: list, width: int) -> list[list[int]]:
        """Column indexes per table: as many as fit ``width`` (a column costs its text + 3,
        a table 1 more)."""
        start = used = max(len(p) for p, _ in rows) + 4
        out: list[list[int]] = [[]]
        for i, column in enumerate(columns):
            cost = max([len(column)] + [len(r[i]) for _, r in rows]) + 3
            if out[-1] and used + cost > width:
                out.append([])
                used = start
            out[-1].append(i)
            used += cost
        return out

    class Tables:
        def __rich_console__(self, console: Any, options: Any) -> Any:
            first = True
            for columns, rows in sets.items():
                for chunk in chunks(columns, rows, options.max_width):
                    t = Table(title=title if first else None, title_justify="left",
                              box=box.SIMPLE_HEAD)
                    first = False
                    t.add_column(no_wrap=True)
                    for i in chunk:
                        t.add_column(columns[i], justify="right", overflow="fold")
                    for part, cells in rows:
                        t.add_row(part, *(cells[i] for i in chunk))
                    yield t
            if grids:
                yield heat_maps(sample, grids)

    return Tables()
