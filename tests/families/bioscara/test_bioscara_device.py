"""The verbs on bioscara-arm, through the I2C transport, against the joint emulators (on a
loopback-served bus, as `deltoctl sim serve` shares it, or in-process with --sim)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from deltoctl.errors import Refused
from deltoctl.families.bioscara import codec
from deltoctl.families.bioscara.driver import BioscaraDriver
from deltoctl.profile.catalog import load_profile
from deltoctl.sim.i2c_bus import I2CSocketServer
from deltoctl.transport.i2c import I2CBus
from tests.conftest import block_for, block_of, joints_of, ros2_messages, sim_i2c_bus

J4 = 0x14
J4_MAX = 3.01069


@pytest.fixture
def arm():
    """A served bioscara-arm bus: ``(target, {address: firmware})``."""
    bus = sim_i2c_bus(load_profile("bioscara-arm"))
    server = I2CSocketServer(bus).start()
    yield server.url, bus.devices
    server.close()


def in_process_driver(profile, smbus):
    """The arm's driver on a simulated bus in this process (no socket in the way)."""
    from deltoctl.core.driver import Links

    url = "i2c:///dev/i2c-sim"
    links = Links()
    links.open[url] = I2CBus(smbus, url)
    return BioscaraDriver(block_for(profile, profile.hardware[0], url, links=links))


def run_json(cli, *args):
    result = cli("-p", "bioscara-arm", *args, "--json")
    assert result.exit_code == 0, result.stderr
    return json.loads(result.stdout)


def test_connect_identify_detect_stream_with_sim(cli):
    result = cli("-p", "bioscara-arm", "--sim", "connect")
    assert result.exit_code == 0
    # the result is data (stdout), even for people
    assert "round trip median" in result.stdout and "finalized" in result.stdout
    ident = block_of(run_json(cli, "--sim", "identify"))["identity"]
    assert ident["joints"]["j2"] == {"address": "0x12", "answers": True,
                                     "flags": "not homed, not enabled", "homed": False,
                                     "home_offset": None}
    detect = block_of(run_json(cli, "--sim", "detect"))["details"]
    assert detect["found"] == ["0x11", "0x12", "0x13", "0x14"] and detect["missing"] == []
    lines = cli("-p", "bioscara-arm", "--sim", "stream", "-d", "0.1", "-i", "j1/*")
    sample = json.loads(lines.stdout.splitlines()[0])["values"]
    assert sample == {"j1/position": 0.0, "j1/velocity": 0.0, "j1/home": 0.0, "j1/flags": 12.0}


def test_detect_draws_the_bus_and_names_a_missing_joint(cli, arm):
    target, devices = arm
    del devices[0x13]
    result = cli("-p", "bioscara-arm", "-t", target, "detect")
    assert result.exit_code == 1  # a joint the profile declares does not answer
    assert "10: -- 11 12 -- 14 --" in result.stdout
    assert "missing: j3" in result.stdout
    assert "j3 at 0x13  joint    no answer  NO" in result.stdout


def test_homing_in_the_profile_order_then_the_offset_survives(cli, arm):
    target, devices = arm
    result = cli("-p", "bioscara-arm", "-t", target, "home", "--yes", "-j", "j4", "-j", "j1")
    assert result.exit_code == 0, result.stderr
    assert result.stderr.index("j1: homed") < result.stderr.index("j4: homed")  # j2, j1, j4, j3
    assert devices[J4].home_offset == pytest.approx(J4_MAX)  # stored in the joint
    assert devices[J4].flags & codec.NOTENABLED  # left disabled: back-drivable
    # a new process reads the offset back from the joint: true positions at once
    values = json.loads(cli("-p", "bioscara-arm", "-t", target, "stream", "-d", "0.05",
                            "--json").stdout.splitlines()[0])["values"]
    assert values["j4/position"] == pytest.approx(J4_MAX) and values["j4/home"] == 1.0
    assert values["j2/home"] == 0.0
    again = run_json(cli, "-t", target, "home", "--yes", "-j", "j4")
    assert joints_of(again, "outcome") == {"j4": "already homed"}


def test_jog_is_refused_until_homed_then_moves(cli, arm):
    target, devices = arm
    refused = cli("-p", "bioscara-arm", "-t", target, "jog", "j4", "-0.2", "--yes")
    assert refused.exit_code == 5 and "j4 is not homed" in refused.stderr
    assert devices[J4].requests < 20 and devices[J4].target is None  # nothing was commanded
    assert cli("-p", "bioscara-arm", "-t", target, "home", "--yes", "-j", "j4").exit_code == 0
    moved = run_json(cli, "-t", target, "jog", "j4", "-0.2", "--yes")
    assert moved["result"]["settled"] and joints_of(moved, "position")["j4"] == pytest.approx(
        J4_MAX - 0.2, abs=1e-3)
    too_far = cli("-p", "bioscara-arm", "-t", target, "jog", "j4", "-0.6", "--yes")
    assert too_far.exit_code == 5  # the profile's max_jog_step


def test_a_stall_during_a_jog_is_reported_and_leaves_the_joint_disabled(cli, arm):
    target, devices = arm
    assert cli("-p", "bioscara-arm", "-t", target, "home", "--yes", "-j", "j4").exit_code == 0
    devices[J4].blocked = True
    result = cli("-p", "bioscara-arm", "-t", target, "jog", "j4", "-0.3", "--yes")
    assert result.exit_code == 1
    assert "j4 stalled" in result.stderr and "disabled" in result.stderr
    assert devices[J4].flags & codec.STALL and devices[J4].flags & codec.NOTENABLED


