from __future__ import annotations

import contextlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from deltoctl.cli.main import app
from typer.testing import CliRunner

from deltoctl_canopen.nodes import GENERIC_EDS, PROFILES

PROFILE = PROFILES / "cia402-two-axis.yaml"
BUS = PROFILES / "cia402-two-axis.bus.yml"
DELTOCTL = [sys.executable, "-m", "deltoctl"]


@pytest.fixture
def cli():
    """deltoctl in-process; the click Result (stdout and stderr apart)."""
    runner = CliRunner()

    def run(*args: str, **kwargs):
        return runner.invoke(app, [str(a) for a in args], **kwargs)

    return run


@pytest.fixture
def served():
    """``deltoctl sim serve PROFILE --json [faults]`` in a process of its own: returns the
    bus URL (the drives answer from another process, on the local hub)."""
    procs = []

    def start(*faults: str, profile: Path = PROFILE) -> str:
        proc = subprocess.Popen([*DELTOCTL, "sim", "serve", str(profile), "--json", *faults],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                env={**os.environ, "PYTHONUNBUFFERED": "1"})
        procs.append(proc)
        line = proc.stdout.readline()
        if not line:
            raise AssertionError(f"sim serve failed: {proc.stderr.read()}")
        return json.loads(line)["endpoint"]

    yield start
    for proc in procs:
        proc.terminate()
        with contextlib.suppress(subprocess.TimeoutExpired):
            proc.wait(5)


@pytest.fixture
def drives():
    """Two generic drives (nodes 2, 3) on a local hub in this process."""
    from deltoctl_canopen.emulator import NodeFaults, start_bus

    bus = start_bus({2: (GENERIC_EDS, NodeFaults()), 3: (GENERIC_EDS, NodeFaults())})
    yield bus
    bus.close()


@pytest.fixture
def client(drives):
    """canopen's own client on the drives' hub."""
    import canopen

    from deltoctl_canopen.hub import HubBus

    network = canopen.Network(HubBus(channel=drives.hub.channel))
    network.connect()
    yield network
    network.disconnect()


@pytest.fixture
def variant(tmp_path):
    """The two-axis profile written anew beside its bus file and EDS, each text changed by
    ``profile`` and ``bus`` (functions of the shipped text)."""

    def make(profile=lambda text: text, bus=lambda text: text) -> Path:
        shutil.copy(GENERIC_EDS, tmp_path)
        (tmp_path / BUS.name).write_text(bus(BUS.read_text()))
        out = tmp_path / PROFILE.name
        out.write_text(profile(PROFILE.read_text()))
        return out

    return make
