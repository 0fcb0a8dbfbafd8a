"""The lifecycle verbs on every block of a robot: connect, identify, detect, gpio, stream."""

import contextlib
import time
from collections.abc import Iterator
from typing import Annotated, Any

import typer

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
from deltoctl.errors import WARNINGS, DeviceError, InvalidInput

AllowMismatch = Annotated[bool, typer.Option(
    "--allow-model-mismatch",
    help="Go on when a device reports another model than the profile (exit 3).")]


@contextlib.contextmanager
def open_system(opts: Options, allow_model_mismatch: bool = False, profile: Any = None,
                probe: bool = False) -> Iterator[Any]:
    """The System of the selected profile's blocks (``--hardware``), configured and active;
    with ``--sim``, each block's emulator is started first and its URL is the block's target.
    Pass ``profile`` when the verb loaded it already; ``probe`` for a verb that looks at a bus
    where nothing may answer."""
    from deltoctl.core.system import System, mock_blocks

    profile = profile or opts.load_profile()
    with contextlib.ExitStack() as stack:
        targets = list(opts.target)
        simulated = dict.fromkeys(opts.hardware or [hw.name for hw in profile.hardware],
                                  "--sim") if opts.sim else mock_blocks(profile, opts.hardware)
        if simulated:
            from deltoctl.sim.serve import ServeOptions, serve_profile

            served = serve_profile(stack, profile, ServeOptions(), list(simulated))
            targets += [f"{bus}={url}" for bus, url in served["buses"].items()]
            for name, why in simulated.items():
                if why != "--sim":  # the profile asked: say so before anything else
                    info(f"{name}: simulated ({why}): no hardware is driven")
        system = System(profile, targets, opts.hardware, probe=probe,
                        allow_model_mismatch=allow_model_mismatch, simulated=simulated)
        with system:
            yield system


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


def block_entry(m: Any, **data: Any) -> dict[str, Any]:
    """One block in a verb's JSON: the same keys first whatever the family."""
    return {"name": m.name, "family": m.family.name, "target": m.url or None,
            "simulated": m.simulated is not None, "state": m.lifecycle.state, **data}


def connect(
    ctx: typer.Context,
    count: Annotated[int, typer.Option("--count", "-n", min=1, max=100000,
                                       help="Round trips to time, per block.")] = 20,
    allow_model_mismatch: AllowMismatch = False,
) -> None:
    """Reach every block, time round trips, and run the lifecycle to active and back."""
    import statistics

    opts = options(ctx)
    blocks = []
    with open_system(opts, allow_model_mismatch) as system:
        for m in system:
            rtts = []
            for _ in range(count):
                start = time.perf_counter()
                m.driver.round_trip()
                rtts.append((time.perf_counter() - start) * 1e3)
            if not m.driver.connected:
                raise DeviceError(f"{m.name} ({m.url}) stopped answering during the round "
                                  "trips")
            blocks.append((m, {"reachable": True, "round_trips": len(rtts), "rtt_ms": {
                "median": round(statistics.median(rtts), 3), "min": round(min(rtts), 3),
                "max": round(max(rtts), 3)}}))
    result = {"profile": system.profile.name,
              "blocks": [block_entry(m, **data, lifecycle=m.lifecycle.history)
                         for m, data in blocks]}
    if opts.json:
        emit_json(result)
    else:
        for m, data in blocks:
            rtt = data["rtt_ms"]
            where = m.url or "the in-process mock"
            if m.simulated:
                where = f"its simulator at {where} ({m.simulated})"
            say(f"{m.name}: connected to {where}: round trip median "
                f"{rtt['median']} ms (min {rtt['min']}, max {rtt['max']}, "
                f"n={data['round_trips']})")
            say(f"{m.name}: lifecycle " + " → ".join(m.lifecycle.history))
    finish(system)


def identify(ctx: typer.Context, allow_model_mismatch: AllowMismatch = False) -> None:
    """What each block's device says it is (model, firmware, servos, joints), against the
    profile."""
    opts = options(ctx)
    with open_system(opts, allow_model_mismatch) as system:
        blocks = [block_entry(m, identity=m.driver.identify()) for m in system.able("identify")]
        unable = [m.name for m in system if not m.can("identify")]
    result = {"profile": system.profile.name, "blocks": blocks}
    if opts.json:
        emit_json(result)
    else:
        for b in blocks:
            identity_tables({"family": b["family"], "target": b["target"], **b["identity"]},
                            b["name"])
    finish(system, [f"{', '.join(unable)}: cannot identify"] if unable else None)


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
    blocks = []
    with open_system(opts, allow_model_mismatch, probe=True) as system:
        for m in system.able("detect"):
            found = m.driver.detect()
            blocks.append(block_entry(m, summary=found.pop("summary"),
                                      checks=found.pop("checks"), details=found))
    if opts.json:
        emit_json({"profile": system.profile.name, "blocks": blocks})
    else:
        for b in blocks:
            say(b["summary"])
            if "grid" in b["details"]:
                typer.echo(b["details"]["grid"])
            if b["checks"]:
                table(b["name"], ["check", "profile", "device", "match"],
                      [[c["what"], c["profile"], c["device"], "yes" if c["match"] else "NO"]
                       for c in b["checks"]])
    mismatches = [f"{b['name']}: {c['what']}" for b in blocks for c in b["checks"]
                  if not c["match"]]
    finish(system, [f"the device differs from the profile in: {', '.join(mismatches)}"]
           if mismatches else None)


