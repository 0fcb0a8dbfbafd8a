"""The CANopen conversation as a master and a node, frames passed by hand: no bus."""

import contextlib

import pytest
from deltoctl.errors import DeviceFault, ProtocolError
from hypothesis import given
from hypothesis import strategies as st

from deltoctl_canopen import session
from deltoctl_canopen.codec import Frame
from deltoctl_canopen.session import Abort, Device, Host


class Dictionary:
    """A node's objects: (index, sub) → bytes; 0x2000 is read-only, 0x3000 refuses values."""

    def __init__(self):
        self.values = {(0x1000, 0): (0x20192).to_bytes(4, "little"), (0x1008, 0): b"drive",
                       (0x2000, 0): b"\x01"}

    def read(self, index, sub):
        return self.values[index, sub]

    def write(self, index, sub, data):
        if index == 0x2000:
            raise Abort(0x06010002)
        if index == 0x3000:
            raise Abort(0x06090030)
        self.values[index, sub] = data


def pair(node=2):
    od = Dictionary()
    return Host(), Device(node, od.read, od.write), od


def converse(host, device, frame):
    """Frames back and forth until the host's transfer ends; its events and the frames."""
    frames, events = [frame], []
    while True:
        replies = [e.frame for e in device.receive(frames[-1]) if isinstance(e, session.Send)]
        assert len(replies) == 1
        frames.append(replies[0])
        got = host.receive(replies[0])
        events += got
        sends = [e.frame for e in got if isinstance(e, session.Send)]
        if not sends:
            return events, frames
        frames.append(sends[0])


def test_expedited_upload_golden():
    host, device, _ = pair()
    request = host.upload(2, 0x1000)
    assert request == Frame(0x602, bytes.fromhex("4000100000000000"))
    events, frames = converse(host, device, request)
    assert frames[1] == Frame(0x582, bytes.fromhex("4300100092010200"))
    assert events == [session.SdoDone(2, 0x1000, 0, (0x20192).to_bytes(4, "little"))]
    assert not host.busy(2)


def test_expedited_download_golden():
    host, device, od = pair()
    request = host.download(2, 0x6040, 0, b"\x06\x00")
    assert request == Frame(0x602, bytes.fromhex("2b40600006000000"))
    events, frames = converse(host, device, request)
    assert frames[1] == Frame(0x582, bytes.fromhex("6040600000000000"))
    assert events == [session.SdoDone(2, 0x6040, 0)]
    assert od.values[0x6040, 0] == b"\x06\x00"


@given(st.binary(min_size=0, max_size=200), st.integers(1, 127))
def test_segmented_both_ways(value, node):
    host, device, od = pair(node)
    events, frames = converse(host, device, host.download(node, 0x1008, 0, value))
    assert events[-1] == session.SdoDone(node, 0x1008, 0)
    assert od.values[0x1008, 0] == value
    events, frames = converse(host, device, host.upload(node, 0x1008))
    assert events[-1] == session.SdoDone(node, 0x1008, 0, value)
    toggles = [f.data[0] >> 4 & 1 for f in frames[2:] if f.can_id == 0x580 + node]
    assert toggles == [i % 2 for i in range(len(toggles))]
    assert not host.busy(node)


def test_segmented_upload_frames():
    host, device, _ = pair()
    events, frames = converse(host, device, host.upload(2, 0x1008))
    assert [f.data.hex() for f in frames] == [
        "4008100000000000", "4108100005000000", "6000000000000000", "0564726976650000"]
    assert events[-1].data == b"drive"


@pytest.mark.parametrize("index, code", [(0x2000, 0x06010002), (0x3000, 0x06090030)])
def test_an_abort_is_a_device_fault_with_its_code(index, code):
    host, device, _ = pair()
    with pytest.raises(DeviceFault) as caught:
        converse(host, device, host.download(2, index, 0, b"\x05"))
    assert caught.value.code == code
    assert not host.busy(2)  # the transfer is over: the next request goes out


