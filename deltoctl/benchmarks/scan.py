"""``bench scan``: how long ``deltoctl scan`` takes to find one servo at a rate and in a
protocol it is not told, per link kind, each servo alone on a paced emulated bus in another
process (the bus takes the wire time of every byte at the rate the host set) — its bus time
(the scan's own figure, the probes on the link) and its wall time (the command in a process of
its own, Python's start and imports included) — side by side with what the SDKs' own way takes
on the same bus, going through the rates in the vendor's order:

- Protocol 2.0: dynamixel-sdk's ``broadcastPing`` at each rate of ROBOTIS' ``find_dynamixel``
  (9,600 up to 4 Mbps; the SDK opens no 4.5 Mbps);
- Protocol 1.0: dynamixel-sdk's ``ping`` of IDs 0-252 at each of those rates, as ROBOTIS'
  tools sweep them;
- Feetech: scservo_sdk's ``ping`` of IDs 0-252 at each rate of the Baud_Rate table (1 Mbps
  first; the SDK opens no 76,800), and a broadcast PING at each of LeRobot's scan rates
  (4,800 up), which scservo_sdk has no call for: sent with its ``txPacket``, its replies
  collected until the timeout LeRobot gives it, then each servo's model read.

Each way stops at the first rate where a servo answers (a sweep at its first servo), the most
favourable reading of an SDK's scan. Then, where cheap, a factory-new arm's bus (six servos at
ID 1: the colliding case), as ``sim serve --factory-new --pace`` serves it."""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

GOAL_S = 1.0  # one servo at an unknown rate and protocol found within a second of bus time
FIND_DYNAMIXEL = (9_600, 57_600, 115_200, 1_000_000, 2_000_000, 3_000_000, 4_000_000)
FEETECH_TABLE = (1_000_000, 500_000, 250_000, 128_000, 115_200, 76_800, 57_600, 38_400)
LEROBOT_SCAN = (4_800, 9_600, 14_400, 19_200, 38_400, 57_600, 115_200, 128_000, 250_000,
                500_000, 1_000_000)
IDS = range(253)  # 0-252, what the SDKs' sweeps ping


@dataclass(frozen=True)
class Case:
    """One servo alone on a bus: its protocol (as ``deltoctl scan`` names it), ID and rate."""

    model: str
    protocol: str
    id: int
    baud: int


CASES = {
    "xl430-57600": Case("XL430-W250", "Dynamixel 2.0", 1, 57_600),
    "xl430-1m": Case("XL430-W250", "Dynamixel 2.0", 1, 1_000_000),
    "xl430-9600": Case("XL430-W250", "Dynamixel 2.0", 1, 9_600),
    "xl430-4m": Case("XL430-W250", "Dynamixel 2.0", 1, 4_000_000),
    "ax12a-1m-id1": Case("AX-12A", "Dynamixel 1.0", 1, 1_000_000),
    "ax12a-1m-id42": Case("AX-12A", "Dynamixel 1.0", 42, 1_000_000),
    "ax12a-57600-id1": Case("AX-12A", "Dynamixel 1.0", 1, 57_600),
    "ax12a-57600-id42": Case("AX-12A", "Dynamixel 1.0", 42, 57_600),
    "sts3215-1m": Case("STS3215", "Feetech", 1, 1_000_000),
    "sts3215-500k": Case("STS3215", "Feetech", 1, 500_000),
    "sts3215-38400": Case("STS3215", "Feetech", 1, 38_400),
}
ARMS = {"koch-arm-factory-new": ("koch-arm", "Dynamixel 2.0"),
        "so101-factory-new": ("so101-follower", "Feetech")}

_SERVE = """
import sys
{imports}
server = {server}.start()
print(server.port, flush=True)
sys.stdin.read()
"""
_BUSES = {
    "Dynamixel 2.0": ("from deltoctl.families.dynamixel.emulator import DynamixelBus, "
                      "DynamixelPtyServer, Servo",
                      "DynamixelPtyServer(DynamixelBus([Servo({id})], baud={baud}), pace=True)"),
    "Dynamixel 1.0": ("from deltoctl.families.dynamixel.emulator import DynamixelPtyServer\n"
                      "from deltoctl.families.dynamixel.emulator1 import Protocol1Bus, Servo1",
                      "DynamixelPtyServer(Protocol1Bus([Servo1({id})], baud={baud}), pace=True)"),
    "Feetech": ("from deltoctl.families.feetech.emulator import FeetechBus, FeetechPtyServer, "
                "Servo", "FeetechPtyServer(FeetechBus([Servo({id})], baud={baud}), pace=True)"),
}


