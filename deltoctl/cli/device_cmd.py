"""The lifecycle verbs on a device: connect, identify, detect, gpio, stream."""

import time
from typing import Annotated, Any

import typer

from deltoctl.cli.context import Options, options
from deltoctl.cli.output import emit_json, emit_json_line, info, say, stdout_is_terminal, table
from deltoctl.errors import WARNINGS, DeviceError, InvalidInput

AllowMismatch = Annotated[bool, typer.Option(
    "--allow-model-mismatch",
    help="Go on when the gripper reports another model than the profile (exit 3).")]


def open_session(opts: Options, allow_model_mismatch: bool = False,  # type: ignore[no-untyped-def]
                 profile: Any = None, probe: bool = False):
    """A session on the selected profile (pass ``profile`` when the verb loaded it already;
    ``probe`` for a verb that looks at a bus where nothing may answer)."""
    from deltoctl.core.session import Session

    return Session(profile or opts.load_profile(), opts.target, sim=opts.sim,
                   allow_model_mismatch=allow_model_mismatch, probe=probe)


def finish(session: Any) -> None:
    """Exit 3 when the verb finished but with warnings (a model mismatch allowed, reconnects)."""
    warnings = list(session.driver.warnings)
    if session.driver.stats.get("reconnects"):
        warnings.append(f"the link was lost and re-established "
                        f"{session.driver.stats['reconnects']} time(s)")
    for w in warnings:
        info(f"warning: {w}")
    if warnings:
        raise typer.Exit(WARNINGS)


def register(app: typer.Typer) -> None:
    app.command("connect")(connect)
    app.command("identify")(identify)
    app.command("detect")(detect)
    app.command("stream")(stream)
    gpio_app = typer.Typer(help="Read and set the gripper's GPIO.", no_args_is_help=True)
    gpio_app.command("get")(gpio_get)
    gpio_app.command("set")(gpio_set)
    app.add_typer(gpio_app, name="gpio")


def connect(
    ctx: typer.Context,
    count: Annotated[int, typer.Option("--count", "-n", help="Round trips to time.")] = 20,
    allow_model_mismatch: AllowMismatch = False,
) -> None:
    """Reach the device, time round trips, and run the lifecycle to active and back."""
    import statistics

    opts = options(ctx)
    session = open_session(opts, allow_model_mismatch)
    with session:
        rtts = []
        for _ in range(max(1, count)):
            start = time.perf_counter()
            session.driver.round_trip()
            rtts.append((time.perf_counter() - start) * 1e3)
        if not session.driver.connected:
            raise DeviceError(f"{session.url} stopped answering during the round trips")
    result = {
        "target": session.url,
        "reachable": True,
        "round_trips": len(rtts),
        "rtt_ms": {"median": round(statistics.median(rtts), 3), "min": round(min(rtts), 3),
                   "max": round(max(rtts), 3)},
        "lifecycle": session.lifecycle.history,
    }
    if opts.json:
        emit_json(result)
    else:
        say(f"connected to {session.url}: round trip median {result['rtt_ms']['median']} ms "
             f"(min {result['rtt_ms']['min']}, max {result['rtt_ms']['max']}, n={len(rtts)})")
        say("lifecycle: " + " → ".join(session.lifecycle.history))
    finish(session)


def identify(ctx: typer.Context, allow_model_mismatch: AllowMismatch = False) -> None:
    """What the device says it is (model, firmware, direction map, flags), against the profile."""
    opts = options(ctx)
    with open_session(opts, allow_model_mismatch) as session:
        ident = session.driver.identity.as_dict()
    ident["profile"] = session.profile.name
    ident["target"] = session.url
    if opts.json:
        emit_json(ident)
    else:
        _identity_tables(ident)
    finish(session)


def _identity_tables(ident: dict, title: str | None = None) -> None:
    """Plain fields in one table; each list of parts (joints, servos) in a table of its own,
    one row per part; nested groups (buses) recursively."""
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
        else:
            _identity_tables(value, name)


def detect(ctx: typer.Context, allow_model_mismatch: AllowMismatch = False) -> None:
    """What is on the device or bus (sensors, GPIO, servos, I2C devices), against the profile."""
    opts = options(ctx)
    with open_session(opts, allow_model_mismatch, probe=True) as session:
        result = session.driver.detect()
    checks = result["checks"]
    if opts.json:
        emit_json({k: v for k, v in result.items() if k != "summary"})
    else:
        say(result["summary"])
        if "grid" in result:
            typer.echo(result["grid"])
        if checks:
            table(None, ["check", "profile", "device", "match"],
                  [[c["what"], c["profile"], c["device"], "yes" if c["match"] else "NO"]
                   for c in checks])
    mismatches = [c["what"] for c in checks if not c["match"]]
    if mismatches:
        info(f"warning: the device differs from the profile in: {', '.join(mismatches)}")
        raise typer.Exit(WARNINGS)
    finish(session)


def _gpio_names(profile: Any) -> list[str]:
    return [n for _, c in profile.components() if c.kind == "gpio"
            for n in c.interface_names("state")]


