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
    from deltoctl.families.dynamixel.emulator import DynamixelBus, DynamixelPtyServer, Servo
    from deltoctl.profile.catalog import load_profile
    from deltoctl.sim.i2c_bus import I2CSocketServer

    profile = load_profile("mh5")
    servers = {}
    for hw in profile.hardware:
        if profile.family_of(hw) == "dynamixel":
            bus = DynamixelBus([Servo(j.address) for j in hw.joints])
            servers[hw.bus] = DynamixelPtyServer(bus).start()
    servers["i2c"] = I2CSocketServer(sim_i2c_bus(profile)).start()  # the IMU
    yield servers
    for server in servers.values():
        server.close()


def block_of(report, name=None):
    """The entry of block ``name`` (the only one when None) in a verb's ``blocks`` list."""
    blocks = report["blocks"]
    if name is None:
        assert len(blocks) == 1, [b["name"] for b in blocks]
        return blocks[0]
    found = [b for b in blocks if b["name"] == name]
    assert len(found) == 1, [b["name"] for b in blocks]
    return found[0]


def joints_of(report, key):
    """``{joint: entry[key]}`` over every block of a home or jog report (``position``,
    ``outcome`` of a homing routine, ``settled``, ``target``)."""
    found = {}
    for block in report["blocks"]:
        for joint, entry in block["joints"].items():
            assert joint not in found, joint  # a joint belongs to one block
            found[joint] = entry[key]
    return found


def block_for(profile, hw, url="", **kwargs):
    """What a driver is built from (``DriverClass(block_for(profile, hw, url))``), as the
    System builds it; ``links`` (a ``Links``) to hand the driver a transport already open."""
    from deltoctl import registry
    from deltoctl.core.driver import Block

    family = registry.of_block(profile.family_of(hw), hw.plugin)
    assert family is not None, hw.name
    return Block(profile, hw, family, url, **kwargs)


def sim_i2c_bus(profile):
    """Every I2C device of the profile on one simulated bus: each Bioscara block's joints and
    an LSM6DS3 chip at each IMU sensor's address (what `sim serve` puts on the bus)."""
    from deltoctl import registry
    from deltoctl.families.bioscara.emulator import joints_for_block
    from deltoctl.families.lsm6ds3.emulator import Lsm6ds3Chip
    from deltoctl.sim.i2c_bus import SimSMBus

    sim = SimSMBus({})
    for hw in profile.hardware:
        family = getattr(registry.of_block(profile.family_of(hw), hw.plugin), "name", None)
        if family == "bioscara":
            sim.devices.update(joints_for_block(hw))
        elif family == "lsm6ds3":
            sim.devices.update({s.address: Lsm6ds3Chip() for s in hw.sensors
                                if s.address is not None})
    return sim


def record_with_a_dropped_link(cli, out):
    """`record` of a simulated DG-5F-R whose connections are cut once, 0.3 s into the
    recording (the gripper stays up, so the link comes back); the CLI's result."""
    import threading

    from deltoctl.families.delto.emulator import DeltoServer, firmware_for_profile
    from deltoctl.profile.catalog import load_profile

    with DeltoServer(firmware_for_profile(load_profile("dg-5f-right"))) as server:
        def drop_once_recording() -> None:
            if eventually(lambda: out.exists() and out.stat().st_size > 0, timeout=15):
                time.sleep(0.3)
                server.drop_connections()

        dropper = threading.Thread(target=drop_once_recording)
        dropper.start()
        result = cli("-p", "dg-5f-right", "-t", server.endpoint, "record", str(out),
                     "--duration", "3", "--rate", "50")
        dropper.join()
    return result


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
    # --sim finds no 'sim serve' of the user's, only those a test starts
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path_factory.mktemp("run")))
