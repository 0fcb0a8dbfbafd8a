"""``bench dynamixel``: sync reads of an emulated bus in another process — deltoctl's driver
against dynamixel-sdk's GroupSyncRead, then deltoctl against the wire's limit, paced; then the
MH5's two buses in one System cycle against the slower bus's wire time; then a bus of mixed
models (five XM430, two XL330) at 1 kHz and 4 Mbps against its wire time, read as one Sync
Read, one Bulk Read or a Sync Read per model; flat out against dynamixel-sdk's GroupBulkRead
on that paced bus (where the wire caps both), and on an unpaced one (what the software
costs); then five AX-12A on a Protocol 1.0 bus, read in turn, against the wire and against
dynamixel-sdk's Protocol 1.0 handler."""

from __future__ import annotations

import subprocess
import sys
import time
from functools import partial
from typing import Any

_SERVE_BUS = """
import sys
from deltoctl.families.dynamixel.emulator import DynamixelBus, DynamixelPtyServer, Servo
from deltoctl.families.dynamixel.models import XL430_W250, by_number
models = {models}
servos = [Servo(i, model=by_number(models[i - 1]) if models else XL430_W250)
          for i in range(1, {n} + 1)]
for servo in servos:
    servo.set("Return Delay Time", 0)  # as the MH5 sets it
server = DynamixelPtyServer(DynamixelBus(servos), pace={pace}).start()
print(server.port, flush=True)
sys.stdin.read()
"""


