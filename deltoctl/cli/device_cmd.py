"""The lifecycle verbs on every block of a robot: connect, identify, detect, gpio, stream."""

import contextlib
from collections.abc import Callable, Iterator, Sequence
from typing import Annotated, Any

import typer

from deltoctl.cli.completions import complete_gpio
from deltoctl.cli.confirm import confirm
from deltoctl.cli.context import Options, options
from deltoctl.cli.output import emit_json, emit_json_line, info, show, stdout_is_terminal, warn
from deltoctl.core.runner import check_loop
from deltoctl.errors import WARNINGS, InvalidInput

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

    prof = profile or opts.load_profile()
    with open_app_robot(prof, opts.target, sim=opts.sim_of(prof), hardware=opts.hardware,
                        allow_model_mismatch=allow_model_mismatch, probe=probe, notice=info,
                        served_by=SERVED_SIMULATED, reuse=not opts.sim_fresh,
                        warn=warn) as robot:
        try:
            yield robot
        finally:
            if SET_SAFE:
                robot.make_safe()


def finish(robot: Any, extra: list[str] | None = None,
           failures: list[dict[str, Any]] | None = None) -> None:
    """Exit 1 naming each check of ``failures`` that failed; exit 3 when the verb finished but
    with warnings (a block left out, a model mismatch allowed, reconnects; ``extra``)."""
    from deltoctl.app.checks import fail_on

    warnings = robot.warnings() + (extra or [])
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


def on_robot(ctx: typer.Context, call: Callable[[Any], Any],
             people: Callable[[Any, Any], Sequence[Any]], allow_model_mismatch: bool = False,
             profile: Any = None, probe: bool = False, judged: bool = False) -> Any:
    """A verb's one call on the robot (``call(robot)``); its result as JSON, or for people
    (``people(result, robot)``: lines and tables); its warnings (exit 3), and with ``judged``
    its failed ``checks`` (exit 1)."""
    opts = options(ctx)
    with open_robot(opts, allow_model_mismatch, profile, probe) as robot:
        result = call(robot)
    if opts.json:
        emit_json(result)
    else:
        show(people(result, robot))
    finish(robot, failures=result["checks"] if judged else None)
    return result


def connect(
    ctx: typer.Context,
    count: Annotated[int, typer.Option("--count", "-n", min=1, max=100000,
                                       help="Round trips to time, per block.")] = 20,
    allow_model_mismatch: AllowMismatch = False,
) -> None:
    """Reach every block, time round trips, and run the lifecycle to active and back."""
    from deltoctl.render.identity import connect_lines

    # each block's lifecycle goes on to its end
    on_robot(ctx, lambda robot: robot.connect(count), lambda result, robot: connect_lines(
        result, [m.simulated for m in robot.blocks]), allow_model_mismatch)


def identify(ctx: typer.Context, allow_model_mismatch: AllowMismatch = False) -> None:
    """What each block's device says it is (model, firmware, servos, joints), against the
    profile."""
    from deltoctl.render.identity import identify_tables

    on_robot(ctx, lambda robot: robot.identify(), lambda result, _: identify_tables(result),
             allow_model_mismatch)


def detect(ctx: typer.Context, allow_model_mismatch: AllowMismatch = False) -> None:
    """What is on each block's device or bus (sensors, GPIO, servos, I2C devices), against
    the profile."""
    from deltoctl.render.identity import detect_parts

    on_robot(ctx, lambda robot: robot.detect(), lambda result, _: detect_parts(result),
             allow_model_mismatch, probe=True, judged=True)


def gpio_get(ctx: typer.Context) -> None:
    """Read every GPIO state interface of every block."""
    profile = options(ctx).load_profile()
    if not any(hw.gpios for hw in profile.hardware):
        raise InvalidInput(f"{profile.name} has no GPIO")
    on_robot(ctx, lambda robot: robot.gpio(), lambda gpio, _: [(
        None, ["interface", "value"], [[n, f"{v:g}"] for n, v in gpio.items()])],
        profile=profile)


def gpio_set(
    ctx: typer.Context,
    name: Annotated[str, typer.Argument(
        autocompletion=complete_gpio,
        help="A GPIO command interface, e.g. gpio/output_2 (Delto: motor on, grasp, release), "
             "flange_vacuum/vacuum; output_2 alone when the profile has one GPIO 'gpio'.")],
    value: Annotated[str, typer.Argument(help="on, off or a number.")],
) -> None:
    """Set one GPIO output and read it back (a Delto's three outputs travel together)."""
    from deltoctl.app.robot import gpio_value

    number = gpio_value(value)

    def set_output(robot: Any) -> dict[str, float]:
        full = robot.gpio_output(name)
        confirm(ctx, f"set {full} of {robot.block_of(full)} to {value}")
        return robot.set_gpio(name, number)

    on_robot(ctx, set_output, lambda _, robot: [f"{robot.gpio_output(name)} = {number:g}"])


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
    from deltoctl.app.live import foxglove_live, start_foxglove
    from deltoctl.app.sinks import LinesSink
    from deltoctl.render.stream import LiveSink

    opts = options(ctx)
    check_loop(rate, duration)
    with foxglove_live(foxglove, foxglove_host, foxglove_port, foxglove_origin, warn,
                       info) as live, open_robot(opts, allow_model_mismatch) as robot:
        names = robot.interfaces(interfaces or [])
        sink: Any = (LinesSink(names, emit_json_line) if opts.json or not stdout_is_terminal()
                     else LiveSink(names, rate, robot.joint_types()))
        loop, links = robot.cycles(rate, duration, [sink, *start_foxglove(live, robot, info)])
    info(f"{sink.samples} samples of {len(names)} interfaces")
    if opts.json:  # stdout holds the frames: the stream's document goes to stderr
        emit_json({"samples": sink.samples, "interfaces": len(names), "loop": loop}, err=True)
    links.finish()
    finish(robot, robot.loop_warnings(rate, loop))