def _served(case: Case) -> tuple[subprocess.Popen, str]:
    """The case's servo, alone on a paced bus in another process: (process, pty path)."""
    imports, server = _BUSES[case.protocol]
    code = _SERVE.format(imports=imports, server=server.format(id=case.id, baud=case.baud))
    proc = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    return proc, proc.stdout.readline().strip() if proc.stdout else ""


def _served_arm(profile: str) -> tuple[subprocess.Popen, str]:
    """``sim serve PROFILE --factory-new --pace`` in another process: (process, pty path)."""
    proc = subprocess.Popen([sys.executable, "-m", "deltoctl", "sim", "serve", profile, "--json",
                             "--factory-new", "--pace"], stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, text=True)
    line = proc.stdout.readline() if proc.stdout else "{}"
    [url] = json.loads(line)["buses"].values()
    return proc, url.split("://", 1)[1].split("?", 1)[0]


def _stop(proc: subprocess.Popen) -> None:
    if proc.stdin:
        proc.stdin.close()
    proc.terminate()
    proc.wait(timeout=5)


# -- deltoctl -------------------------------------------------------------------------------


def _deltoctl(pty: str) -> dict[str, Any]:
    """``deltoctl --json scan PTY`` in a process of its own: its bus time, the wall time of
    the command, what it found and the probes it ran."""
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "deltoctl", "--json", "scan", pty],
                          capture_output=True, text=True, timeout=600)
    wall = time.perf_counter() - start
    doc = json.loads(done.stdout).get("result", {}) if done.stdout.strip() else {}
    return {"bus_s": doc.get("bus_seconds"), "wall_s": wall, "exit_code": done.returncode,
            "probes": doc.get("probes"), "found": [
                {k: s[k] for k in ("id", "model", "protocol", "baud", "colliding")}
                for s in doc.get("servos", [])]}


# -- the SDKs' own ways ---------------------------------------------------------------------

Found = list[dict[str, Any]]  # {"id", "baud"} of each servo a way found


def _dynamixel_port(pty: str) -> tuple[Any, Any]:
    import dynamixel_sdk as sdk

    port = sdk.PortHandler(pty)
    port.openPort()
    return sdk, port


def _broadcast_ping_2(pty: str) -> tuple[Found, int]:
    """dynamixel-sdk's broadcastPing at each of find_dynamixel's rates up to one that
    answers: (what it found, the rates it tried)."""
    sdk, port = _dynamixel_port(pty)
    handler = sdk.PacketHandler(2.0)
    try:
        for n, baud in enumerate(FIND_DYNAMIXEL, 1):
            port.setBaudRate(baud)
            found, result = handler.broadcastPing(port)
            if result == sdk.COMM_SUCCESS and found:
                return [{"id": i, "baud": baud} for i in sorted(found)], n
        return [], len(FIND_DYNAMIXEL)
    finally:
        port.closePort()


def _ping_sweep(port: Any, ping: Callable[[int], bool], rates: tuple[int, ...],
                set_rate: Callable[[int], bool]) -> tuple[Found, int]:
    """``ping`` of IDs 0-252 at each rate the SDK opens, up to the first servo that answers."""
    tried = 0
    for baud in rates:
        if not set_rate(baud):
            continue  # a rate the SDK cannot open
        tried += 1
        for i in IDS:
            if ping(i):
                return [{"id": i, "baud": baud}], tried
    return [], tried


def _ping_sweep_1(pty: str) -> tuple[Found, int]:
    """dynamixel-sdk's Protocol 1.0 ping of IDs 0-252 at each of find_dynamixel's rates."""
    sdk, port = _dynamixel_port(pty)
    handler = sdk.PacketHandler(1.0)
    try:
        return _ping_sweep(port, lambda i: handler.ping(port, i)[1] == sdk.COMM_SUCCESS,
                           FIND_DYNAMIXEL, port.setBaudRate)
    finally:
        port.closePort()