def test_ctrl_c_while_homing_sends_stop():
    profile = load_profile("bioscara-arm")
    bus = sim_i2c_bus(profile)
    driver = in_process_driver(profile, bus)
    driver.configure()

    def interrupt(name, status, fraction):
        if status == "homing":
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        driver.home(["j2"], progress=interrupt)
    j2 = bus.devices[0x12]
    assert j2.homing is None and not j2.flags & codec.BUSY
    assert j2.flags & codec.NOTHOMED and j2.flags & codec.NOTENABLED


def test_the_deadman_and_one_command_mode_per_joint():
    import time

    profile = load_profile("bioscara-arm")
    bus = sim_i2c_bus(profile)
    j1 = bus.devices[0x11]
    j1.flags &= ~codec.NOTHOMED  # as if homed, mid-range
    j1.angle = j1.command = 0.0
    driver = in_process_driver(profile, bus)
    driver.configure()
    with pytest.raises(Refused, match="j2 is not homed"):
        driver.set_command("j2/velocity", 0.01)
    driver.set_command("j1/velocity", 0.2)
    for _ in range(10):  # reads every 20 ms keep the deadman fed while it ramps up
        time.sleep(0.02)
        velocity = driver.read()["j1/velocity"]
    assert velocity == pytest.approx(0.2, rel=0.05)
    with pytest.raises(Refused, match="commanded through velocity"):
        driver.set_command("j1/position", 0.0)
    time.sleep(0.12)  # silence: the joint stops itself and disables
    values = driver.read()
    assert values["j1/velocity"] == 0.0 and int(values["j1/flags"]) & codec.NOTENABLED
    driver.stop()
    assert driver.joints["j1"].mode is None


def test_record_has_the_joint_flags(cli, tmp_path):
    out = tmp_path / "arm.mcap"
    assert cli("-p", "bioscara-arm", "--sim", "record", str(out), "-d", "0.2").exit_code == 0
    dyn = [m for _, m in ros2_messages(out, ["/dynamic_joint_states"])]
    assert dyn and dyn[0].joint_names == ["j1", "j2", "j3", "j4"]
    j1 = dyn[0].interface_values[0]
    assert j1.interface_names == ["position", "velocity", "home", "flags"]
    assert j1.values[3] == codec.NOTHOMED | codec.NOTENABLED


def test_sim_serve_in_its_own_process():
    proc = subprocess.Popen([sys.executable, "-m", "deltoctl", "sim", "serve", "bioscara-arm",
                             "--json", "--missing", "j2"], stdout=subprocess.PIPE, text=True)
    try:
        target = json.loads(proc.stdout.readline())["buses"]["i2c"]
        assert target.startswith("i2c+tcp://127.0.0.1:")
        result = subprocess.run([sys.executable, "-m", "deltoctl", "-p", "bioscara-arm", "-t",
                                 target, "detect", "--json"], capture_output=True, text=True)
        assert result.returncode == 1  # j2 does not answer
        assert block_of(json.loads(result.stdout))["details"]["missing"] == ["j2"]
    finally:
        proc.terminate()
        assert proc.wait(timeout=5) == 0


def test_detect_still_draws_a_bus_where_no_joint_answers(cli, arm):
    target, devices = arm
    devices.clear()
    assert cli("-p", "bioscara-arm", "-t", target, "identify").exit_code == 4
    result = cli("-p", "bioscara-arm", "-t", target, "detect", "--json")
    assert result.exit_code == 1, result.stderr  # no joint answers
    report = block_of(json.loads(result.stdout))["details"]
    assert report["found"] == [] and report["missing"] == ["j1", "j2", "j3", "j4"]


def test_a_limit_past_a_32_bit_float_is_one_clear_error(cli, tmp_path):
    """max_velocity: 1e40 is finite (the profile takes it) but no joint register holds it."""
    from deltoctl.profile.catalog import resolve

    text = resolve("bioscara-arm").read_text()
    assert "max_velocity: 1.0}" in text
    path = tmp_path / "wide.yaml"
    path.write_text(text.replace("max_velocity: 1.0}", "max_velocity: 1e40}", 1))
    result = cli("-p", str(path), "--sim", "home", "-j", "j1", "--yes")
    assert result.exit_code == 2, result.output
    assert "max_velocity 1e+40: the joint takes a 32-bit float" in result.stderr
    assert "internal error" not in result.stderr


def test_set_safe_stops_a_homing_another_process_started(arm):
    """Setting the blocks safe (what the fleet's agent does after killing a motion verb)
    sends STOP to every joint, though this session commanded none."""
    from deltoctl.core.system import System

    target, joints = arm
    fw = joints[J4]
    fw.angle = fw.command = sum(fw.stops) / 2  # far from either hard stop: a long homing
    fw.write(codec.setup(20, 20))
    fw.read(1)
    fw.write(codec.home(1.0, 30, 15))  # a homing the killed process left running
    assert fw.read(1)[0] & codec.BUSY
    with System(load_profile("bioscara-arm"), [target]) as system:
        system.stop()  # its own stop: it commanded nothing, so it sends nothing
        assert fw.flags & codec.BUSY
        system.make_safe()
        assert not fw.flags & codec.BUSY
