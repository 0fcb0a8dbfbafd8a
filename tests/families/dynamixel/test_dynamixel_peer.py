"""Peer test: ROBOTIS' dynamixel-sdk and deltoctl put the same bytes on a (pseudo-terminal) wire."""

from __future__ import annotations

import os
import select
import tty

import pytest

from deltoctl.families.dynamixel import codec

sdk = pytest.importorskip("dynamixel_sdk")


@pytest.fixture
def wire():
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    port = sdk.PortHandler(os.ttyname(slave))
    assert port.openPort() and port.setBaudRate(1000000)
    handler = sdk.PacketHandler(2.0)

    def sent() -> bytes:
        data = b""
        while select.select([master], [], [], 0.2)[0]:
            data += os.read(master, 4096)
        return data

    yield port, handler, sent
    port.closePort()
    os.close(master)
    os.close(slave)


def test_packets_are_byte_identical(wire):
    port, ph, sent = wire
    cases = [
        (lambda: ph.write4ByteTxOnly(port, 1, 116, 512),
         codec.write(1, 116, (512).to_bytes(4, "little"))),
        (lambda: ph.write1ByteTxOnly(port, 33, 64, 1), codec.write(33, 64, b"\x01")),
        (lambda: ph.readTx(port, 51, 132, 4), codec.read(51, 132, 4)),
        (lambda: ph.regWriteTxOnly(port, 2, 116, 4, [0, 2, 0, 0]),
         codec.reg_write(2, 116, bytes([0, 2, 0, 0]))),
        (lambda: ph.syncReadTx(port, 126, 10, [11, 12, 13], 3, False), codec.sync_read(126, 10, [11, 12, 13])),
        (lambda: ph.syncWriteTxOnly(port, 64, 1, [11, 1, 12, 0], 4),
         codec.sync_write(64, 1, {11: b"\x01", 12: b"\x00"})),
        (lambda: ph.bulkReadTx(port, [1, 132, 0, 4, 0, 2, 144, 0, 3, 0], 10, False),
         codec.bulk_read([(1, 132, 4), (2, 144, 3)])),
    ]
    for call, ours in cases:
        call()
        port.is_using = False  # the *Tx calls keep the port for the reply we do not read
        assert sent() == ours


def test_byte_stuffing_follows_the_protocol_where_the_python_sdk_does_not(wire):
    """dynamixel-sdk's Python txPacket drops the result of addStuffing, so a payload holding
    FF FF FD goes out unstuffed with the unstuffed LEN; deltoctl stuffs it as Protocol 2.0
    says (FF FF FD → FF FF FD FD, LEN and CRC over the stuffed packet)."""
    port, ph, sent = wire
    payload = bytes([0xFF, 0xFF, 0xFD, 0x00])
    ph.writeTxOnly(port, 1, 116, 4, list(payload))
    sdk_bytes = sent()
    ours = codec.write(1, 116, payload)
    assert sdk_bytes[7:14] == bytes([codec.WRITE, 116, 0]) + payload  # not stuffed
    assert ours[5] == sdk_bytes[5] + 1 and ours[7:15] == bytes(
        [codec.WRITE, 116, 0, 0xFF, 0xFF, 0xFD, 0xFD, 0x00])
    [(device, instruction, body)] = codec.PacketReader().feed(ours)
    assert (device, instruction, body) == (1, codec.WRITE, bytes([116, 0]) + payload)