def _scservo_port(pty: str) -> tuple[Any, Any, Any]:
    import scservo_sdk as sdk

    port = sdk.PortHandler(pty)
    port.openPort()
    return sdk, port, sdk.PacketHandler(0)


def _scservo_sweep(pty: str) -> tuple[Found, int]:
    """scservo_sdk's ping (a PING, then a read of the model) of IDs 0-252 at each rate of
    the Baud_Rate table."""
    sdk, port, handler = _scservo_port(pty)
    try:
        return _ping_sweep(port, lambda i: handler.ping(port, i)[1] == sdk.COMM_SUCCESS,
                           FEETECH_TABLE, port.setBaudRate)
    finally:
        port.closePort()


def _scservo_broadcast(pty: str) -> tuple[Found, int]:
    """A broadcast PING at each of LeRobot's scan rates, with scservo_sdk's port and packet
    handler, up to a rate where servos answer; then each one's model number read."""
    sdk, port, handler = _scservo_port(pty)
    try:
        tried = 0
        for baud in LEROBOT_SCAN:
            if not port.setBaudRate(baud):
                continue
            tried += 1
            ids = _broadcast_ids(sdk, port, handler, baud)
            if ids:
                for i in ids:
                    handler.read2ByteTxRx(port, i, 3)  # Model_Number, as LeRobot reads it
                return [{"id": i, "baud": baud} for i in ids], tried
        return [], tried
    finally:
        port.closePort()


def _broadcast_ids(sdk: Any, port: Any, handler: Any, baud: int) -> list[int]:
    """One broadcast PING: the IDs of the well-formed statuses heard until the timeout of
    252 statuses' wire time, 3 ms each and 16 ms more (LeRobot's)."""
    from deltoctl.families.feetech import codec

    statuses = 6 * sdk.MAX_ID
    session = codec.session()
    if handler.txPacket(port, list(session.send(codec.BROADCAST_ID, codec.PING, b""))) \
            != sdk.COMM_SUCCESS:
        return []
    port.setPacketTimeoutMillis(statuses * 10_000.0 / baud + 3.0 * sdk.MAX_ID + 16.0)
    data = b""
    while not port.isPacketTimeout() and len(data) < statuses:
        data += bytes(port.readPort(statuses - len(data)))
    port.is_using = False
    return sorted({i for i, _, _ in session.frames.split(data)})


SDK_WAYS: dict[str, tuple[str, Callable[[str], tuple[Found, int]]]] = {
    "dynamixel_sdk broadcastPing": ("Dynamixel 2.0", _broadcast_ping_2),
    "dynamixel_sdk ping sweep": ("Dynamixel 1.0", _ping_sweep_1),
    "scservo_sdk ping sweep": ("Feetech", _scservo_sweep),
    "scservo_sdk broadcast ping (LeRobot's)": ("Feetech", _scservo_broadcast),
}
ARM_WAYS = ("dynamixel_sdk broadcastPing", "scservo_sdk broadcast ping (LeRobot's)")


