"""``deltoctl sim serve PROFILE``: a simulated device in its own process."""

import contextlib
from typing import Annotated

import typer

from deltoctl.cli.context import options
from deltoctl.errors import InvalidInput

app = typer.Typer(help="Simulated devices that speak the real protocol.", no_args_is_help=True)


def _complete_profile(incomplete: str) -> list[str]:
    from deltoctl.cli.profile_cmd import _complete_profile as names

    return names(incomplete)


def _complete_joint(ctx: typer.Context, incomplete: str) -> list[str]:
    """Joints of the PROFILE argument (or --profile), for the faults that name one."""
    from deltoctl.cli.profile_cmd import complete_joints

    return complete_joints(ctx, incomplete)


@app.command("serve")
def serve(
    ctx: typer.Context,
    profile: Annotated[str | None, typer.Argument(
        metavar="[PROFILE]", autocompletion=_complete_profile,
        help="Catalog name or file; default: --profile.")] = None,
    host: Annotated[str, typer.Option(help="Address to listen on.")] = "127.0.0.1",
    port: Annotated[int, typer.Option(help="TCP port (0: any free port).")] = 0,
    firmware: Annotated[str, typer.Option(
        help="Firmware version the device reports, MAJOR.MINOR.")] = "3.0",
    model_id: Annotated[str | None, typer.Option(
        help="Emulate another model than the profile's (e.g. 0x3F02), to rehearse a "
             "mismatch.")] = None,
    short_version: Annotated[bool, typer.Option(
        help="Send the short GET_VERSION reply of old firmware.")] = False,
    input_1: Annotated[bool, typer.Option("--input-1", help="Drive gpio/input_1 high.")]
        = False,
    delay: Annotated[float, typer.Option(help="Fault: seconds added before every reply.")]
        = 0.0,
    stall: Annotated[list[str] | None, typer.Option(
        autocompletion=_complete_joint,
        help="Fault: a joint that cannot move (repeatable).")] = None,
    missing: Annotated[list[str] | None, typer.Option(
        autocompletion=_complete_joint,
        help="Fault: a joint (servo, I2C joint) that never answers (repeatable).")] = None,
    pace: Annotated[bool, typer.Option(
        help="Serial buses take the wire time of every byte at the baud rate the host "
             "set, as a real bus does.")] = False,
    wrong_baud: Annotated[list[str] | None, typer.Option(
        autocompletion=_complete_joint,
        help="Fault: a servo set to another baud rate than its bus (repeatable).")] = None,
    who_am_i: Annotated[str, typer.Option(
        help="WHO_AM_I of a simulated LSM6DS3: 0x69 (LSM6DS3), 0x6A (LSM6DS3TR-C), or "
             "another value to rehearse a wrong part.")] = "0x6A",
    orientation: Annotated[str, typer.Option(
        help="The IMU's roll,pitch in degrees (gravity follows).")] = "0,0",
) -> None:
    """Serve every block's simulated device until Ctrl-C or SIGTERM, printing one target per
    bus (BUS=URL, ready for --target).

    A gripper on loopback TCP, a servo bus on a pseudo-terminal, an I2C bus as i2c+tcp://;
    --hardware serves some blocks only; with --json, one JSON line."""
    import gc
    import json
    import math
    import signal
    import sys
    import threading

    from deltoctl.sim.serve import ServeOptions, serve_profile

    opts = options(ctx)
    prof = opts.load_profile(profile)
    try:
        model = int(model_id, 0) if model_id else None
        who = int(who_am_i, 0)
        angles = tuple(float(x) for x in orientation.split(","))
    except ValueError:
        raise InvalidInput("--model-id and --who-am-i take numbers (0x5F22, 0x6A), "
                           "--orientation ROLL,PITCH in degrees") from None
    if not (math.isfinite(delay) and 0 <= delay <= 10):
        raise InvalidInput(f"--delay must be 0 to 10 seconds, got {delay:g}")
    if not (0 <= port <= 65535 and 0 <= who <= 0xFF and 2 <= len(angles) <= 3
            and all(math.isfinite(a) for a in angles)):
        raise InvalidInput("--port takes 0-65535, --who-am-i a byte, --orientation ROLL,PITCH"
                           "[,YAW] in finite degrees")
    serve_options = ServeOptions(
        host=host, port=port, firmware=firmware, model_id=model, short_version=short_version,
        input_1=input_1, delay=delay, stall=tuple(stall or ()), missing=tuple(missing or ()),
        pace=pace, wrong_baud=tuple(wrong_baud or ()), who_am_i=who, orientation=angles)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    gc.disable()  # a served device answers within microseconds; no collector pauses
    with contextlib.ExitStack() as stack:
        info = serve_profile(stack, prof, serve_options, opts.hardware)
        if opts.json:
            typer.echo(json.dumps(info))
        else:
            typer.echo("\n".join(f"--target {bus}={url}" for bus, url in info["buses"].items()))
        sys.stdout.flush()
        with contextlib.suppress(KeyboardInterrupt):
            stop.wait()


def register(root: typer.Typer) -> None:
    root.add_typer(app, name="sim")
