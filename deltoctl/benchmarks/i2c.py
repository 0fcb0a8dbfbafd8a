"""``bench i2c``: the Bioscara read cycle on the in-process emulator — deltoctl's own time
per transaction against the I2C wire time, beside a hand-written smbus2 loop."""

from __future__ import annotations

import struct
import time

from smbus2 import i2c_msg

from deltoctl import registry
from deltoctl.core.driver import Block, Links
from deltoctl.families.bioscara import codec
from deltoctl.families.bioscara.driver import BioscaraDriver
from deltoctl.families.bioscara.emulator import joints_for_block
from deltoctl.profile.catalog import load_profile
from deltoctl.sim.i2c_bus import SimSMBus
from deltoctl.transport.i2c import I2CBus, wire_bits


class _Timed:
    """An SMBus-compatible wrapper that adds up the time spent inside the bus it wraps."""

    def __init__(self, smbus: SimSMBus) -> None:
        self.smbus = smbus
        self.seconds = 0.0

    def i2c_rdwr(self, *msgs: i2c_msg) -> None:
        start = time.perf_counter()
        self.smbus.i2c_rdwr(*msgs)
        self.seconds += time.perf_counter() - start

    def close(self) -> None:
        self.smbus.close()


def measure(cycles: int, clock: int) -> dict:
    """deltoctl's time per transaction (the emulator's own time taken out), the wire time of
    those transactions at ``clock`` Hz, and the hand-written smbus2 loop."""
    profile = load_profile("bioscara-arm")
    hw = profile.hardware[0]
    timed = _Timed(SimSMBus(joints_for_block(hw)))
    url = "i2c:///dev/i2c-bench"
    links = Links()
    links.open[url] = I2CBus(timed, url)  # the emulator in-process: no socket in the way
    family = registry.get(profile.family_of(hw))
    assert family is not None
    driver = BioscaraDriver(Block(profile, hw, family, url, links=links))
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
    return results
