from __future__ import annotations

import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from deltoctl.cli.main import app

REPO = Path(__file__).resolve().parent.parent
SHARED = REPO.parent / "shared"
SAMPLES = SHARED / "data" / "urdf"


@pytest.fixture
def cli():
    """Run deltoctl in-process; returns the click Result (stdout and stderr apart)."""
    runner = CliRunner()

    def run(*args: str, **kwargs):
        return runner.invoke(app, list(args), **kwargs)

    return run


def eventually(predicate, timeout: float = 2.0) -> bool:
    """For writes without a reply: true once an emulator thread has applied them."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


@pytest.fixture
def mh5_buses():
    """The MH5's two Dynamixel buses on ptys and its I2C bus (the IMU) on loopback."""
    from deltoctl.profile.catalog import load_profile
    from deltoctl.families.dynamixel.emulator import DynamixelBus, DynamixelPtyServer, Servo
    from deltoctl.sim.i2c_bus import I2CSocketServer, bus_for_profile

    profile = load_profile("mh5")
    servers = {}
    for hw in profile.hardware:
        if profile.family_of(hw) == "dynamixel":
            bus = DynamixelBus([Servo(j.address) for j in hw.joints])
            servers[hw.bus] = DynamixelPtyServer(bus).start()
    servers["i2c"] = I2CSocketServer(bus_for_profile(profile)).start()  # the IMU
    yield servers
    for server in servers.values():
        server.close()


def ros2_messages(path, topics=None):
    """(topic, decoded ROS 2 message) for each message of an MCAP file, in log order."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, channel, _, msg in reader.iter_decoded_messages(topics=topics):
            yield channel.topic, msg


def mh5_targets(servers):
    return [a for bus, s in servers.items()
            for a in ("-t", f"{bus}={s.url}" if bus == "i2c" else
                      f"{bus}=serial://{s.port}?baud=2000000")]


needs_samples = pytest.mark.skipif(not SAMPLES.is_dir(), reason="../shared/data is not present")


@pytest.fixture(autouse=True)
def _private_cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path_factory.mktemp("cache")))
