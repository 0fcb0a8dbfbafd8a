"""``deltoctl sim serve PROFILE``: a simulated device in its own process."""

import contextlib
from typing import Annotated

import typer

from deltoctl.cli.context import options
from deltoctl.errors import InvalidInput

app = typer.Typer(help="Simulated devices that speak the real protocol.", no_args_is_help=True)


@app.command("serve")
def serve(
    ctx: typer.Context,
    profile: Annotated[str | None, typer.Argument(
        metavar="[PROFILE]", help="Catalog name or file; default: --profile.")] = None,
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
        help="Fault: a joint that cannot move (repeatable).")] = None,
    missing: Annotated[list[str] | None, typer.Option(
        help="Fault: a joint (servo, I2C joint) that never answers (repeatable).")] = None,
    pace: Annotated[bool, typer.Option(
        help="Serial buses take the wire time of every byte at the baud rate the host "
             "set, as a real bus does.")] = False,
    wrong_baud: Annotated[list[str] | None, typer.Option(
        help="Fault: a servo set to another baud rate than its bus (repeatable).")] = None,
    who_am_i: Annotated[str, typer.Option(
        help="WHO_AM_I of a simulated LSM6DS3: 0x69 (LSM6DS3), 0x6A (LSM6DS3TR-C), or "
             "another value to rehearse a wrong part.")] = "0x6A",
    orientation: Annotated[str, typer.Option(
        help="The IMU's roll,pitch in degrees (gravity follows).")] = "0,0",
) -> None:
    """Serve a simulated device until Ctrl-C or SIGTERM, printing each bus's target.

    A Delto gripper on loopback TCP, a Dynamixel bus on a pseudo-terminal, an I2C bus as
    i2c+tcp://; with --json, one JSON line."""
    import gc
    import json
    import signal
    import sys
    import threading

    opts = options(ctx)
    prof = opts.load_profile(profile)
    families = {prof.family_of(h) for h in prof.hardware}
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    gc.disable()  # a served device answers within microseconds; no collector pauses
    delto_only = {"--firmware": firmware != "3.0", "--model-id": model_id is not None,
                  "--short-version": short_version, "--input-1": input_1, "--delay": delay}
    bus_only = {"--missing": bool(missing), "--pace": pace, "--wrong-baud": bool(wrong_baud),
                "--who-am-i": who_am_i != "0x6A", "--orientation": orientation != "0,0"}
    misplaced = [k for k, given in (bus_only if "delto" in families else delto_only).items()
                 if given]
    if misplaced:
        raise InvalidInput(f"{', '.join(misplaced)}: not for {prof.name} "
                           f"({'a Delto gripper' if 'delto' in families else 'not a gripper'})")
    with contextlib.ExitStack() as stack:
        if "delto" in families:
            info = _serve_delto(stack, prof, host, port, firmware, model_id, short_version,
                                input_1, delay, stall)
        elif families & {"dynamixel", "bioscara", "lsm6ds3"}:
            info = {"profile": prof.name, "buses": {}}
            missing_ids = _joint_addresses(prof, missing or [], "--missing")
            if "dynamixel" in families:
                info["buses"].update(_serve_dynamixel(
                    stack, prof, pace, missing_ids.get("dynamixel", set()),
                    _joint_addresses(prof, wrong_baud or [], "--wrong-baud").get("dynamixel",
                                                                                 set())))
            if families & {"bioscara", "lsm6ds3"}:
                blocked = _joint_addresses(prof, stall or [], "--stall").get("bioscara", set())
                info["buses"].update(_serve_i2c(stack, prof, host,
                                                missing_ids.get("bioscara", set()), blocked,
                                                who_am_i, orientation))
        else:
            raise InvalidInput(f"no simulator for profile {prof.name!r} yet "
                               "(supported: delto, dynamixel, bioscara, lsm6ds3)")
        if opts.json:
            typer.echo(json.dumps(info))
        else:
            typer.echo("\n".join(f"{bus}: {url}" for bus, url in info["buses"].items()))
        sys.stdout.flush()
        with contextlib.suppress(KeyboardInterrupt):
            stop.wait()


