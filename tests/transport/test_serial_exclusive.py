"""Serial ports are opened exclusively: a second opener gets a busy port named (exit 4)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from deltoctl.errors import UNREACHABLE, Unreachable
from deltoctl.transport.serial_port import open_serial
from tests.conftest import REPO

HOLD = textwrap.dedent("""
    import sys, time
    from deltoctl.transport.serial_port import open_serial
    port = open_serial(sys.argv[1])
    print("holding", flush=True)
    time.sleep(60)
""")


@pytest.fixture
def pty():
    """A pseudo-terminal's device path (the test keeps only its master end)."""
    master, slave = os.openpty()
    path = os.ttyname(slave)
    os.close(slave)
    yield path
    os.close(master)


@pytest.fixture
def held(pty):
    """The pty opened by another process with deltoctl's open_serial; yields (url, pid)."""
    url = f"serial://{pty}?baud=2000000"
    proc = subprocess.Popen([sys.executable, "-c", HOLD, url], cwd=REPO, stdout=subprocess.PIPE,
                            text=True)
    try:
        assert proc.stdout.readline().strip() == "holding"
        yield url, proc.pid
    finally:
        proc.kill()
        proc.wait(timeout=5)


def test_a_second_open_in_the_same_process_is_refused(pty):
    url = f"serial://{pty}?baud=1000000"
    first = open_serial(url)
    try:
        with pytest.raises(Unreachable) as caught:
            open_serial(url)
        assert caught.value.exit_code == UNREACHABLE
        assert caught.value.message.startswith(f"{pty} is busy: open in this deltoctl (pid {os.getpid()})")
        assert f"fuser -v {pty}" in caught.value.hint
    finally:
        first.close()
    open_serial(url).close()  # free again once closed


def test_a_port_held_by_another_process_names_it(held):
    url, pid = held
    with pytest.raises(Unreachable) as caught:
        open_serial(url)
    message = caught.value.message
    assert "is busy" in message and f"(pid {pid})" in message
    assert "python" in message  # the holder's command name


def test_a_verb_on_a_busy_bus_exits_4_naming_the_port(cli, held):
    url, pid = held
    result = cli("-p", "mh5", "--hardware", "upper_body", "-t", f"upper_body={url}", "connect")
    assert result.exit_code == 4, result.stderr
    port = url.removeprefix("serial://").partition("?")[0]
    assert f"{port} is busy" in result.stderr and f"pid {pid}" in result.stderr
    assert "Traceback" not in result.stderr
