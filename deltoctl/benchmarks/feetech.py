"""``bench feetech``: sync reads of six STS3215 (an SO-101 arm's bus) on an emulated bus in
another process, side by side with scservo_sdk's GroupSyncRead (feetech-servo-sdk, the SDK
LeRobot pins): paced at 1 Mbps, each against the wire's limit, and against it with the
pseudo-terminal's own round trip taken out (the transport of an emulated bus, which a real one
does not have: one per read, as the request goes out and the last status comes back); unpaced,
the CPU a read costs each client."""

from __future__ import annotations

import subprocess
import sys
from typing import Any

from deltoctl.benchmarks.dynamixel import _flat_out, _pty_round_trip, _stop

ADDRESS, LENGTH = 56, 6  # Present_Position, Velocity, Load: the driver's read each cycle
_SERVE_BUS = """
import sys
from deltoctl.families.feetech.emulator import FeetechBus, FeetechPtyServer, Servo
servos = [Servo(i) for i in range(1, {n} + 1)]
for servo in servos:
    servo.memory[7] = 0  # Return_Delay_Time 0, as LeRobot sets it
server = FeetechPtyServer(FeetechBus(servos), pace={pace}).start()
print(server.port, flush=True)
sys.stdin.read()
"""


def _bus_process(servos: int, pace: bool) -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen([sys.executable, "-c", _SERVE_BUS.format(n=servos, pace=pace)],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    return proc, proc.stdout.readline().strip() if proc.stdout else ""


def _driver(pty: str, servos: int, baud: int) -> Any:
    from deltoctl import registry
    from deltoctl.core.driver import Block
    from deltoctl.families.feetech.driver import FeetechDriver
    from deltoctl.profile.model import Component, Hardware, Profile

    family = registry.get("feetech")
    assert family is not None
    hw = Hardware("bus", family=family.name, joints=[
        Component("joint", f"j{i}", address=i) for i in range(1, servos + 1)])
    driver = FeetechDriver(Block(Profile("bench", hardware=[hw]), hw, family,
                                 f"serial://{pty}?baud={baud}"))
    driver.configure()
    return driver


def _ours(pty: str, servos: int, baud: int) -> tuple[Any, Any]:
    driver = _driver(pty, servos, baud)
    ids = list(range(1, servos + 1))
    return driver, lambda: len(driver.sync.read(ADDRESS, LENGTH, ids))


def _theirs(pty: str, servos: int, baud: int) -> tuple[Any, Any] | None:
    try:
        import scservo_sdk as sdk
    except ImportError:
        return None
    port = sdk.PortHandler(pty)
    port.openPort()
    port.setBaudRate(baud)
    group = sdk.GroupSyncRead(port, sdk.PacketHandler(0), ADDRESS, LENGTH)
    for i in range(1, servos + 1):
        group.addParam(i)
    return port, group.txRxPacket


def wire_limit(servos: int, baud: int) -> float:
    """Sync reads per second the wire allows: the instruction and every status, 10 bits a
    byte, no return delay."""
    from deltoctl.families.feetech import codec
    from deltoctl.servo.frames.checksum import status

    ids = list(range(1, servos + 1))
    sent = len(codec.sync_read(ADDRESS, LENGTH, ids)) + sum(
        len(status(i, 0, bytes(LENGTH))) for i in ids)
    return baud / (10 * sent)


def _run(pace: bool, servos: int, baud: int, duration: float) -> dict[str, tuple]:
    """Each client flat out on one bus: (reads/s, CPU µs a read, the emulator's CPU µs)."""
    proc, pty = _bus_process(servos, pace)
    out = {}
    try:
        driver, read = _ours(pty, servos, baud)
        out["deltoctl"] = _flat_out(read, duration, proc.pid)
        errors = driver.stats["errors"]
        driver.cleanup()
        sdk = _theirs(pty, servos, baud)
        if sdk is not None:
            port, read = sdk
            out["scservo_sdk"] = _flat_out(read, duration, proc.pid)
            port.closePort()
    finally:
        _stop(proc)
    out["errors"] = (errors,)
    return out


def _less_pty(hz: float, limit: float, pty_s: float) -> float | None:
    """The wire's time of a read over the time it took less the pseudo-terminal's round trip
    (None when the round trip is not shorter than the read)."""
    left = 1.0 / hz - pty_s
    return round(1.0 / limit / left, 3) if left > 0 else None


def measure(servos: int = 6, duration: float = 3.0, baud: int = 1_000_000) -> dict:
    from deltoctl.families.feetech import codec

    limit = wire_limit(servos, baud)
    _, pty_ms = _pty_round_trip(min(duration, 1.0),  # the median: a stray wake-up aside
                                len(codec.sync_read(ADDRESS, LENGTH, list(range(1, servos + 1)))))
    paced = _run(True, servos, baud, duration)
    unpaced = _run(False, servos, baud, duration)
    results: dict = {"servos": servos, "baud": baud, "item": f"{ADDRESS}/{LENGTH}",
                     "wire_limit_hz": round(limit, 1), "errors": paced["errors"][0],
                     "pty_round_trip_us": round(pty_ms * 1e3, 1)}
    for name in ("deltoctl", "scservo_sdk"):
        if name in paced:
            results[name] = {
                "paced_hz": round(paced[name][0], 1),
                "paced_fraction_of_wire": round(paced[name][0] / limit, 3),
                "paced_fraction_less_pty": _less_pty(paced[name][0], limit, pty_ms / 1e3),
                "unpaced_hz": round(unpaced[name][0], 1),
                "cpu_us_per_read": round(unpaced[name][1], 1)}
    if "scservo_sdk" in results:
        ours, theirs = results["deltoctl"], results["scservo_sdk"]
        results["paced_ratio"] = round(ours["paced_hz"] / theirs["paced_hz"], 2)
        results["cpu_ratio"] = round(theirs["cpu_us_per_read"] / ours["cpu_us_per_read"], 2)
    return results
