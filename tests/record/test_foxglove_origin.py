"""The live view lets in Foxglove and programs, not any web page: a browser opens a WebSocket
to loopback from any page, saying which in the handshake's Origin. A real client (websockets)
on loopback, against `stream --foxglove` on the simulated cell."""

from __future__ import annotations

import asyncio
import json
import socket
from urllib.parse import urlsplit

import pytest

from tests.record.test_foxglove import SUBPROTOCOLS, WAIT, _start, _stop, decode

websockets = pytest.importorskip("websockets")
pytest.importorskip("foxglove")

STREAM = ("stream", "--foxglove", "--foxglove-port", "0", "--duration", "300", "--json",
          "--rate", "50")


async def _joint_states(url: str, origin: str | None) -> list[str]:
    """Subscribe to /joint_states with this Origin (None: none sent); the joint names of
    the first message."""
    async with websockets.connect(url, origin=origin, subprotocols=SUBPROTOCOLS,
                                  max_size=None, open_timeout=WAIT) as ws:
        channel = None
        while channel is None:
            msg = await ws.recv()
            if isinstance(msg, str) and json.loads(msg)["op"] == "advertise":
                channel = next((c for c in json.loads(msg)["channels"]
                                if c["topic"] == "/joint_states"), None)
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": 1, "channelId": channel["id"]}]}))
        while True:
            msg = await ws.recv()
            if isinstance(msg, bytes) and msg[0] == 1:
                return list(decode(channel, msg[13:]).name)


async def _refused(url: str, origin: str) -> int:
    """The HTTP status of a handshake with this Origin, which must fail."""
    with pytest.raises(websockets.InvalidStatus) as caught:
        async with websockets.connect(url, origin=origin, subprotocols=SUBPROTOCOLS,
                                      open_timeout=WAIT):
            pass
    return caught.value.response.status_code


def _run(coroutine):  # type: ignore[no-untyped-def]
    return asyncio.run(asyncio.wait_for(coroutine, WAIT))


def test_a_foreign_page_is_refused_foxglove_and_programs_are_served():
    proc, url, _, err = _start(*STREAM)
    try:
        assert _run(_refused(url, "http://evil.example")) == 403
        assert _run(_refused(url, "null")) == 403  # a sandboxed frame of any page
        for origin in (None, "https://app.foxglove.dev", "file://"):  # program, web, desktop
            names = _run(_joint_states(url, origin))
            assert names[:4] == ["j1", "j2", "j3", "j4"], origin
    finally:
        code = _stop(proc)
    assert code == 0, "".join(err)
    assert "2 connection(s) refused for their origin" in "".join(err)


def test_an_origin_named_by_the_user_is_let_in():
    proc, url, _, err = _start(*STREAM, "--foxglove-origin", "http://localhost:8080/")
    try:
        assert _run(_joint_states(url, "http://localhost:8080"))[:1] == ["j1"]
        assert _run(_joint_states(url, "https://app.foxglove.dev"))[:1] == ["j1"]
        assert _run(_refused(url, "http://localhost:8081")) == 403
    finally:
        assert _stop(proc) == 0, "".join(err)


def _raw_handshake(url: str, headers: str) -> bytes:
    """A hand-written handshake; everything the server answered until it closed."""
    parts = urlsplit(url)
    with socket.create_connection((parts.hostname, parts.port), timeout=WAIT) as sock:
        sock.sendall(("GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                      "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n"
                      "Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n" + headers + "\r\n").encode())
        answer = b""
        while chunk := sock.recv(65536):
            answer += chunk
        return answer


def test_a_handshake_that_hides_its_origin_is_refused():
    proc, url, _, err = _start(*STREAM)
    try:
        two = _raw_handshake(url, "Origin: https://app.foxglove.dev\r\n"
                                  "origin: http://evil.example\r\n")
        assert two.startswith(b"HTTP/1.1 403") and b"advertise" not in two
        cased = _raw_handshake(url, "ORIGIN: HTTP://EVIL.EXAMPLE\r\n")
        assert cased.startswith(b"HTTP/1.1 403") and b"evil.example" in cased
        huge = _raw_handshake(url, "X-Pad: " + "a" * 20_000 + "\r\n")
        assert huge.startswith(b"HTTP/1.1 400")
    finally:
        assert _stop(proc) == 0, "".join(err)


@pytest.mark.parametrize("origin", ["https://app.foxglove.dev/path", "app.foxglove.dev",
                                    "https://", "https://x:port"])
def test_an_origin_that_is_no_origin_is_a_usage_error(cli, origin):
    result = cli("-p", "bioscara-dg-3f-m", "--sim", "stream", "--foxglove", "--foxglove-port",
                 "0", "--duration", "1", "--foxglove-origin", origin)
    assert result.exit_code == 2, (result.stderr, result.exception)
    assert f"--foxglove-origin {origin!r}: expected an origin" in result.stderr