def gpio_get(ctx: typer.Context) -> None:
    """Read every GPIO state interface."""
    opts = options(ctx)
    with open_session(opts) as session:
        values = session.driver.read()
        names = [n for n in _gpio_names(session.profile) if n in values]
    if not names:
        raise DeviceError("the device sends no GPIO values (no GPIO on this model, or IO is "
                          "false in the profile)")
    gpio = {n: values[n] for n in names}
    if opts.json:
        emit_json(gpio)
    else:
        table(None, ["interface", "value"], [[n, f"{v:g}"] for n, v in gpio.items()])


_ON = {"on": 1.0, "true": 1.0, "off": 0.0, "false": 0.0}


def gpio_set(
    ctx: typer.Context,
    name: Annotated[str, typer.Argument(help="A GPIO command interface, e.g. output_2 or "
                                        "gpio/output_2 (Delto: motor on, grasp, release), "
                                        "flange_vacuum/vacuum.")],
    value: Annotated[str, typer.Argument(help="on, off or a number.")],
) -> None:
    """Set one GPIO output and read it back (a Delto's three outputs travel together)."""
    opts = options(ctx)
    try:
        number = _ON[value.lower()] if value.lower() in _ON else float(value)
    except ValueError:
        raise InvalidInput(f"value must be on, off or a number, got {value!r}") from None
    with open_session(opts) as session:
        full = name if "/" in name else f"gpio/{name}"
        session.driver.set_command(full, number)
        after = dict(session.driver.read())
        names = _gpio_names(session.profile)
    if full in after and after[full] != number:
        raise DeviceError(f"{full} reads back {after[full]:g} after setting it to {number:g}")
    if opts.json:
        emit_json({n: after[n] for n in names if n in after})
    elif not opts.quiet:
        say(f"{full} = {number:g}")


def _select(names: list[str], patterns: list[str]) -> list[str]:
    import fnmatch

    if not patterns:
        return names
    globs = [p for item in patterns for p in item.split(",") if p]
    chosen = [n for n in names if any(fnmatch.fnmatchcase(n, g) for g in globs)]
    if not chosen:
        raise InvalidInput(f"--interfaces {','.join(globs)} matches no interface")
    return chosen


LIVE_PERIOD = 0.05  # s between redraws of the live table: people read at most 20 a second
RateOpt = Annotated[float, typer.Option("--rate", "-r", help="Samples per second.")]
DurationOpt = Annotated[float | None, typer.Option(
    "--duration", "-d", help="Stop after this many seconds (default: Ctrl-C or SIGTERM).")]


def stream(
    ctx: typer.Context,
    rate: RateOpt = 50.0,
    duration: DurationOpt = None,
    interfaces: Annotated[list[str] | None, typer.Option(
        "--interfaces", "-i", help="Glob(s) of interface names, e.g. 'rj_dg_1_*/position'.")]
        = None,
    allow_model_mismatch: AllowMismatch = False,
) -> None:
    """Stream state interfaces: a live table on a terminal, NDJSON with --json or when piped."""
    import signal

    from deltoctl.core.loop import CycleLoop

    opts = options(ctx)
    if rate <= 0:
        raise InvalidInput("--rate must be positive")
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    as_lines = opts.json or not stdout_is_terminal()
    with open_session(opts, allow_model_mismatch) as session:
        driver = session.driver
        extras = [f"{j.name}/{e}" for j in session.profile.joints()
                  for e in driver.extra_states]  # e.g. a Bioscara joint's flags
        names = _select([*session.profile.state_interfaces(), *extras,
                         "system/connection_status"], list(interfaces or []))
        live = None
        if not as_lines:
            from rich.live import Live

            live = Live(auto_refresh=False)
            live.start()
        samples, shown = 0, 0.0
        try:
            for _ in CycleLoop(rate, duration):
                values = driver.read()
                sample = {n: values.get(n) for n in names}
                samples += 1
                if live is None:
                    emit_json_line({"t": time.time_ns(), "values": sample})
                elif time.monotonic() - shown >= LIVE_PERIOD:
                    live.update(live_tables(sample, f"{samples} samples at {rate:g} Hz"),
                                refresh=True)
                    shown = time.monotonic()
        except KeyboardInterrupt:
            pass
        finally:
            if live is not None:
                live.stop()
    if not opts.quiet:
        info(f"{samples} samples of {len(names)} interfaces")
    finish(session)


def live_tables(sample: dict[str, Any], title: str):  # type: ignore[no-untyped-def]
    """One row per part and a column per interface: a table for each set of interfaces
    (joints, F/T sensors, GPIO), so a hand of 20 joints fits on a screen."""
    from rich import box
    from rich.console import Group
    from rich.table import Table

    parts: dict[str, dict[str, Any]] = {}
    for name, value in sample.items():
        part, _, interface = name.rpartition("/")
        parts.setdefault(part, {})[interface] = value
    link = parts.pop("system", {}).get("connection_status")
    if link is not None:
        title += " · link up" if link else " · [bold red]link lost, reconnecting[/]"
    tables: dict[tuple[str, ...], Table] = {}
    for part, values in parts.items():
        columns = tuple(values)
        if columns not in tables:
            tables[columns] = t = Table(title=None if tables else title, title_justify="left",
                                        box=box.SIMPLE_HEAD)
            t.add_column(no_wrap=True)
            for column in columns:
                t.add_column(column, justify="right")
        tables[columns].add_row(part, *("—" if v is None else f"{v:.4g}"
                                        for v in values.values()))
    return Group(*tables.values())