def test_reading_an_object_the_node_lacks():
    host, device, _ = pair()
    with pytest.raises(DeviceFault) as caught:
        converse(host, device, host.upload(2, 0x6099, 1))
    assert caught.value.code == 0x06020000 and "object does not exist" in caught.value.message


def test_a_reply_nobody_asked_for():
    host = Host()
    with pytest.raises(ProtocolError, match="nobody asked"):
        host.receive(Frame(0x582, bytes.fromhex("4300100092010200")))
    host.upload(2, 0x1000)
    with pytest.raises(ProtocolError, match="not the 0x1000:00"):
        host.receive(Frame(0x582, bytes.fromhex("4318100001000000")))
    host.upload(2, 0x1000)
    with pytest.raises(ProtocolError, match="8 bytes"):
        host.receive(Frame(0x582, b"\x43"))
    host.upload(3, 0x1000)  # another node's reply matches its own request only
    with pytest.raises(ProtocolError, match="node 2"):
        host.receive(Frame(0x582, bytes.fromhex("4300100092010200")))
    assert host.busy(3)


def test_a_segment_out_of_turn():
    host, device, _ = pair()
    host.upload(2, 0x1008)
    host.receive(Frame(0x582, bytes.fromhex("4108100005000000")))
    with pytest.raises(ProtocolError, match="toggle"):
        host.receive(Frame(0x582, bytes.fromhex("1b64726976650000")))
    # the node side: a segment with the wrong toggle, or none open, is aborted
    assert device.receive(Frame(0x602, bytes.fromhex("7000000000000000")))[0].frame.data[:1] \
        == b"\x80"
    events = device.receive(Frame(0x602, bytes.fromhex("4008100000000000")))
    assert events[0].frame.data[0] == 0x41
    reply = device.receive(Frame(0x602, bytes.fromhex("7000000000000000")))[0].frame
    assert reply.data.hex() == "8008100000000305"  # toggle bit not alternated


def test_one_transfer_a_node():
    host, _, _ = pair()
    host.upload(2, 0x1000)
    with pytest.raises(ValueError):
        host.upload(2, 0x1000)
    assert host.cancel(2) == Frame(0x602, bytes.fromhex("8000100000000405"))
    host.upload(2, 0x1000)


def test_nmt_boot_up_heartbeat_and_guarding():
    host, device, _ = pair(5)
    boot = device.boot()
    assert host.receive(boot) == [session.Heartbeat(5, 0)] and host.receive(boot)[0].boot_up
    assert device.state == session.PRE_OPERATIONAL
    assert device.receive(session.nmt_frame(0x01, 4)) == []  # another node's command
    assert device.receive(session.nmt_frame(0x01, 0)) == [session.NmtCommand(0x01, 0)]
    assert device.operational
    assert host.receive(device.heartbeat()) == [session.Heartbeat(5, session.OPERATIONAL)]
    events = device.receive(session.nmt_frame(0x81, 5))
    assert events == [session.NmtCommand(0x81, 5), session.Send(Frame(0x705, b"\x00"))]
    assert device.state == session.PRE_OPERATIONAL
    guard = Frame(0x705, b"", remote=True)
    first, second = (device.receive(guard)[0].frame for _ in range(2))
    assert (first.data, second.data) == (b"\x7f", b"\xff")
    with pytest.raises(ProtocolError):
        device.receive(Frame(0x000, b"\x33\x00"))
    with pytest.raises(ValueError):
        session.nmt_frame(0x33)


def test_sync_and_pdos():
    host, device, _ = pair()
    assert device.receive(session.sync_frame()) == [session.Sync()]
    assert host.receive(Frame(0x182, b"\x37\x06")) == [session.Pdo(0x182, b"\x37\x06")]
    assert device.receive(session.sync_frame(7)) == [session.Sync(7)]


@given(st.binary(min_size=0, max_size=8), st.integers(0x580, 0x5FF))
def test_any_reply_is_an_event_or_one_error(data, can_id):
    host = Host()
    host.upload(can_id & 0x7F or 1, 0x1008)
    with contextlib.suppress(ProtocolError, DeviceFault):
        host.receive(Frame(can_id, data))


