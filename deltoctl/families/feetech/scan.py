"""How a box of Feetech servos is found at an unknown rate: a broadcast PING per Baud_Rate
code's rate (each servo answers, with no data), then a READ of 0..57 of each ID that
answered — firmware, model and present position: two servos at one ID differ in position,
so their replies garble where their PINGs did not. 1 Mbps, the factory rate, comes first."""

from __future__ import annotations

from typing import Any

from deltoctl.families.feetech import codec
from deltoctl.families.feetech.models import BAUD_RATES, by_bytes
from deltoctl.servo.scan import BROADCAST, BROADCAST_REPLIES, Found, Probe, listen, several


def _broadcast(baud: int) -> Probe:
    def run(port: Any, wait: float, first: bool = False) -> list[Found]:
        replies, garbled = listen(port, codec.session(), codec.BROADCAST_ID, codec.PING, b"",
                                  wait, 0, BROADCAST_REPLIES - 1)
        ids = [i for i, _, _ in replies]
        twice = several(ids)
        rows = [_identify(port, i, baud, wait, i in twice) for i in sorted(set(ids))]
        if garbled:
            rows.append(Found(None, "", "", "Feetech", baud, True))
        return rows

    return Probe("Feetech", baud, BROADCAST, run)


def _identify(port: Any, device_id: int, baud: int, wait: float, twice: bool) -> Found:
    replies, garbled = listen(port, codec.session(), device_id, codec.READ,
                              codec.read_params(0, 58), wait, 58)
    if not replies or len(replies[0][2]) < 5:
        return Found(device_id, "", "", "Feetech", baud, True)
    data = replies[0][2]
    model = by_bytes(data[3:5])
    name = model.name if model else f"model bytes {data[3]:02x} {data[4]:02x}"
    return Found(device_id, name, f"{data[0]}.{data[1]}", "Feetech", baud,
                 twice or garbled or len(replies) > 1)


def probes() -> list[Probe]:
    rates = sorted(BAUD_RATES.values(), key=lambda b: (b != 1_000_000, b == 128_000, -b))
    return [_broadcast(b) for b in rates]