def _gpio_command(system: Any, output: str) -> str:
    """The GPIO command interface a bare name (``output_2``) means: the one of that name."""
    found = [n for m in system for c in m.hw.gpios for n in c.interface_names("command")
             if n.endswith("/" + output)]
    if len(found) == 1:
        return found[0]
    if found:
        raise InvalidInput(f"{output} is ambiguous: name one of {', '.join(found)}")
    from deltoctl.suggest import did_you_mean

    commands = [n for m in system for c in m.hw.gpios for n in c.interface_names("command")]
    raise InvalidInput(f"{system.profile.name} has no GPIO output {output!r}"
                       + (did_you_mean(output, commands) or
                          f" (its outputs: {', '.join(commands) or 'none'})"))


def _gpio_names(system: Any) -> list[str]:
    return [n for m in system for c in m.hw.gpios for n in c.interface_names("state")]


def gpio_get(ctx: typer.Context) -> None:
    """Read every GPIO state interface of every block."""
    opts = options(ctx)
    profile = opts.load_profile()
    if not any(hw.gpios for hw in profile.hardware):
        raise InvalidInput(f"{profile.name} has no GPIO")
    with open_system(opts, profile=profile) as system:
        values = system.read()
        names = [n for n in _gpio_names(system) if n in values]
    if not names:
        raise DeviceError("the devices send no GPIO values (no GPIO on this model, or IO is "
                          "false in the profile)")
    gpio = {n: values[n] for n in names}
    if opts.json:
        emit_json(gpio)
    else:
        table(None, ["interface", "value"], [[n, f"{v:g}"] for n, v in gpio.items()])
    finish(system)


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
    with open_system(opts) as system:
        full = name if "/" in name else _gpio_command(system, name)
        m = system.member(full)
        if not m.can("gpio"):
            raise InvalidInput(f"{m.name} has no GPIO outputs to set")
        m.driver.set_command(full, number)
        after = dict(system.read())
        names = _gpio_names(system)
    if full in after and after[full] != number:
        raise DeviceError(f"{full} reads back {after[full]:g} after setting it to {number:g}")
    if opts.json:
        emit_json({n: after[n] for n in names if n in after})
    else:
        say(f"{full} = {number:g}")
    finish(system)


def select(names: list[str], patterns: list[str]) -> list[str]:
    import fnmatch

    if not patterns:
        return names
    globs = [p for item in patterns for p in item.split(",") if p]
    chosen = [n for n in names if any(fnmatch.fnmatchcase(n, g) for g in globs)]
    if not chosen:
        from deltoctl.suggest import did_you_mean

        typed = globs[0].translate(str.maketrans("", "", "*?[]")) if globs else ""
        raise InvalidInput(f"--interfaces {','.join(globs)} matches no interface"
                           + did_you_mean(typed, names))
    return chosen


def check_loop(rate: float, duration: float | None) -> None:
    """--rate and --duration: finite and positive."""
    import math

    if not (math.isfinite(rate) and 0 < rate <= 100_000):
        raise InvalidInput(f"--rate must be a positive number of Hz up to 100000, got {rate:g}")
    if duration is not None and not (math.isfinite(duration) and duration > 0):
        raise InvalidInput(f"--duration must be a positive number of seconds, got {duration:g}")


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
) -> None:
    """Stream every block's state interfaces: a live table on a terminal, NDJSON with --json
    or when piped; with --foxglove, to Foxglove as well (every interface, whatever -i picks).
    Exit 4 when a link is down at the end, 3 when one was lost and came back."""
    import dataclasses

    from deltoctl.cli.record_cmd import foxglove_live, start_foxglove
    from deltoctl.core.runner import run_cycles

    opts = options(ctx)
    check_loop(rate, duration)
    with foxglove_live(foxglove, foxglove_host, foxglove_port) as live, \
            open_system(opts, allow_model_mismatch) as system:
        names = select(system.state_interfaces(), list(interfaces or []))
        sink = (LinesSink(names) if opts.json or not stdout_is_terminal()
                else LiveSink(names, rate))
        links = LinkWatch(system)
        sinks: list[Sink] = [sink, links]
        if live is not None:
            start_foxglove(live, dataclasses.replace(system.profile,
                                                     hardware=[m.hw for m in system]),
                           tuple(system.extra_states()))
            sinks.append(live)
        run_cycles(system, rate, duration, sinks)
    info(f"{sink.samples} samples of {len(names)} interfaces")
    links.finish()
    finish(system)


class LinkWatch(Sink):
    """Counts link losses per block; at the end, a block whose link is still down is
    unreachable (exit 4)."""

    def __init__(self, system: Any) -> None:
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
        from deltoctl.errors import Unreachable

        down = [self.keys[k].name for k, up in self.up.items() if not up]
        if down:
            raise Unreachable(f"the link to {', '.join(down)} was lost and did not come back")
        for name, n in self.losses.items():
            self.system.notes.append(f"{name}: the link was lost {n} time(s) and came back")


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