@given(st.binary(min_size=0, max_size=8))
def test_any_request_gets_a_reply(data):
    od = Dictionary()
    device = Device(2, od.read, od.write)
    for event in device.receive(Frame(0x602, data)):
        assert isinstance(event, session.Send) and len(event.frame.data) == 8


# -- the master side against the emulated drives, over the local hub -------------------------

def over_hub(bus, host, frame, deadline=5.0):
    """Send a frame; feed every reply to the host until its transfer ends: its last event."""
    import time

    import can

    bus.send(can.Message(arbitration_id=frame.can_id, data=frame.data, is_extended_id=False))
    end = time.monotonic() + deadline
    while time.monotonic() < end:
        msg = bus.recv(0.1)
        if msg is None or msg.arbitration_id & 0x780 != 0x580:
            continue
        for event in host.receive(Frame(msg.arbitration_id, bytes(msg.data))):
            if isinstance(event, session.Send):
                bus.send(can.Message(arbitration_id=event.frame.can_id, data=event.frame.data,
                                     is_extended_id=False))
            elif isinstance(event, session.SdoDone):
                return event
    raise AssertionError("no reply")


@pytest.fixture
def hub_bus(drives):
    from deltoctl_canopen.hub import HubBus

    bus = HubBus(channel=drives.hub.channel)
    yield bus
    bus.shutdown()


def test_the_emulated_drive_serves_the_session(hub_bus):
    host = Host()
    name = over_hub(hub_bus, host, host.upload(2, 0x1008))
    assert name.data == b"deltoctl generic CiA 402 drive"  # segmented, 5 segments
    assert over_hub(hub_bus, host, host.download(3, 0x6081, 0, (1234).to_bytes(4, "little")))
    value = over_hub(hub_bus, host, host.upload(3, 0x6081))
    assert int.from_bytes(value.data, "little") == 1234
    with pytest.raises(DeviceFault) as caught:
        over_hub(hub_bus, host, host.download(2, 0x1000, 0, bytes(4)))
    assert caught.value.code == 0x06010002  # write of a read-only object
    with pytest.raises(DeviceFault) as caught:
        over_hub(hub_bus, host, host.download(2, 0x6081, 0, b"\x01"))
    assert caught.value.code == 0x06070010  # the length is not the type's
    with pytest.raises(DeviceFault) as caught:
        over_hub(hub_bus, host, host.upload(2, 0x5FFF))
    assert caught.value.code == 0x06020000


def test_the_emulated_drive_boots_up_after_a_reset(hub_bus):
    import time

    import can

    host = Host()
    hub_bus.send(can.Message(arbitration_id=0, data=session.nmt_frame(0x82, 3).data,
                             is_extended_id=False))
    end, seen = time.monotonic() + 5, []
    while time.monotonic() < end and not any(e.boot_up for e in seen):
        msg = hub_bus.recv(0.1)
        if msg is not None and msg.arbitration_id == 0x703:
            seen += host.receive(Frame(msg.arbitration_id, bytes(msg.data)))
    assert any(e.boot_up for e in seen)


def test_the_emulated_drive_answers_node_guarding(hub_bus):
    import time

    import can

    replies = []
    for _ in range(2):
        hub_bus.send(can.Message(arbitration_id=0x702, is_remote_frame=True, dlc=0,
                                 is_extended_id=False))
        end = time.monotonic() + 5
        while time.monotonic() < end:
            msg = hub_bus.recv(0.1)
            if msg is not None and msg.arbitration_id == 0x702 and msg.data[0] & 0x80 == \
                    len(replies) * 0x80:
                replies.append(msg.data[0])
                break
    assert replies == [0x7F, 0xFF]  # pre-operational, the toggle bit alternating


def test_a_master_abort_ends_the_nodes_transfer_unanswered():
    host, device, _ = pair()
    device.receive(host.upload(2, 0x1008))
    assert device.receive(host.cancel(2)) == []
    reply = device.receive(Frame(0x602, bytes.fromhex("6000000000000000")))[0].frame
    assert reply.data[0] == 0x80  # no transfer open: a segment request is refused
