"""The LSS slave (CiA 305) of the node's session against canopen's own LssMaster, with no
transport: each request the master sends goes through the slaves' ``receive`` at once, their
replies (one frame when several send the same) back into the master's queue."""

import pytest
from canopen.lss import LssError, LssMaster

from deltoctl_canopen.codec import Frame
from deltoctl_canopen.session import (
    LSS_CONFIGURATION,
    LSS_WAITING,
    UNCONFIGURED,
    LssBitRate,
    LssSlave,
    LssStart,
    Send,
)

VENDOR, PRODUCT, REVISION = 0xDE7, 0x40201, 0x10002


class Wire:
    """A bus between canopen's LssMaster and LSS slaves."""

    def __init__(self, *slaves: LssSlave) -> None:
        self.slaves = list(slaves)
        self.events: list = []
        self.master = LssMaster()
        self.master.RESPONSE_TIMEOUT = 0.001  # replies are in the queue before it waits
        self.master.network = self

    def send_message(self, can_id: int, data: bytes) -> None:
        replies = []
        for slave in self.slaves:
            for event in slave.receive(Frame(can_id, bytes(data))):
                if isinstance(event, Send):
                    if event.frame not in replies:
                        replies.append(event.frame)
                else:
                    self.events.append(event)
        for frame in replies:
            self.master.on_message_received(frame.can_id, frame.data, 0.0)


def slave(serial: int, node: int = UNCONFIGURED) -> LssSlave:
    return LssSlave((VENDOR, PRODUCT, REVISION, serial), node)


@pytest.fixture(autouse=True)
def no_waits(monkeypatch):
    """canopen's fast scan and selective switch sleep between messages, for slow devices."""
    import canopen.lss

    monkeypatch.setattr(canopen.lss.time, "sleep", lambda s: None)


def test_fast_scan_finds_each_unconfigured_node_lowest_first():
    wire = Wire(slave(0x00C0FFEE), slave(0x0000BEEF), slave(0x1, node=5))
    found = []
    while True:
        ok, identity = wire.master.fast_scan()
        if not ok:
            break
        found.append(identity)
    # the configured node (serial 1, lowest of all) is never a candidate
    assert found == [[VENDOR, PRODUCT, REVISION, 0xBEEF], [VENDOR, PRODUCT, REVISION, 0xC0FFEE]]
    assert [s.state for s in wire.slaves] == [LSS_CONFIGURATION, LSS_CONFIGURATION, LSS_WAITING]
    wire.master.send_switch_state_global(LSS_WAITING)
    assert {s.state for s in wire.slaves} == {LSS_WAITING} and not wire.events


def test_selective_switch_configure_store_then_the_node_starts():
    chosen, other = slave(0xBEEF), slave(0xC0FFEE)
    wire = Wire(chosen, other)
    assert wire.master.send_switch_state_selective(VENDOR, PRODUCT, REVISION, 0xBEEF)
    assert (chosen.state, other.state) == (LSS_CONFIGURATION, LSS_WAITING)
    assert wire.master.inquire_node_id() == UNCONFIGURED
    wire.master.configure_node_id(5)
    wire.master.configure_bit_timing(2)
    assert chosen.stored == UNCONFIGURED
    wire.master.store_configuration()
    assert (chosen.stored, chosen.stored_bit_timing, chosen.node) == (5, 2, UNCONFIGURED)
    wire.master.send_switch_state_global(LSS_WAITING)
    assert wire.events == [LssStart(5)] and chosen.node == 5 and other.pending == UNCONFIGURED


def test_a_selective_switch_to_an_address_nobody_has_gets_no_answer():
    wire = Wire(slave(0xBEEF))
    with pytest.raises(LssError, match="No LSS response"):
        wire.master.send_switch_state_selective(VENDOR, PRODUCT, REVISION, 0xBEEE)
    assert wire.slaves[0].state == LSS_WAITING


def test_configuration_answers_only_in_the_configuration_state_and_refuses_bad_values():
    node = slave(0xBEEF, node=7)
    wire = Wire(node)
    with pytest.raises(LssError, match="No LSS response"):
        wire.master.configure_node_id(9)  # waiting: the node ignores it
    wire.master.send_switch_state_global(LSS_CONFIGURATION)
    with pytest.raises(LssError, match="LSS Error: 1"):
        wire.master.configure_node_id(0)
    with pytest.raises(LssError, match="LSS Error: 1"):
        wire.master.configure_bit_timing(9)
    assert (node.pending, node.pending_bit_timing) == (7, 0)
    wire.master.configure_node_id(9)
    wire.master.send_switch_state_global(LSS_WAITING)
    assert node.node == 7 and not wire.events  # a configured node: the new ID at its reset
    assert node.reset_communication() == 9


def test_inquire_identity_and_activate_bit_timing():
    node = slave(0xBEEF, node=7)
    wire = Wire(node)
    wire.master.send_switch_state_global(LSS_CONFIGURATION)
    assert [wire.master.inquire_lss_address(cs) for cs in (0x5A, 0x5B, 0x5C, 0x5D)] == \
        [VENDOR, PRODUCT, REVISION, 0xBEEF]
    assert wire.master.inquire_node_id() == 7
    wire.master.configure_bit_timing(3)
    wire.master.activate_bit_timing(50)
    assert wire.events == [LssBitRate(250_000, 50)] and node.bit_timing == 3


def test_identify_remote_slave_and_non_configured():
    wire = Wire(slave(0xBEEF), slave(0xC0FFEE, node=4))
    wire.master.send_identify_remote_slave(VENDOR, PRODUCT, 0, 0xFFFFFFFF, 0xC0000, 0xD00000)
    assert wire.master.responses.get_nowait()[0] == 0x4F  # the node of serial 0xC0FFEE
    assert wire.master.responses.empty()
    wire.master.send_identify_non_configured_remote_slave()
    assert wire.master.responses.get_nowait()[0] == 0x50  # the one without a node ID
    assert wire.master.responses.empty()


def test_frames_that_are_no_lss_request_are_ignored():
    node = slave(0xBEEF)
    assert node.receive(Frame(0x7E5, b"\x04\x01")) == []  # short
    assert node.receive(Frame(0x7E4, b"\x04\x01" + bytes(6))) == []  # a slave's reply
    assert node.receive(Frame(0x7E5, b"\x04\x01" + bytes(6), remote=True)) == []
    assert node.receive(Frame(0x7E5, b"\x51" + bytes(4) + b"\x40\x00\x00")) == []  # bit 64
    assert node.state == LSS_WAITING
    with pytest.raises(ValueError):
        LssSlave((1, 2, 3, 4), node=0)