def _serve_delto(stack, prof, host, port, firmware, model_id, short_version,  # type: ignore[no-untyped-def]
                 input_1, delay, stall) -> dict:
    from deltoctl.drivers.delto.models import MODELS
    from deltoctl.sim.delto import DeltoServer, firmware_for_profile

    try:
        major, minor = (int(x) for x in firmware.split("."))
    except ValueError:
        raise InvalidInput(f"--firmware {firmware!r} is not MAJOR.MINOR (e.g. 2.8)") from None
    try:
        model = int(model_id, 0) if model_id else None
    except ValueError:
        raise InvalidInput(f"--model-id {model_id!r} is not a number (e.g. 0x5F22)") from None
    if model is not None and model not in MODELS:
        raise InvalidInput(f"--model-id {model:#06x} is not a Delto model "
                           f"({', '.join(f'{m:#06x}' for m in MODELS)})")
    device = firmware_for_profile(prof, model_id=model, firmware=(major, minor),
                                  short_version=short_version)
    device.input_1 = input_1
    device.faults.delay = delay
    hw = next(h for h in prof.hardware if prof.family_of(h) == "delto")
    joints = [j.name for j in hw.joints]
    for name in stall or []:
        if name not in joints:
            raise InvalidInput(f"--stall: {prof.name} has no joint {name!r}")
        device.faults.stalled.add(joints.index(name))
    server = stack.enter_context(DeltoServer(device, host=host, port=port))
    return {"profile": prof.name, "endpoint": server.endpoint,
            "buses": {hw.bus or "gripper": server.endpoint}, "model": device.model.name,
            "firmware": firmware}


def _joint_addresses(prof, names: list[str], option: str) -> dict[str, set[int]]:  # type: ignore[no-untyped-def]
    """The bus addresses of the named joints (Dynamixel IDs, I2C addresses) by family."""
    from deltoctl.profile.validate import part_address

    found: dict[str, set[int]] = {}
    for name in names:
        hw_comp = next(((h, c) for h, c in prof.components() if c.name == name), None)
        address = part_address(prof, *hw_comp) if hw_comp else None
        if address is None:
            raise InvalidInput(f"{option}: {prof.name} has no joint {name!r} with a bus address")
        found.setdefault(prof.family_of(hw_comp[0]), set()).add(address)
    return found


def _serve_dynamixel(stack, prof, pace: bool, missing: set[int],  # type: ignore[no-untyped-def]
                     wrong_baud: set[int]) -> dict:
    """One pseudo-terminal per Dynamixel bus of the profile, its servos at the joints' IDs,
    listening at the bus URL's baud rate."""
    from deltoctl.sim.dynamixel import DynamixelBus, DynamixelPtyServer, Servo
    from deltoctl.transport.serial_port import parse_serial_url

    buses = {}
    for hw in prof.hardware:
        if prof.family_of(hw) != "dynamixel":
            continue
        url = prof.buses.get(hw.bus or "", "serial:///dev/ttyUSB0?baud=1000000")
        _, baud, _ = parse_serial_url(url)
        bus = DynamixelBus([Servo(j.address) for j in hw.joints if j.address is not None],
                           baud=baud)
        bus.faults.missing |= missing
        for device_id in wrong_baud & set(bus.servos):
            bus.servos[device_id].memory[8] = 1 if baud != 57600 else 2  # 57600 (or 115200)
        server = stack.enter_context(DynamixelPtyServer(bus, pace=pace))
        query = url.split("?", 1)[1] if "?" in url else f"baud={baud}"
        buses[hw.bus or hw.name] = f"serial://{server.port}?{query}"
    return buses


def _serve_i2c(stack, prof, host: str, missing: set[int], blocked: set[int],  # type: ignore[no-untyped-def]
               who_am_i: str, orientation: str) -> dict:
    """The profile's I2C devices on one simulated bus, served over loopback TCP."""
    import math

    from deltoctl.drivers.lsm6ds3.codec import WHO_AM_I
    from deltoctl.sim.bioscara import JointFirmware
    from deltoctl.sim.i2c_bus import I2CSocketServer, bus_for_profile
    from deltoctl.sim.lsm6ds3 import Lsm6ds3Chip

    try:
        who = int(who_am_i, 0)
        angles = [math.radians(float(x)) for x in orientation.split(",")]
    except ValueError:
        raise InvalidInput("--who-am-i takes a number (0x6A), --orientation ROLL,PITCH in "
                           "degrees") from None
    bus = bus_for_profile(prof, missing=tuple(missing))
    for address, device in bus.devices.items():
        if isinstance(device, Lsm6ds3Chip):
            device.registers[WHO_AM_I] = who
            device.set_orientation(*angles[:3])
        elif isinstance(device, JointFirmware) and address in blocked:
            device.blocked = True
    server = stack.enter_context(I2CSocketServer(bus, host=host))
    names = {h.bus for h in prof.hardware if prof.family_of(h) in ("bioscara", "lsm6ds3")}
    return {name or "i2c": server.url for name in names}


def register(root: typer.Typer) -> None:
    root.add_typer(app, name="sim")
