"""Servos answering at once on one wire: their statuses AND (garbled where they differ, clean
where they are alike), per request and per sending ID; a status from another ID, or one that
does not check, goes as it came."""

from __future__ import annotations

from deltoctl.servo.collision import collide, overlap
from deltoctl.servo.frames import checksum

SPLIT = checksum.ChecksumFrames().split


def _sender(packet: bytes) -> int | None:
    statuses = SPLIT(packet)
    return statuses[0][0] if statuses else None


def test_bytes_and_a_longer_tail_goes_through():
    assert collide([b"\xff\x0f", b"\xf0\xff\x01"]) == b"\xf0\x0f\x01"


def test_statuses_from_one_id_collide_others_stay_apart():
    one, twin = checksum.status(1, 0, b"\x10"), checksum.status(1, 0, b"\x20")
    other, bad = checksum.status(2, 0, b"\x10"), b"\xff\xff\x03\x02\x00\x00"
    answers = [[(6, [(0.001, one), (0.0, bad)])], [(6, [(0.002, twin), (0.0, other)])]]
    [(size, replies)] = overlap(answers, _sender)
    assert size == 6
    assert replies == [(0.001, collide([one, twin])), (0.0, bad), (0.0, other)]
    assert SPLIT(replies[0][1]) == []  # garbled: its checksum fails
    alike = overlap([[(6, [(0.0, one)])], [(6, [(0.0, one)])]], _sender)
    assert alike == [(6, [(0.0, one)])]  # identical bytes superimposed are clean


def test_requests_one_group_alone_heard_go_through():
    one = checksum.status(1)
    assert overlap([[(6, [(0.0, one)]), (8, [])], [(6, [])]], _sender) == \
        [(6, [(0.0, one)]), (8, [])]
    assert overlap([], _sender) == []
