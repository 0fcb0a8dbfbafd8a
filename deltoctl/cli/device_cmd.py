"""The lifecycle verbs on every block of a robot: connect, identify, detect, gpio, stream."""

import contextlib
from collections.abc import Iterator
from typing import Annotated, Any

import typer

from deltoctl.app.robot import check_loop
from deltoctl.app.sinks import LinkWatch
from deltoctl.cli.confirm import confirm
from deltoctl.cli.context import Options, options
from deltoctl.cli.output import (
    emit_json,
    emit_json_line,
    info,
    say,
    show,
    stdout_is_terminal,
    table,
    warn,
)
from deltoctl.errors import WARNINGS, InvalidInput, NotHomed

AllowMismatch = Annotated[bool, typer.Option(
    "--allow-model-mismatch",
    help="Go on when a device reports another model than the profile (exit 3).")]


# why every block runs on a simulator that -t names like a device: set by 'deltoctl agent
# --sim' in the processes that run its verbs, so that their JSON and recordings say simulated
SERVED_SIMULATED: str | None = None
# every block set safe on the way out, whatever the verb sent: set by the agent's verb process
# that runs the connect after a motion verb was killed (deltoctl.fleet.SET_SAFE)
SET_SAFE = False


@contextlib.contextmanager
def open_robot(opts: Options, allow_model_mismatch: bool = False, profile: Any = None,
               probe: bool = False) -> Iterator[Any]:
    """The robot of the selected profile's blocks (``--hardware``), configured and active;
    with ``--sim``, on the ``sim serve`` of this profile running for the user, else on
    simulators started first. Pass ``profile`` when the verb loaded it already; ``probe`` for
    a verb that looks at a bus where nothing may answer."""
    from deltoctl.app.robot import open_robot as open_app_robot
    from deltoctl.sim import running

    prof = profile or opts.load_profile()
    sim: Any = opts.sim
    if opts.sim and opts.sim_options:
        from deltoctl.sim.serve import options_given

        sim = options_given(opts.sim_options, "--sim-option", prof, opts.hardware)
    found = (running.find(prof, sim if isinstance(sim, dict) else {}, opts.hardware, warn)
             if opts.sim and not opts.sim_fresh else None)
    if found is not None:
        info(f"using {found.name} of {found.profile}; --sim-fresh starts one of its own")
    try:
        with open_app_robot(prof, [*opts.target, *found.targets] if found else opts.target,
                            sim=False if found else sim, hardware=opts.hardware,
                            allow_model_mismatch=allow_model_mismatch, probe=probe, notice=info,
                            served_by=found.name if found else SERVED_SIMULATED) as robot:
            try:
                yield robot
            finally:
                if SET_SAFE:
                    robot.system.make_safe()
    except NotHomed as exc:
        if opts.sim and found is None:
            exc.hint = running.fresh_hint(prof.name)
        raise


def finish(system: Any, extra: list[str] | None = None,
           failures: list[dict[str, Any]] | None = None) -> None:
    """Exit 3 when the verb finished but with warnings (a block left out, a model mismatch
    allowed, reconnects); exit 1 naming each check of ``failures`` that failed."""
    from deltoctl.app.checks import fail_on

    warnings = system.warnings() + (extra or [])
    for w in warnings:
        warn(w)
    fail_on(failures or [])
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
        from deltoctl.render.identity import connect_lines

        show(connect_lines(result, [m.simulated for m in robot.blocks]))
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
        from deltoctl.render.identity import identify_tables

        show(identify_tables(result))
    finish(robot.system)


def detect(ctx: typer.Context, allow_model_mismatch: AllowMismatch = False) -> None:
    """What is on each block's device or bus (sensors, GPIO, servos, I2C devices), against
    the profile."""
    opts = options(ctx)
    with open_robot(opts, allow_model_mismatch, probe=True) as robot:
        result = robot.detect()
    if opts.json:
        emit_json(result)
    else:
        from deltoctl.render.identity import detect_parts

        show(detect_parts(result))
    finish(robot.system, failures=result["checks"])


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
        full = robot.gpio_output(name)
        confirm(ctx, f"set {full} of {robot.system.member(full).name} to {value}")
        after = robot.set_gpio(name, number)
    if opts.json:
        emit_json(after)
    else:
        say(f"{full} = {number:g}")
    finish(robot.system)


