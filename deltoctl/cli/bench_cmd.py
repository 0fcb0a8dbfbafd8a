"""Benchmarks that ship with deltoctl: ``bench loop`` (the Delto read+write cycle against
``sim serve`` in another process, recording to MCAP, the time per cycle split by stage),
``bench dynamixel`` (sync reads against dynamixel-sdk and the wire limit) and ``bench i2c``
(the Bioscara read cycle against the I2C wire time)."""

import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from deltoctl.cli.context import options
from deltoctl.cli.output import emit_json, info
from deltoctl.errors import DeviceError, InvalidInput

if TYPE_CHECKING:
    import subprocess

app = typer.Typer(help="Benchmarks that ship with deltoctl.", no_args_is_help=True)


def _serve(profile: str) -> tuple["subprocess.Popen", str]:
    import json
    import subprocess

    proc = subprocess.Popen([sys.executable, "-m", "deltoctl", "sim", "serve", profile,
                             "--json"], stdout=subprocess.PIPE, text=True)
    line = proc.stdout.readline() if proc.stdout else ""
    if not line:
        proc.kill()
        raise DeviceError("sim serve did not start")
    return proc, json.loads(line)["endpoint"]


def _cpu_ticks() -> list[int] | None:
    """The machine's CPU time by kind (Linux /proc/stat), to tell how much of a run the
    hypervisor took away (steal): on a shared virtual machine, the cause of most misses."""
    try:
        with open("/proc/stat") as f:
            return [int(x) for x in f.readline().split()[1:9]]
    except (OSError, ValueError):
        return None


def _steal_percent(before: list[int] | None, after: list[int] | None) -> float | None:
    if not before or not after:
        return None
    delta = [b - a for a, b in zip(before, after)]
    return round(100 * delta[7] / max(sum(delta), 1), 2)


def _idle_loop(rate: float, duration: float) -> dict:
    """The baseline: the same cycle loop doing nothing, on this machine, right now. What it
    misses, no work in the cycle can avoid."""
    from deltoctl.core.loop import CycleLoop

    ticks = _cpu_ticks()
    loop = CycleLoop(rate, duration)
    for _ in loop:
        pass
    stats = loop.stats.summary()
    return {"real_rate": stats["real_rate"],
            "achieved_fraction": round(stats["real_rate"] / rate, 4),
            "deadline_misses": stats["deadline_misses"],
            "lateness_p99_ms": stats["lateness_p99_ms"],
            "cpu_steal_percent": _steal_percent(ticks, _cpu_ticks())}


def _run(session, rate: float, duration: float, mcap_path: Path) -> dict:  # type: ignore[no-untyped-def]
    from deltoctl.core.loop import CycleLoop
    from deltoctl.record.recorder_process import RecorderProcess

    driver = session.driver
    timing = {"codec": 0.0, "socket": 0.0, "recording": 0.0, "write": 0.0}
    driver.timing = timing
    efforts = {j.name: 0.0 for j in session.hw.joints}
    recorder = RecorderProcess(mcap_path, session.profile, {})
    loop = CycleLoop(rate, duration)
    cpu0 = time.process_time()
    ticks = _cpu_ticks()
    try:
        for _ in loop:
            values = driver.read()
            t0 = time.perf_counter()
            driver.write_efforts(efforts)
            t1 = time.perf_counter()
            recorder.write(values, time.time_ns())
            t2 = time.perf_counter()
            timing["write"] += t1 - t0
            timing["recording"] += t2 - t1
        cpu = time.process_time() - cpu0
        steal = _steal_percent(ticks, _cpu_ticks())
    finally:
        recorder.close(loop.stats.summary())
        driver.timing = None
    stats = loop.stats.summary()
    n = max(stats["cycles"], 1)
    return {
        **stats,
        "achieved_fraction": round(stats["real_rate"] / rate, 4) if rate else None,
        "cpu_us_per_cycle": round(cpu / n * 1e6, 1),
        "recorder_process_cpu_us_per_cycle": round(recorder.cpu_seconds / n * 1e6, 1),
        "stage_us_per_cycle": {k: round(v / n * 1e6, 1) for k, v in timing.items()},
        "mcap_bytes": mcap_path.stat().st_size,
        "mcap_messages": sum(recorder.counts.values()),
        "cpu_steal_percent": steal,
        "errors": driver.stats["errors"],
    }


