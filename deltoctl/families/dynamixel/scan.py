"""How a box of Dynamixel servos is found at an unknown rate and protocol: a broadcast PING
per X-series rate in Protocol 2.0 (every servo answers with its model and firmware; then a READ
of each one's present position, as servos of one model at one ID ping alike), and in
Protocol 1.0, whose broadcast PING no servo answers, a PING to ID 1 (the factory's) per AX/MX
rate, then to each ID 0–252 in turn, and the model and firmware of each that answers read at
address 0. The common rates come first (1 Mbps, the AX's default; 57,600, the X's and MX's)."""

from __future__ import annotations

import struct
from typing import Any

from deltoctl.families.dynamixel import codec, protocol1
from deltoctl.families.dynamixel.control_table import BAUD_RATES
from deltoctl.families.dynamixel.models import by_number
from deltoctl.families.dynamixel.models1 import BAUD_CODES
from deltoctl.servo.scan import (
    BROADCAST,
    BROADCAST_REPLIES,
    FACTORY_ID,
    SWEEP,
    Found,
    Probe,
    alone,
    hear,
    listen,
    pings,
    several,
)

COMMON = (1_000_000, 57_600)
EVERY_ID = (1, 0, *range(2, 253))  # the factory's ID first


def _ordered(rates: Any) -> list[int]:
    return sorted(rates, key=lambda b: (b not in COMMON, COMMON.index(b) if b in COMMON else -b))


def _model(number: int) -> str:
    model = by_number(number)
    return model.name if model else f"model number {number}"


def _broadcast_2(baud: int) -> Probe:
    def run(port: Any, wait: float, first: bool = False) -> list[Found]:
        session = codec.session()
        replies, data = hear(port, session, codec.BROADCAST_ID, codec.PING, b"",
                             wait, 3,
                             BROADCAST_REPLIES - 1)
        twice = several([i for i, _, _ in replies])
        rows = [Found(i, _model(number), str(d[2]), "Dynamixel 2.0", baud,
                      i in twice or not _alone(port, i, number, wait))
                for i, _, d in replies if len(d) == 3
                for number in struct.unpack_from("<H", d)]
        rows = list({row.id: row for row in rows}.values())
        if sum(session.frames.status_size(len(d)) for _, _, d in replies) < len(data):
            ids = _headers(data) - {row.id for row in rows}  # garbled statuses keep their ID
            rows += [Found(i, "", "", "Dynamixel 2.0", baud, True) for i in sorted(ids)] or \
                [Found(None, "", "", "Dynamixel 2.0", baud, True)]
        return rows

    return Probe("Dynamixel 2.0", baud, BROADCAST, run)


def _alone(port: Any, device_id: int, number: int, wait: float) -> bool:
    """Whether the PING's clean status was one servo's (its present position read: see
    deltoctl.servo.scan.alone)."""
    model = by_number(number)
    item = model.by_name.get("Present Position") if model is not None else None
    if item is None:
        return True
    return alone(port, codec.session(), device_id, codec.READ,
                 codec.read_params(item.address, item.size), wait, item.size)


def _headers(data: bytes) -> set[int]:
    """The IDs in the Protocol 2.0 headers among ``data`` (servos at one ID send one header:
    it survives their collision)."""
    ids, at = set(), data.find(codec.HEADER)
    while 0 <= at < len(data) - 4:
        if data[at + 4] < codec.BROADCAST_ID:
            ids.add(data[at + 4])
        at = data.find(codec.HEADER, at + 1)
    return ids


def _sweep_1(baud: int, ids: tuple[int, ...]) -> Probe:
    def run(port: Any, wait: float, first: bool = False) -> list[Found]:
        heard, noise = pings(port, protocol1.session(), protocol1.PING, ids, wait, first)
        rows: list[Found] = []
        for i in ids if noise else heard:  # bytes that garbled: each ID asked alone, to tell
            if rows and first:
                break
            replies, garbled = listen(port, protocol1.session(), i, protocol1.PING, b"", wait)
            if not replies and not garbled:
                continue
            data, garbled_read = _read(port, i, wait)
            garbled = garbled or len(replies) > 1
            number, firmware = struct.unpack_from("<HB", data) if len(data) >= 3 else (0, 0)
            rows.append(Found(i, _model(number) if data else "", str(firmware) if data else "",
                              "Dynamixel 1.0", baud, garbled or garbled_read))
        return rows

    return Probe("Dynamixel 1.0", baud, FACTORY_ID if len(ids) == 1 else SWEEP, run)


def _read(port: Any, device_id: int, wait: float) -> tuple[bytes, bool]:
    """Model, firmware and present position (two servos at one ID differ in it: they garble)."""
    replies, garbled = listen(port, protocol1.session(), device_id, protocol1.READ,
                              protocol1.read_params(0, 38), wait, 38)
    return (replies[0][2] if replies else b""), garbled or len(replies) != 1


def probes() -> list[Probe]:
    return [*(_broadcast_2(b) for b in _ordered(BAUD_RATES.values())),
            *(_sweep_1(b, (1,)) for b in _ordered(BAUD_CODES)),
            *(_sweep_1(b, EVERY_ID) for b in _ordered(BAUD_CODES))]