RateOpt = Annotated[float, typer.Option("--rate", "-r", help="Samples per second.")]
DurationOpt = Annotated[float | None, typer.Option(
    "--duration", "-d", help="Stop after this many seconds (default: Ctrl-C or SIGTERM).")]
# the live view in Foxglove, served by stream and by record (in the words of each one's help)
_SERVE = ("to Foxglove too (WebSocket, the topics and messages of a recording); needs pip "
          "install 'deltoctl\\[foxglove]'.")
FoxgloveOpt = Annotated[bool, typer.Option("--foxglove", help=f"Serve the live values {_SERVE}")]
StreamFoxgloveOpt = Annotated[bool, typer.Option("--foxglove", help=f"Serve the values {_SERVE}")]
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
StreamOriginOpt = Annotated[list[str] | None, typer.Option(
    "--foxglove-origin", metavar="ORIGIN", help="Also let in browser pages of this origin "
    "(repeatable); by default only Foxglove's own and clients that send no Origin.")]


@contextlib.contextmanager
def foxglove_live(enabled: bool, host: str, port: int,
                  origins: list[str] | None = None) -> Iterator[Any]:
    """With --foxglove, the Foxglove sink, its address and port checked before the devices
    are opened (the server starts with ``start_foxglove``, and stops on the way out); else
    None."""
    if not enabled:
        yield None
        return
    from deltoctl.record.foxglove_live import FoxgloveLive

    with FoxgloveLive(host, port, origins=tuple(origins or ())) as live:
        if not live.local:
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


def start_foxglove(live: Any, system: Any, gpio_type: str = "group-values") -> list[Any]:
    """With --foxglove (``live``), the server started with the topics of the blocks ``system``
    drives, where it is said on stderr, and the live view as the loop's sink; else no sink."""
    if live is None:
        return []
    from deltoctl.app.recording import driven_profile

    live.begin(driven_profile(system), tuple(system.extra_states()), gpio_type)
    info(f"Foxglove: connect to {live.url} (Open connection → Foxglove WebSocket)")
    return [live]


def stream(
    ctx: typer.Context,
    rate: RateOpt = 50.0,
    duration: DurationOpt = None,
    interfaces: Annotated[list[str] | None, typer.Option(
        "--interfaces", "-i", help="Glob(s) of interface names, e.g. 'rj_dg_1_*/position'.")]
        = None,
    allow_model_mismatch: AllowMismatch = False,
    foxglove: StreamFoxgloveOpt = False,
    foxglove_port: FoxglovePortOpt = 8765,
    foxglove_host: FoxgloveHostOpt = "127.0.0.1",
    foxglove_origin: StreamOriginOpt = None,
) -> None:
    """Stream every block's state interfaces: a live table on a terminal (fitted to it; the
    rows that do not fit are counted, -i picks fewer), NDJSON with --json or when piped; with
    --foxglove, to Foxglove as well (every interface, whatever -i picks). Exit 4 when a link
    is down at the end, 3 when one was lost and came back."""
    from deltoctl.app.latency import loop_warnings
    from deltoctl.app.sinks import LinesSink
    from deltoctl.core.runner import run_cycles
    from deltoctl.render.stream import LiveSink

    opts = options(ctx)
    check_loop(rate, duration)
    with foxglove_live(foxglove, foxglove_host, foxglove_port, foxglove_origin) as live, \
            open_robot(opts, allow_model_mismatch) as robot:
        system = robot.system
        names = robot.interfaces(interfaces or [])
        sink: Any = (LinesSink(names, emit_json_line) if opts.json or not stdout_is_terminal()
                     else LiveSink(names, rate, robot.joint_types()))
        links = LinkWatch(system)
        stats = run_cycles(system, rate, duration, [sink, links, *start_foxglove(live, system)])
    info(f"{sink.samples} samples of {len(names)} interfaces")
    if opts.json:  # stdout holds the frames: the stream's document goes to stderr
        emit_json({"samples": sink.samples, "interfaces": len(names),
                   "loop": stats.summary()}, err=True)
    links.finish()
    finish(system, loop_warnings([m.url for m in system.members], rate,
                                 stats.summary()["real_rate"]))