@app.command("loop")
def bench_loop(
    ctx: typer.Context,
    rate: Annotated[float, typer.Option("--rate", help="Requested cycle rate, Hz.")] = 1000.0,
    duration: Annotated[float, typer.Option("--duration", help="Seconds per run.")] = 10.0,
    unpaced: Annotated[float, typer.Option(
        "--unpaced", help="Seconds of the unpaced run (0: skip).")] = 5.0,
) -> None:
    """The Delto read+write cycle while recording, paced and unpaced.

    A Delto profile (default dg-5f-right: F/T and IO) against `sim serve` over loopback TCP,
    recording to MCAP; beside it, the same loop idle (what this machine allows)."""
    import os
    import tempfile

    from deltoctl.core.session import Session

    opts = options(ctx)
    if rate <= 0 or duration <= 0 or unpaced < 0:
        raise InvalidInput("--rate and --duration must be positive, --unpaced not negative")
    prof = opts.load_profile(opts.profile or "dg-5f-right")
    proc, endpoint = _serve(str(prof.source))
    results = {"profile": prof.name, "endpoint": endpoint, "python": sys.version.split()[0],
               "idle_loop": _idle_loop(rate, duration)}
    try:
        with tempfile.TemporaryDirectory() as tmp, Session(prof, [endpoint]) as session:
            results["paced"] = _run(session, rate, duration, Path(tmp) / "paced.mcap")
            if unpaced > 0:
                results["unpaced"] = _run(session, 0.0, unpaced, Path(tmp) / "unpaced.mcap")
    finally:
        proc.terminate()
        proc.wait(timeout=5)
    paced = results["paced"]
    results["goals"] = {
        "achieved_rate_ge_99_5_percent": paced["achieved_fraction"] >= 0.995,
        "p99_lateness_le_0_5_ms": paced["lateness_p99_ms"] <= 0.5,
    }
    if "unpaced" in results:
        results["goals"]["unpaced_ge_5_khz"] = results["unpaced"]["real_rate"] >= 5000
    if opts.json:
        emit_json(results)
        return
    info(f"bench loop: {prof.name} against sim serve at {endpoint} ({os.cpu_count()} CPUs)")
    idle = results["idle_loop"]
    info(f"  baseline: an idle {rate:g} Hz loop here reaches {100 * idle['achieved_fraction']:.2f}"
         f" %, lateness p99 {idle['lateness_p99_ms']:.3f} ms, misses {idle['deadline_misses']}"
         + (f", CPU steal {idle['cpu_steal_percent']} %"
            if idle["cpu_steal_percent"] is not None else ""))
    for name in ("paced", "unpaced"):
        if name not in results:
            continue
        r = results[name]
        info(f"  {name:8} requested {r['requested_rate']:g} Hz, real {r['real_rate']:.1f} Hz"
             + (f" ({100 * r['achieved_fraction']:.2f} %)" if r["achieved_fraction"] else "")
             + f", lateness p50 {r['lateness_p50_ms']:.3f} ms p99 {r['lateness_p99_ms']:.3f} ms"
             f", misses {r['deadline_misses']}, errors {r['errors']}"
             + (f", CPU steal {r['cpu_steal_percent']} %" if r["cpu_steal_percent"] is not None
                else ""))
        stages = ", ".join(f"{k} {v:.1f}" for k, v in r["stage_us_per_cycle"].items())
        info(f"           µs per cycle: {stages}; CPU {r['cpu_us_per_cycle']:.1f} in the loop, "
             f"{r['recorder_process_cpu_us_per_cycle']:.1f} in the recorder process")
    info("  goals: " + ", ".join(f"{k}={'yes' if v else 'NO'}"
                                 for k, v in results["goals"].items()))


def register(root: typer.Typer) -> None:
    root.add_typer(app, name="bench")


_SERVE_BUS = """
import sys
from deltoctl.sim.dynamixel import DynamixelBus, DynamixelPtyServer, Servo
servos = [Servo(i) for i in range(1, {n} + 1)]
for servo in servos:
    servo.set("Return Delay Time", 0)  # as the MH5 sets it
server = DynamixelPtyServer(DynamixelBus(servos), pace={pace}).start()
print(server.port, flush=True)
sys.stdin.read()
"""