def _bus_process(servos: int, pace: bool,
                 models: list[int] | None = None) -> tuple[subprocess.Popen, str]:
    """An emulated bus of N servos (XL430-W250s, or these model numbers) in another process;
    returns (process, pty path)."""
    code = _SERVE_BUS.format(n=servos, pace=pace, models=list(models or []))
    proc = subprocess.Popen([sys.executable, "-c", code],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    return proc, proc.stdout.readline().strip() if proc.stdout else ""


def _stop(proc: subprocess.Popen) -> None:
    if proc.stdin:
        proc.stdin.close()
    proc.wait(timeout=5)


def _deltoctl_rate(pty: str, servos: int, baud: int, duration: float) -> tuple[float, int]:
    """Sync reads (126, 10) per second through deltoctl's driver, and its errors."""
    from deltoctl import registry
    from deltoctl.core.driver import Block
    from deltoctl.families.dynamixel.driver import DynamixelDriver
    from deltoctl.profile.model import Component, Hardware, Profile

    family = registry.get("dynamixel")
    assert family is not None
    hw = Hardware("bus", family=family.name, joints=[
        Component("joint", f"j{i}", address=i) for i in range(1, servos + 1)])
    driver = DynamixelDriver(Block(Profile("bench", hardware=[hw]), hw, family,
                                   f"serial://{pty}?baud={baud}"))
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
    from deltoctl.families.dynamixel import codec

    ids = list(range(1, servos + 1))
    sent = len(codec.sync_read(126, 10, ids)) + sum(len(codec.status(i, 0, bytes(10)))
                                                    for i in ids)
    return baud / (10 * sent)


def measure(servos: int, duration: float) -> dict:
    """deltoctl against dynamixel-sdk on one unpaced bus; then deltoctl on a bus paced at
    1 and 2 Mbps against the wire's limit."""
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
    results["two_buses"] = measure_two_buses(duration)
    results["mixed_bus"] = measure_mixed_bus(duration)
    results["protocol1"] = measure_protocol1(duration)
    return results


def _cycle_ms(read: Any, duration: float) -> float:
    """Mean milliseconds per call of ``read`` over ``duration`` seconds (after a warm-up)."""
    for _ in range(20):
        read()
    cycles, start = 0, time.perf_counter()
    while time.perf_counter() - start < duration:
        read()
        cycles += 1
    return (time.perf_counter() - start) / cycles * 1e3


def measure_two_buses(duration: float, servos: tuple[int, int] = (10, 12),
                      baud: int = 1_000_000) -> dict:
    """The MH5's two buses (10 and 12 servos), each paced at ``baud`` in a process of its own:
    one System cycle of sync reads on both, against the slower bus's wire time, beside the
    two read one after the other (how buses ran before the System overlapped them)."""
    from deltoctl import registry
    from deltoctl.core.system import System
    from deltoctl.profile.model import Component, Hardware, Profile

    family = registry.get("dynamixel")
    assert family is not None
    procs = []
    try:
        blocks, targets, wire = [], [], {}
        for n, count in enumerate(servos):
            proc, pty = _bus_process(count, pace=True)
            procs.append(proc)
            name = f"bus{n + 1}"
            blocks.append(Hardware(name, family=family.name, bus=name, params={
                "pvl_reader_rate": "0", "tv_reader_rate": "0.0001"}, joints=[
                    Component("joint", f"{name}_j{i}", address=i) for i in range(1, count + 1)]))
            targets.append(f"{name}=serial://{pty}?baud={baud}")
            wire[name] = 1e3 / _wire_limit(count, baud)
        robot = Profile("two-buses", buses={b.name: "" for b in blocks}, hardware=blocks)
        alone = {}
        for hw in blocks:
            with System(robot, targets, [hw.name]) as system:
                alone[hw.name] = _cycle_ms(system.read, duration)
        with System(robot, targets) as system:
            both = _cycle_ms(system.read, duration)
            drivers = [m.driver for m in system]
            series = _cycle_ms(lambda: [d.read() for d in drivers], duration)
    finally:
        for proc in procs:
            _stop(proc)
    slower = max(wire.values())
    return {"baud": baud, "servos": list(servos),
            "wire_ms": {k: round(v, 4) for k, v in wire.items()},
            "alone_ms": {k: round(v, 4) for k, v in alone.items()},
            "both_ms": round(both, 4), "in_series_ms": round(series, 4),
            "both_over_slower_wire": round(both / slower, 3),
            "in_series_over_slower_wire": round(series / slower, 3),
            "goal_both_le_1_15_of_slower_wire": both <= 1.15 * slower}


MIXED = [1020] * 5 + [1200] * 2  # five XM430-W350 and two XL330-M288


def _mixed_driver(pty: str, baud: int, fast: bool = False) -> Any:
    """deltoctl's driver of the mixed bus (with ``fast``, its sync reads are Fast Sync
    Reads: one status packet for all)."""
    from deltoctl import registry
    from deltoctl.core.driver import Block
    from deltoctl.families.dynamixel.driver import DynamixelDriver
    from deltoctl.profile.model import Component, Hardware, Profile

    family = registry.get("dynamixel")
    assert family is not None
    hw = Hardware("bus", family=family.name, params={"fast_sync_read": str(fast).lower()},
                  joints=[Component("joint", f"j{i}", address=i,
                                    params={"model_number": str(n)})
                          for i, n in enumerate(MIXED, 1)])
    driver = DynamixelDriver(Block(Profile("bench", hardware=[hw]), hw, family,
                                   f"serial://{pty}?baud={baud}"))
    driver.configure()
    return driver


def _read_ways(driver: Any) -> dict[str, Any]:
    """One read of every servo's present current/load, velocity and position, three ways:
    one Sync Read (every X model keeps them at 126), one Bulk Read, a Sync Read per model."""
    ids = list(range(1, len(MIXED) + 1))
    bulk = [(i, 126, 10) for i in ids]
    groups = [[i for i in ids if MIXED[i - 1] == n] for n in sorted(set(MIXED))]
    return {"sync_read": lambda: len(driver._sync_read(126, 10, ids)),
            "bulk_read": lambda: len(driver.bulk_read(bulk)),
            "sync_read_per_model": lambda: sum(len(driver._sync_read(126, 10, g))
                                               for g in groups)}


def _paced_ms(read: Any, duration: float, rate: float = 1000.0,
              expect: int = len(MIXED)) -> tuple[float, float, float, int]:
    """Reads at ``rate`` Hz for ``duration`` s: (mean, median and 99th percentile ms, the
    reads that missed a servo: ``read`` returns how many answered, ``expect`` of them)."""
    from deltoctl.servo.pty_server import wait_until

    period, times, short = 1.0 / rate, [], 0
    start = next_at = time.perf_counter()
    while next_at - start < duration:
        t0 = time.perf_counter()
        short += read() != expect
        times.append(time.perf_counter() - t0)
        next_at += period
        wait_until(next_at)  # sleeps: the emulator's process keeps the other core
    times.sort()
    return (sum(times) / len(times) * 1e3, times[len(times) // 2] * 1e3,
            times[int(0.99 * (len(times) - 1))] * 1e3, short)


def _cpu_s(pid: int) -> float | None:
    """Another process's CPU seconds so far (user and system, all its threads), from /proc;
    None where there is none."""
    import os

    try:
        with open(f"/proc/{pid}/stat") as stat:
            fields = stat.read().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _flat_out(read: Any, duration: float,
              emulator: int | None = None) -> tuple[float, float, float | None]:
    """Calls of ``read`` per second flat out, this process's CPU µs per call, and the CPU µs
    per call of the ``emulator`` process (None: not measured)."""
    for _ in range(20):
        read()
    theirs = _cpu_s(emulator) if emulator is not None else None
    cycles, cpu, start = 0, time.process_time(), time.perf_counter()
    while time.perf_counter() - start < duration:
        read()
        cycles += 1
    elapsed, cpu = time.perf_counter() - start, time.process_time() - cpu
    after = _cpu_s(emulator) if theirs is not None and emulator is not None else None
    other = None if after is None or theirs is None else (after - theirs) / cycles * 1e6
    return cycles / elapsed, cpu / cycles * 1e6, other


def _sdk_bulk(pty: str, baud: int, duration: float,
              emulator: int | None = None) -> tuple[float, float, float | None] | None:
    """dynamixel-sdk's GroupBulkRead of the same items, as fast as it goes: as ``_flat_out``
    (None when it is not installed)."""
    try:
        import dynamixel_sdk as sdk
    except ImportError:
        return None
    port = sdk.PortHandler(pty)
    port.openPort()
    port.setBaudRate(baud)
    group = sdk.GroupBulkRead(port, sdk.PacketHandler(2.0))
    for i in range(1, len(MIXED) + 1):
        group.addParam(i, 126, 10)
    try:
        return _flat_out(group.txRxPacket, duration, emulator)
    finally:
        port.closePort()


_ECHO = """
import os, tty
master, slave = os.openpty()
tty.setraw(master)
tty.setraw(slave)
print(os.ttyname(slave), flush=True)
os.set_blocking(master, False)
while True:  # watches the line as a paced bus does: spinning, yielding the CPU each turn
    try:
        data = os.read(master, 4096)
    except BlockingIOError:
        os.sched_yield()
        continue
    os.write(master, data)
"""


def _pty_round_trip(duration: float, size: int) -> tuple[float, float]:
    """The pseudo-terminal's own share of a paced read: ``size`` bytes written to a process
    that writes them straight back (watching the line as the paced bus does), read back as
    the driver reads (poll, then read), at 1 kHz; (mean, median) ms of the round trip."""
    import os
    import select
    import tty

    proc = subprocess.Popen([sys.executable, "-c", _ECHO], stdout=subprocess.PIPE, text=True)
    fd = -1
    try:
        fd = os.open(proc.stdout.readline().strip() if proc.stdout else "", os.O_RDWR
                     | os.O_NOCTTY)
        tty.setraw(fd)
        poll = select.poll()
        poll.register(fd, select.POLLIN)
        message = bytes(size)

        def echo() -> int:
            os.write(fd, message)
            got = 0
            while got < size and poll.poll(100):
                got += len(os.read(fd, 4096))
            return got

        for _ in range(20):
            echo()
        mean, median, _, _ = _paced_ms(echo, duration, expect=size)
    finally:
        if fd >= 0:
            os.close(fd)
        proc.kill()
        proc.wait(timeout=5)
    return mean, median


def _sdk_bulk_hz(pty: str, baud: int, duration: float) -> float | None:
    """dynamixel-sdk's GroupBulkRead of the same items, as fast as it goes."""
    got = _sdk_bulk(pty, baud, duration)
    return None if got is None else got[0]


def measure_mixed_unpaced(duration: float, baud: int = 4_000_000) -> dict:
    """The same seven servos and items on an unpaced bus (it answers at once, no wire time):
    reads per second flat out — deltoctl's Sync Read, Bulk Read and Fast Sync Read against
    dynamixel-sdk's GroupBulkRead (and its GroupSyncRead, for reference) — and the CPU µs a
    read costs this process (the software's cost) and the emulator's (the same for both;
    with the pseudo-terminal's wake-ups, in every read's time)."""
    proc, pty = _bus_process(len(MIXED), pace=False, models=MIXED)
    try:
        driver = _mixed_driver(pty, baud)
        ways = _read_ways(driver)
        ours = {k: _flat_out(ways[k], duration, proc.pid) for k in ("sync_read", "bulk_read")}
        driver.cleanup()
        driver = _mixed_driver(pty, baud, fast=True)
        ours["fast_sync_read"] = _flat_out(_read_ways(driver)["sync_read"], duration, proc.pid)
        driver.cleanup()
        theirs = _sdk_bulk(pty, baud, duration, proc.pid)
        theirs_sync = _sdk_rate(pty, len(MIXED), duration)
    finally:
        _stop(proc)
    runs = {f"deltoctl_{k}": v for k, v in ours.items()}
    out: dict = {f"{k}_hz": round(v[0], 1) for k, v in runs.items()}
    if theirs is not None:
        hz = theirs[0]
        runs["dynamixel_sdk_bulk_read"] = theirs
        out.update({"dynamixel_sdk_bulk_read_hz": round(hz, 1),
                    "ratio_to_sdk": round(ours["sync_read"][0] / hz, 2),
                    "ratios_to_sdk": {k: round(v[0] / hz, 2) for k, v in ours.items()},
                    "goal_ratio_ge_2": ours["sync_read"][0] >= 2 * hz})
    if theirs_sync is not None:
        out["dynamixel_sdk_sync_read_hz"] = round(theirs_sync[0], 1)
    out["cpu_us_per_read"] = {k: round(v[1], 1) for k, v in runs.items()}
    out["emulator_cpu_us_per_read"] = {k: None if v[2] is None else round(v[2], 1)
                                       for k, v in runs.items()}
    return out


def measure_mixed_bus(duration: float, baud: int = 4_000_000) -> dict:
    """Five XM430 and two XL330 on one bus paced at ``baud``: deltoctl's read of all seven
    at 1 kHz against the wire time of one Sync Read, beside a Bulk Read and a Sync Read per
    model, and the pseudo-terminal's own round trip (``pty_round_trip_ms``: the bus's
    transport here, which a real bus does not have) taken out; then deltoctl flat out against
    dynamixel-sdk's GroupBulkRead on the same bus, paced (the wire's limit caps both:
    ``flat_out_wire_limit_hz``) and unpaced (``unpaced``)."""
    from deltoctl.families.dynamixel import codec

    ids = list(range(1, len(MIXED) + 1))
    replies = sum(len(codec.status(i, 0, bytes(10))) for i in ids)
    wire = {"sync_read": len(codec.sync_read(126, 10, ids)) + replies,
            "bulk_read": len(codec.bulk_read([(i, 126, 10) for i in ids])) + replies}
    wire_ms = {k: n * 10 / baud * 1e3 for k, n in wire.items()}
    pty_mean, pty_median = _pty_round_trip(duration, len(codec.sync_read(126, 10, ids)))
    proc, pty = _bus_process(len(MIXED), pace=True, models=MIXED)
    try:
        driver = _mixed_driver(pty, baud)
        ways = {}
        for name, read in _read_ways(driver).items():
            mean, median, p99, short = _paced_ms(read, duration)
            ways[name] = {"mean_ms": round(mean, 4), "median_ms": round(median, 4),
                          "p99_ms": round(p99, 4), "short_reads": short}
        flat = 1.0 / (_cycle_ms(_read_ways(driver)["sync_read"], duration) / 1e3)
        driver.cleanup()
        theirs = _sdk_bulk_hz(pty, baud, duration)
    finally:
        _stop(proc)
    best = min(ways, key=lambda k: ways[k]["mean_ms"])
    sync = ways["sync_read"]["mean_ms"] / wire_ms["sync_read"]
    median = ways["sync_read"]["median_ms"] / wire_ms["sync_read"]
    p99 = ways["sync_read"]["p99_ms"] / wire_ms["sync_read"]
    out: dict = {"baud": baud, "servos": {"XM430-W350": 5, "XL330-M288": 2}, "rate_hz": 1000,
                 "wire_ms": {k: round(v, 4) for k, v in wire_ms.items()}, "reads": ways,
                 "fastest": best, "sync_read_over_wire": round(sync, 3),
                 "sync_read_median_over_wire": round(median, 3),
                 "sync_read_p99_over_wire": round(p99, 3),
                 "pty_round_trip_ms": {"mean": round(pty_mean, 4),
                                       "median": round(pty_median, 4)},
                 "sync_read_less_pty_over_wire": round(
                     (ways["sync_read"]["mean_ms"] - pty_mean) / wire_ms["sync_read"], 3),
                 "sync_read_median_less_pty_over_wire": round(
                     (ways["sync_read"]["median_ms"] - pty_median) / wire_ms["sync_read"], 3),
                 "goal_sync_read_le_1_1_of_wire": sync <= 1.1,
                 "deltoctl_flat_out_hz": round(flat, 1),
                 "flat_out_wire_limit_hz": {k: round(1e3 / v, 1) for k, v in wire_ms.items()}}
    if theirs is not None:
        out.update({"dynamixel_sdk_bulk_read_hz": round(theirs, 1),
                    "ratio_to_sdk": round(flat / theirs, 2),
                    "goal_ratio_ge_2": flat >= 2 * theirs})
    out["unpaced"] = measure_mixed_unpaced(duration, baud)
    return out


# -- Protocol 1.0: five AX-12A read in turn -------------------------------------------------------

_SERVE_P1 = """
import sys
from deltoctl.families.dynamixel.emulator import DynamixelPtyServer
from deltoctl.families.dynamixel.emulator1 import Protocol1Bus, Servo1
servos = [Servo1(i) for i in range(1, {n} + 1)]
for servo in servos:
    servo.memory[5] = 0  # Return Delay Time 0, as the MH5 sets its X servos'
server = DynamixelPtyServer(Protocol1Bus(servos, baud=1000000), pace={pace}).start()
print(server.port, flush=True)
sys.stdin.read()
"""


def _p1_driver(pty: str, servos: int) -> Any:
    from deltoctl import registry
    from deltoctl.core.driver import Block
    from deltoctl.families.dynamixel.protocols import BusDriver
    from deltoctl.profile.model import Component, Hardware, Profile

    family = registry.get("dynamixel")
    assert family is not None
    hw = Hardware("bus", family=family.name, params={"protocol_version": "1.0"}, joints=[
        Component("joint", f"j{i}", address=i) for i in range(1, servos + 1)])
    driver = BusDriver(Block(Profile("bench", hardware=[hw]), hw, family,
                                   f"serial://{pty}?baud=1000000"))
    driver.configure()
    return driver


def _sdk_p1_reads(pty: str, servos: int) -> Any:
    """dynamixel-sdk's Protocol 1.0 handler reading each servo in turn (None when it is not
    installed), and what closes its port."""
    try:
        import dynamixel_sdk as sdk
    except ImportError:
        return None, lambda: None
    port = sdk.PortHandler(pty)
    port.openPort()
    port.setBaudRate(1_000_000)
    handler = sdk.PacketHandler(1.0)

    def read() -> int:
        return sum(handler.readTxRx(port, i, 36, 8)[1] == sdk.COMM_SUCCESS
                   for i in range(1, servos + 1))

    return read, port.closePort


def _count(read: Any, ids: list[int]) -> int:
    return len(read(ids))


def measure_protocol1(duration: float, servos: int = 5) -> dict:
    """Five AX-12A on a Protocol 1.0 bus at 1 Mbps, each read in turn (36, 8 bytes: position
    to temperature; Protocol 1.0 has no Sync Read): deltoctl's cycle paced against the wire's
    time and against dynamixel-sdk's Protocol 1.0 reads on the same bus; then both flat out on
    an unpaced bus (what the software costs)."""
    from deltoctl.families.dynamixel import protocol1 as p1

    per_servo = len(p1.read(1, 36, 8)) + len(p1.FRAMES.status(1, 0, bytes(8)))
    wire_ms = servos * per_servo * 10 / 1_000_000 * 1e3
    out: dict = {"servos": servos, "model": "AX-12A", "baud": 1_000_000,
                 "wire_ms": round(wire_ms, 4), "wire_limit_hz": round(1e3 / wire_ms, 1)}
    for pace in (True, False):
        code = _SERVE_P1.format(n=servos, pace=pace)
        proc = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, text=True)
        pty = proc.stdout.readline().strip() if proc.stdout else ""
        try:
            driver = _p1_driver(pty, servos)
            ids = list(range(1, servos + 1))
            ours = _flat_out(partial(_count, driver.read_present, ids), duration, proc.pid)
            driver.cleanup()
            sdk_read, close = _sdk_p1_reads(pty, servos)
            theirs = _flat_out(sdk_read, duration, proc.pid) if sdk_read else None
            close()
        finally:
            _stop(proc)
        key = "paced" if pace else "unpaced"
        run: dict = {"deltoctl_hz": round(ours[0], 1), "deltoctl_cpu_us": round(ours[1], 1)}
        if pace:
            run["fraction_of_wire"] = round(ours[0] * wire_ms / 1e3, 3)
        if theirs is not None:
            run.update({"dynamixel_sdk_hz": round(theirs[0], 1),
                        "dynamixel_sdk_cpu_us": round(theirs[1], 1),
                        "ratio_to_sdk": round(ours[0] / theirs[0], 2)})
        out[key] = run
    return out
