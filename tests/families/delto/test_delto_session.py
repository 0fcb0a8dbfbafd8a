"""The Delto protocol session as a host/device pair with no transport: what one side sends, the
other receives byte for byte, split or coalesced, and a stream that breaks the protocol."""

from __future__ import annotations

import pytest

from deltoctl.errors import ProtocolError
from deltoctl.families.delto import codec
from deltoctl.families.delto.emulator import firmware_for_profile
from deltoctl.families.delto.session import NEED_DATA, Reply, Request, Role, Session
from deltoctl.profile.catalog import load_profile

DG5F_R = codec.MODELS[0x5F22]
CODES = codec.data_codes(DG5F_R, True, True)
SENSOR = 1  # FT_6AXIS


def events(session: Session, data: bytes) -> list:
    session.receive_data(data)
    out = []
    while (event := session.next_event()) is not NEED_DATA:
        out.append(event)
    return out


def test_every_request_reaches_the_device_and_every_reply_the_host():
    """Each request kind: the host sends it, the device gets it as a Request, its reply (if
    it has one) comes back to the host as a Reply; the others leave nothing due."""
    host, device = Session(Role.HOST), Session(Role.DEVICE)
    firmware = firmware_for_profile(load_profile("dg-5f-right"))
    requests = [codec.encode_version_request(), codec.encode_data_request(CODES),
                codec.encode_duty([100] * 20), codec.encode_gpio((True, False, True)),
                codec.encode_ft_offset()]
    for request in requests:
        (got,) = events(device, host.send(request))
        assert isinstance(got, Request) and got.frame == request and got.cmd == request[2]
        answered = request[2] in (codec.GET_VERSION, codec.GET_DATA)
        assert got.answered == answered
        assert host.expected == device.expected == int(answered)
        reply = firmware.handle(got.frame)
        assert (reply is not None) == answered
        if reply is None:
            continue
        (back,) = events(host, device.send(reply))
        assert isinstance(back, Reply) and back.cmd == request[2] and back.frame == reply
        assert host.expected == device.expected == 0
    assert firmware.gpio_out == [True, False, True] and firmware.duty == [100] * 20


def test_replies_come_in_the_order_asked_whatever_the_split():
    """Three requests at once (coalesced), their replies fed back one byte at a time."""
    host, device = Session(Role.HOST), Session(Role.DEVICE)
    version = codec.encode_version_reply(codec.VersionInfo(0x5F22, (3, 0), 1, 0x1F))
    data = codec.encode_data_reply(codec.DataRecord([0.1] * 20, [5.0] * 20, [30.0] * 20,
                                                    [0.0] * 20, [(0.0,) * 6] * 5,
                                                    gpio=(True, False, False, True)),
                                   DG5F_R, CODES, SENSOR)
    stream = b"".join(host.send(r) for r in (codec.encode_version_request(),
                                              codec.encode_duty([0] * 20),
                                              codec.encode_data_request(CODES)))
    assert [e.cmd for e in events(device, stream)] == [codec.GET_VERSION, codec.SET_DUTY,
                                                      codec.GET_DATA]
    assert host.expected == device.expected == 2
    replies = device.send(version) + device.send(data)
    got = []
    for i in range(len(replies)):
        got += events(host, replies[i:i + 1])
        assert len(got) == (i + 1 >= len(version)) + (i + 1 == len(replies))
    assert [g.frame for g in got] == [version, data] and host.expected == 0
    assert codec.decode_data_reply(got[1].frame, DG5F_R, CODES, SENSOR).gpio == \
        (True, False, False, True)


def test_received_straight_into_the_buffer():
    """``room`` and ``received``, as a socket's recv_into uses them, across many frames."""
    host = Session(Role.HOST, max_frame=64)
    reply = codec.frame(codec.GET_DATA, bytes(range(40)))
    for _ in range(50):
        host.send(codec.encode_data_request(CODES))
    stream = reply * 50
    got = []
    while stream:
        room = host.room()
        count = min(len(room), 37, len(stream))
        room[:count] = stream[:count]
        host.received(count)
        stream = stream[count:]
        got += [e.frame for e in iter(host.next_event, NEED_DATA)]
    assert got == [reply] * 50 and host.buffered == 0


def test_a_reply_not_asked_for_breaks_the_conversation():
    host = Session(Role.HOST)
    with pytest.raises(ProtocolError, match="GET_DATA reply arrived, no reply was due"):
        events(host, codec.frame(codec.GET_DATA, b"\0"))
    host = Session(Role.HOST)
    host.send(codec.encode_version_request())
    with pytest.raises(ProtocolError, match="GET_DATA reply arrived, GET_VERSION was due"):
        events(host, codec.frame(codec.GET_DATA, b"\0"))


def test_the_device_sends_only_the_reply_due():
    device = Session(Role.DEVICE)
    with pytest.raises(ProtocolError, match="not due"):
        device.send(codec.frame(codec.GET_VERSION, b"\0" * 4))
    events(device, codec.encode_version_request())
    with pytest.raises(ProtocolError, match="GET_DATA reply is not due"):
        device.send(codec.frame(codec.GET_DATA, b""))


@pytest.mark.parametrize("role", [Role.HOST, Role.DEVICE])
@pytest.mark.parametrize("head", [b"\x00\x00", b"\x00\x02", b"\x10\x01", b"\xff\xff"])
def test_a_frame_length_out_of_bounds_breaks_the_stream_for_good(role, head):
    """Too short, or over the maximum: no start marker to resynchronise on, so the stream is
    over — every later call says so, whatever comes after (the connection is closed)."""
    session = Session(role)
    if role is Role.HOST:
        session.send(codec.encode_version_request())
    with pytest.raises(ProtocolError, match=r"is not possible \(3\.\.4096\)"):
        events(session, head + b"\x08")
    assert session.buffered == 0
    with pytest.raises(ProtocolError, match="not possible"):
        events(session, codec.encode_version_request())
    with pytest.raises(ProtocolError, match="not possible"):
        session.send(codec.encode_version_request())


def test_a_frame_at_the_maximum_passes_and_one_byte_more_does_not():
    device = Session(Role.DEVICE, max_frame=100)
    assert [len(e.frame) for e in events(device, codec.frame(0x05, bytes(97)))] == [100]
    with pytest.raises(ProtocolError, match="101 is not possible"):
        events(device, codec.frame(0x05, bytes(98)))


def test_garbage_is_one_protocol_error_as_soon_as_it_shows():
    """An HTTP client on the port: its first two bytes read as a length of 0x4745."""
    session = Session(Role.DEVICE)
    garbage = b"GET / HTTP/1.1\r\n"
    assert events(session, garbage[:1]) == []
    with pytest.raises(ProtocolError, match="frame length 18245 is not possible"):
        events(session, garbage[1:])


def test_a_short_frame_waits_for_the_rest():
    device = Session(Role.DEVICE)
    request = codec.encode_data_request(CODES)
    assert events(device, request[:1]) == [] and events(device, request[1:3]) == []
    assert device.buffered == 3
    assert [e.frame for e in events(device, request[3:])] == [request]