def _installed(way: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(way.split()[0]) is not None


def _sdk(way: str, pty: str) -> dict[str, Any]:
    start = time.perf_counter()
    found, rates = SDK_WAYS[way][1](pty)
    return {"s": time.perf_counter() - start, "found": found, "rates_tried": rates}


# -- the runs -------------------------------------------------------------------------------


def _median(runs: list[dict[str, Any]], key: str) -> float | None:
    values = [r[key] for r in runs if r.get(key) is not None]
    return round(statistics.median(values), 4) if values else None


def _runs(serve: Callable[[], tuple[subprocess.Popen, str]], run: Callable[[str], dict],
          count: int) -> list[dict[str, Any]]:
    """``count`` runs of ``run``, each on a bus served afresh (a scan leaves none behind)."""
    out = []
    for _ in range(count):
        proc, pty = serve()
        try:
            out.append(run(pty))
        finally:
            _stop(proc)
    return out


def _deltoctl_row(runs: list[dict[str, Any]], hit: Callable[[dict], bool]) -> dict[str, Any]:
    return {"bus_s": _median(runs, "bus_s"), "wall_s": _median(runs, "wall_s"),
            "bus_runs_s": [r["bus_s"] for r in runs],
            "wall_runs_s": [round(r["wall_s"], 4) for r in runs],
            "probes": runs[-1]["probes"], "exit_code": runs[-1]["exit_code"],
            "found": runs[-1]["found"], "found_it": all(any(map(hit, r["found"])) for r in runs)}


def _sdk_row(runs: list[dict[str, Any]], hit: Callable[[dict], bool]) -> dict[str, Any]:
    return {"s": _median(runs, "s"), "runs_s": [round(r["s"], 4) for r in runs],
            "rates_tried": runs[-1]["rates_tried"], "found": runs[-1]["found"],
            "found_it": all(any(map(hit, r["found"])) for r in runs)}


def measure_case(name: str, runs: int, sdk_runs: int) -> dict[str, Any]:
    """One servo alone: deltoctl's scan ``runs`` times, each SDK way of its protocol
    ``sdk_runs`` times (0: none)."""
    case = CASES[name]

    def hit(found: dict) -> bool:  # the servo, clean (an SDK's found names no protocol)
        return (found["id"], found["baud"], found.get("protocol", case.protocol),
                found.get("model", case.model), found.get("colliding", False)) == \
            (case.id, case.baud, case.protocol, case.model, False)

    ours = _runs(lambda: _served(case), _deltoctl, runs)
    row: dict[str, Any] = {"servo": {"model": case.model, "protocol": case.protocol,
                                     "id": case.id, "baud": case.baud},
                           "deltoctl": _deltoctl_row(ours, hit), "sdks": {}}
    row["goal_bus_le_1_s"] = (row["deltoctl"]["bus_s"] or GOAL_S + 1) <= GOAL_S
    for way, (protocol, _) in SDK_WAYS.items():
        if protocol == case.protocol and sdk_runs > 0 and _installed(way):
            row["sdks"][way] = _sdk_row(
                _runs(lambda: _served(case), lambda pty, w=way: _sdk(w, pty), sdk_runs), hit)
    return row


def measure_arm(name: str, runs: int, sdk_runs: int) -> dict[str, Any]:
    """A factory-new arm's bus, six servos at ID 1: deltoctl's scan, which names the
    colliding replies, and the SDK's broadcast of its family (what it makes of them)."""
    profile, protocol = ARMS[name]
    ours = _runs(lambda: _served_arm(profile), _deltoctl, runs)
    row: dict[str, Any] = {"profile": profile, "protocol": protocol,
                           "deltoctl": _deltoctl_row(ours, lambda f: f["colliding"]),
                           "sdks": {}}
    for way in ARM_WAYS:
        if SDK_WAYS[way][0] == protocol and sdk_runs > 0 and _installed(way):
            row["sdks"][way] = _sdk_row(_runs(lambda: _served_arm(profile),
                                              lambda pty, w=way: _sdk(w, pty), sdk_runs),
                                        lambda f: False)
    return row


def measure(cases: list[str] | None = None, runs: int = 3, sdk_runs: int = 3) -> dict[str, Any]:
    """Every case named (default: all, and the factory-new arms): medians of ``runs`` scans
    by deltoctl and of ``sdk_runs`` by each SDK way."""
    names = cases or [*CASES, *ARMS]
    out: dict[str, Any] = {"runs": runs, "sdk_runs": sdk_runs, "goal_bus_s": GOAL_S,
                           "cases": {}}
    for name in names:
        measure_one = measure_arm if name in ARMS else measure_case
        out["cases"][name] = measure_one(name, runs, sdk_runs)
    return out


def case_names(given: str) -> list[str]:
    """The cases of a comma-separated list (empty: all); an unknown name is a usage error."""
    from deltoctl.errors import InvalidInput

    names = [n.strip() for n in given.split(",") if n.strip()]
    unknown = [n for n in names if n not in CASES and n not in ARMS]
    if unknown:
        raise InvalidInput(f"no scan case {', '.join(unknown)}: the cases are "
                           f"{', '.join([*CASES, *ARMS])}")
    return names
