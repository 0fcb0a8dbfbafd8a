"""The TCP link moves bytes and knows no protocol: what arrives, as it arrives; nothing within
the timeout; a closed connection as LinkLost (the one of deltoctl.errors)."""

from __future__ import annotations

import socket

import pytest

from deltoctl import errors
from deltoctl.transport.tcp import TRANSPORT, LinkLost, TcpLink, parse_tcp_url, tcp_transport


def test_bytes_as_they_arrive_nothing_within_the_timeout_and_a_closed_peer():
    with socket.create_server(("127.0.0.1", 0)) as server:
        link = TcpLink("127.0.0.1", server.getsockname()[1])
        peer, _ = server.accept()
        buffer = bytearray(16)
        assert link.recv_into(buffer, 0.05) == 0  # nothing yet: 0, not an error
        peer.sendall(b"\x00\x01\x02")  # no frame of any protocol: bytes all the same
        assert link.recv_into(buffer, 5.0) == 3 and buffer[:3] == b"\x00\x01\x02"
        link.send(b"ping")
        assert peer.recv(16) == b"ping"
        peer.close()
        with pytest.raises(LinkLost, match="closed the connection"):
            link.recv_into(buffer, 5.0)
        link.close()
    assert LinkLost is errors.LinkLost


def test_a_url_without_a_port_takes_the_callers_default():
    assert parse_tcp_url("tcp://gripper", 1502) == ("gripper", 1502)
    assert tcp_transport(7).parse("tcp://gripper") == ("gripper", 7)
    assert TRANSPORT.parse("tcp://gripper:9") == ("gripper", 9)
    with pytest.raises(errors.InvalidInput, match="no port"):
        tcp_transport().parse("tcp://gripper")
