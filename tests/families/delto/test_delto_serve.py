"""sim serve answers every Delto block of a process from one thread (DeltoHub), through real
loopback sockets: each block's gripper, its faults, a bad frame and a pulled cable."""

from __future__ import annotations

import contextlib
import threading

import pytest

from deltoctl.core.system import System
from deltoctl.families.delto import codec
from deltoctl.families.delto.driver import receive
from deltoctl.families.delto.emulator import DeltoHub, DeltoServer, firmware_for_profile
from deltoctl.families.delto.session import Role, Session
from deltoctl.profile.catalog import load_profile
from deltoctl.sim.serve import ServeOptions, serve_profile
from deltoctl.transport.tcp import LinkLost, TcpLink, parse_tcp_url


class _Host:
    """A link to a gripper and the host's side of its session, as the driver holds them."""

    def __init__(self, server: DeltoServer) -> None:
        self.link = TcpLink(*parse_tcp_url(server.endpoint))
        self.session = Session(Role.HOST)

    def send(self, frame: bytes) -> None:
        self.link.send(self.session.send(frame))

    def recv_frame(self, timeout: float) -> bytes:
        return receive(self.link, self.session, timeout).frame

    def close(self) -> None:
        self.link.close()


def _link(server: DeltoServer) -> _Host:
    return _Host(server)


def _data_request(firmware) -> bytes:
    return codec.encode_data_request(codec.data_codes(firmware.model, True, True))


@pytest.fixture
def hub():
    """A hub and the grippers it serves (closed in turn)."""
    with contextlib.ExitStack() as stack:
        shared = DeltoHub()
        stack.callback(shared.close)

        def serve(name: str = "dg-5f-right", **options) -> DeltoServer:
            firmware = firmware_for_profile(load_profile(name), **options)
            return stack.enter_context(DeltoServer(firmware, hub=shared))

        yield serve


def test_sim_serve_answers_every_block_from_one_thread():
    prof = load_profile("dg-5f-bimanual")
    with contextlib.ExitStack() as stack:
        served = serve_profile(stack, prof, ServeOptions())
        targets = [f"{bus}={url}" for bus, url in served["buses"].items()]
        with System(prof, targets) as system:
            for _ in range(20):
                values = system.read()
            assert values["system/connection_status"] == 1.0
            assert len(system.members) == 2 and system.stats["errors"] == 0
            threads = threading.enumerate()
            assert [t.name for t in threads].count("delto-sim-hub") == 1
            assert not [t for t in threads if "process_request_thread" in t.name]


def test_a_delayed_reply_holds_no_other_gripper(hub):
    slow, quick = hub(), hub()
    slow.firmware.faults.delay = 3.0
    late, prompt = _link(slow), _link(quick)
    late.send(_data_request(slow.firmware))
    prompt.send(_data_request(quick.firmware))
    assert prompt.recv_frame(2.5)[2] == codec.GET_DATA  # while the slow one waits
    assert late.recv_frame(10.0)[2] == codec.GET_DATA  # then its reply, late
    late.close()
    prompt.close()


def test_a_bad_frame_closes_that_connection_only(hub):
    bad, good = hub(), hub()
    broken, working = _link(bad), _link(good)
    broken.send(b"\x00\x01\x02")  # a frame length of 1
    with pytest.raises(LinkLost, match="closed the connection"):
        broken.recv_frame(5.0)
    working.send(_data_request(good.firmware))
    assert working.recv_frame(5.0)[2] == codec.GET_DATA
    working.close()


def test_a_pulled_cable_closes_its_connections_and_the_gripper_takes_new_ones(hub):
    server = hub()
    link = _link(server)
    link.send(codec.encode_version_request())
    assert codec.decode_version_reply(link.recv_frame(5.0)).model_id == server.firmware.model.id
    server.drop_connections()
    with pytest.raises(LinkLost):
        link.send(_data_request(server.firmware))
        link.recv_frame(5.0)
    again = _link(server)
    again.send(_data_request(server.firmware))
    assert again.recv_frame(5.0)[2] == codec.GET_DATA
    again.close()