def _bus_process(servos: int, pace: bool):  # type: ignore[no-untyped-def]
    """An emulated bus of N servos in another process; returns (process, pty path)."""
    import subprocess

    proc = subprocess.Popen([sys.executable, "-c", _SERVE_BUS.format(n=servos, pace=pace)],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    return proc, proc.stdout.readline().strip() if proc.stdout else ""


def _stop(proc) -> None:  # type: ignore[no-untyped-def]
    if proc.stdin:
        proc.stdin.close()
    proc.wait(timeout=5)


def _deltoctl_rate(pty: str, servos: int, baud: int, duration: float) -> tuple[float, int]:
    """Sync reads (126, 10) per second through deltoctl's driver, and its errors."""
    from deltoctl.drivers.dynamixel.driver import DynamixelDriver
    from deltoctl.profile.model import Component, Hardware, Profile

    hw = Hardware("bus", family="dynamixel", joints=[
        Component("joint", f"j{i}", address=i) for i in range(1, servos + 1)])
    driver = DynamixelDriver(Profile("bench", hardware=[hw]), hw, f"serial://{pty}?baud={baud}")
    driver.configure()
    ids = list(range(1, servos + 1))
    errors = driver.stats["errors"]
    cycles, start = 0, time.perf_counter()
    while time.perf_counter() - start < duration:
        driver._sync_read(126, 10, ids)
        cycles += 1
    rate = cycles / (time.perf_counter() - start)
    errors = driver.stats["errors"] - errors
    driver.cleanup()
    return rate, errors


def _sdk_rate(pty: str, servos: int, duration: float) -> tuple[float, int] | None:
    """The same with dynamixel-sdk's GroupSyncRead (None when it is not installed)."""
    try:
        import dynamixel_sdk as sdk
    except ImportError:
        return None
    port = sdk.PortHandler(pty)
    port.openPort()
    port.setBaudRate(1000000)
    group = sdk.GroupSyncRead(port, sdk.PacketHandler(2.0), 126, 10)
    for i in range(1, servos + 1):
        group.addParam(i)
    cycles, failed, start = 0, 0, time.perf_counter()
    while time.perf_counter() - start < duration:
        failed += group.txRxPacket() != sdk.COMM_SUCCESS
        cycles += 1
    rate = cycles / (time.perf_counter() - start)
    port.closePort()
    return rate, failed


def _wire_limit(servos: int, baud: int) -> float:
    """Sync reads per second the wire allows: the instruction and every status, 10 bits a
    byte, no return delay."""
    from deltoctl.drivers.dynamixel import codec

    ids = list(range(1, servos + 1))
    sent = len(codec.sync_read(126, 10, ids)) + sum(len(codec.status(i, 0, bytes(10)))
                                                    for i in ids)
    return baud / (10 * sent)


@app.command("dynamixel")
def bench_dynamixel(
    ctx: typer.Context,
    servos: Annotated[int, typer.Option(help="Servos on the bus.")] = 11,
    duration: Annotated[float, typer.Option(help="Seconds per measurement.")] = 3.0,
) -> None:
    """Dynamixel sync reads against dynamixel-sdk, and against the wire's limit.

    Present load/velocity/position (126, 10) from N servos of an emulated bus in another
    process: deltoctl's driver against dynamixel-sdk's GroupSyncRead; then, with the bus paced
    at 1 and 2 Mbps, deltoctl's rate against the wire's limit."""
    opts = options(ctx)
    if not 1 <= servos <= 252 or duration <= 0:
        raise InvalidInput("--servos must be 1-252 and --duration positive")
    proc, pty = _bus_process(servos, pace=False)
    try:
        ours, errors = _deltoctl_rate(pty, servos, 1_000_000, duration)
        theirs = _sdk_rate(pty, servos, duration)
    finally:
        _stop(proc)
    results: dict = {"servos": servos, "deltoctl_hz": round(ours, 1), "deltoctl_errors": errors}
    if theirs is not None:
        results.update({"dynamixel_sdk_hz": round(theirs[0], 1),
                        "dynamixel_sdk_errors": theirs[1], "ratio": round(ours / theirs[0], 2),
                        "goal_ratio_ge_2": ours >= 2 * theirs[0]})
    paced = {}
    for baud in (1_000_000, 2_000_000):
        proc, pty = _bus_process(servos, pace=True)
        try:
            rate, errors = _deltoctl_rate(pty, servos, baud, duration)
        finally:
            _stop(proc)
        limit = _wire_limit(servos, baud)
        paced[str(baud)] = {"deltoctl_hz": round(rate, 1), "errors": errors,
                            "wire_limit_hz": round(limit, 1),
                            "fraction": round(rate / limit, 3),
                            "goal_ge_0_9": rate >= 0.9 * limit}
    results["paced"] = paced
    if opts.json:
        emit_json(results)
        return
    info(f"sync read 126/10 of {servos} servos, emulator in another process:")
    info(f"  deltoctl       {results['deltoctl_hz']:8.1f} cycles/s "
         f"({results['deltoctl_errors']} errors)")
    if "dynamixel_sdk_hz" in results:
        info(f"  dynamixel-sdk  {results['dynamixel_sdk_hz']:8.1f} cycles/s "
             f"({results['dynamixel_sdk_errors']} errors)   ratio {results['ratio']:.2f}")
    for baud, p in paced.items():
        info(f"  paced at {int(baud) // 1000} kbps: {p['deltoctl_hz']:.1f} cycles/s of a "
             f"{p['wire_limit_hz']:.1f} wire limit = {100 * p['fraction']:.1f} % "
             f"({p['errors']} errors)")


class _Timed:
    """An SMBus-compatible wrapper that adds up the time spent inside the bus it wraps."""

    def __init__(self, smbus) -> None:  # type: ignore[no-untyped-def]
        self.smbus = smbus
        self.seconds = 0.0

    def i2c_rdwr(self, *msgs) -> None:  # type: ignore[no-untyped-def]
        start = time.perf_counter()
        self.smbus.i2c_rdwr(*msgs)
        self.seconds += time.perf_counter() - start

    def close(self) -> None:
        self.smbus.close()


@app.command("i2c")
def bench_i2c(
    ctx: typer.Context,
    cycles: Annotated[int, typer.Option(help="Read cycles per client.")] = 3000,
    clock: Annotated[int, typer.Option(help="I2C clock in Hz for the wire time.")] = 400_000,
) -> None:
    """The Bioscara read cycle against the I2C wire time.

    Position and velocity of bioscara-arm's four joints, each reply with its flags, on the
    in-process emulator: deltoctl's own time per transaction, without the emulator's, against
    the I2C wire time; beside it, the same transactions written straight against smbus2."""
    import struct

    from smbus2 import i2c_msg

    from deltoctl.drivers.bioscara import codec
    from deltoctl.drivers.bioscara.driver import BioscaraDriver
    from deltoctl.profile.catalog import load_profile
    from deltoctl.sim.i2c_bus import bus_for_profile
    from deltoctl.transport.i2c import wire_bits

    opts = options(ctx)
    if cycles < 1 or clock <= 0:
        raise InvalidInput("--cycles and --clock must be positive")
    profile = load_profile("bioscara-arm")
    timed = _Timed(bus_for_profile(profile))
    driver = BioscaraDriver(profile, profile.hardware[0], "i2c+sim://bench", timed)
    driver.configure()
    for _ in range(200):
        driver.read()
    stats = driver.bus.stats if driver.bus else {}
    packets, sent = stats["packets"], stats["bytes"]
    timed.seconds = 0.0
    start = time.perf_counter()
    for _ in range(cycles):
        driver.read()
    total = time.perf_counter() - start
    transactions = stats["packets"] - packets
    wire = (stats["bytes"] - sent) * 9 / clock / transactions
    ours = (total - timed.seconds) / transactions
    emulator = timed.seconds / transactions

    addresses = [j.address for j in driver.present]
    timed.seconds = 0.0
    start = time.perf_counter()
    for _ in range(cycles):  # baseline: a hand-written smbus2 loop, no retries or counters
        for address in addresses:
            for register in (codec.ANGLEMOVED, codec.GETENCODERRPM):
                reply = i2c_msg.read(address, 5)
                timed.i2c_rdwr(i2c_msg.write(address, [register]), reply)
                struct.unpack("<fB", bytes(reply))
    plain = (time.perf_counter() - start - timed.seconds) / (cycles * 2 * len(addresses))
    driver.cleanup()
    results = {
        "joints": len(addresses), "cycles": cycles, "transactions_per_cycle":
            transactions // cycles, "clock_hz": clock,
        "wire_us": round(wire * 1e6, 2), "deltoctl_us": round(ours * 1e6, 2),
        "smbus2_loop_us": round(plain * 1e6, 2), "emulator_us": round(emulator * 1e6, 2),
        "overhead_pct_of_wire": round(100 * ours / wire, 1),
        "goal_overhead_le_25pct": ours <= 0.25 * wire,
        "wire_bits_per_transaction": wire_bits(1, 5),
    }
    if opts.json:
        emit_json(results)
        return
    info(f"read cycle of {len(addresses)} Bioscara joints ({results['transactions_per_cycle']} "
         f"transactions), {cycles} cycles, I2C wire time at {clock / 1000:g} kHz:")
    info(f"  wire time          {results['wire_us']:8.2f} µs per transaction")
    info(f"  deltoctl           {results['deltoctl_us']:8.2f} µs "
         f"({results['overhead_pct_of_wire']} % of the wire time; goal ≤ 25 %)")
    info(f"  smbus2 by hand     {results['smbus2_loop_us']:8.2f} µs")
    info(f"  emulator (apart)   {results['emulator_us']:8.2f} µs")
