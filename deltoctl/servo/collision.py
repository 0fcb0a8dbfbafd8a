"""Servos that answer at once on a half-duplex bus: their statuses overlap on the wire. The
line is low (0) whenever one of them drives it low, so the host reads the bytes ANDed — garbled
where they differ, and clean where they are byte-identical (identical bytes superimposed are
the same bytes), so a host tells two servos at one ID apart only by something that differs
between them (a pose, a model)."""

from __future__ import annotations

from collections.abc import Callable

from deltoctl.servo.pty_server import Replies


def collide(packets: list[bytes]) -> bytes:
    """What the host reads when ``packets`` are sent at once (a longer one's tail goes
    through alone)."""
    out = bytearray(max(len(p) for p in packets))
    for k in range(len(out)):
        byte = 0xFF
        for p in packets:
            if k < len(p):
                byte &= p[k]
        out[k] = byte
    return bytes(out)


def overlap(answers: list[list[tuple[int, Replies]]],
            sender: Callable[[bytes], int | None]) -> list[tuple[int, Replies]]:
    """Several groups of servos on one wire, each group's answers to the same bytes (one
    protocol: each group read the same requests): per request, the statuses sent from one ID
    (``sender``; None: none can tell, it stays apart) collide into one, each at its first
    sender's place and return delay; the others go as they came."""
    out: list[tuple[int, Replies]] = []
    for k in range(max((len(a) for a in answers), default=0)):
        same = [a[k] for a in answers if k < len(a)]
        slots: dict[object, list[tuple[float, bytes]]] = {}
        for _, replies in same:
            for delay, packet in replies:
                key = sender(packet)
                slots.setdefault(object() if key is None else key, []).append((delay, packet))
        out.append((same[0][0], [(s[0][0], collide([p for _, p in s])) for s in slots.values()]))
    return out
