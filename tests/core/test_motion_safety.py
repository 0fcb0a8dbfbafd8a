"""Every way out of a move leaves the device safe — Ctrl-C, SIGTERM, SIGHUP (a closed terminal
or SSH session) — for the Delto, Dynamixel and Bioscara families, checked against the
emulator's own state; and a Delto move that loses its link stops and does not resume."""

from __future__ import annotations

import math
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from deltoctl.profile.catalog import load_profile
from tests.conftest import eventually

DELTOCTL = Path(sys.executable).parent / "deltoctl"
SIGNALS = [signal.SIGINT, signal.SIGTERM, signal.SIGHUP]
pytestmark = pytest.mark.skipif(not DELTOCTL.exists(), reason="deltoctl is not installed")


def _moving(args: list[str], started, env: dict | None = None) -> subprocess.Popen:
    """A deltoctl move in a process of its own, once the device shows it moving."""
    proc = subprocess.Popen([str(DELTOCTL), "--yes", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)
    if not eventually(started, timeout=10):
        proc.kill()
        pytest.fail(f"never started moving: {proc.communicate()[1]}")
    return proc


def _safe_after(proc: subprocess.Popen, sig: int, safe) -> float:
    """Send ``sig``; seconds until the emulator is in its safe state."""
    sent = time.monotonic()
    proc.send_signal(sig)
    while not safe():  # polled every 0.5 ms: the figure is the device's, not the poll's
        assert time.monotonic() - sent < 2, "the device was not left safe"
        time.sleep(0.0005)
    seconds = time.monotonic() - sent
    print(f"{signal.Signals(sig).name}: safe after {seconds * 1e3:.1f} ms")  # for the figures
    _, err = proc.communicate(timeout=10)
    assert proc.returncode == 130, err  # interrupted, cleanly
    assert "Traceback" not in err
    return seconds


@pytest.mark.parametrize("sig", SIGNALS)
def test_a_delto_move_stops_at_duty_zero(sig):
    from deltoctl.families.delto.emulator import DeltoServer, firmware_for_profile

    firmware = firmware_for_profile(load_profile("dg-5f-right"))
    with DeltoServer(firmware) as server:
        proc = _moving(["-p", "dg-5f-right", "-t", server.endpoint, "jog", "rj_dg_2_2",
                        "--to", "0.5", "--velocity", "0.02"],
                       lambda: any(firmware.duty))
        assert _safe_after(proc, sig, lambda: not any(firmware.duty)) < 1.0


@pytest.mark.parametrize("sig", SIGNALS)
def test_a_dynamixel_move_stops_where_it_is(sig):
    from deltoctl.families.dynamixel.emulator import DynamixelBus, DynamixelPtyServer, Servo

    hw = next(h for h in load_profile("mh5").hardware if h.name == "upper_body")
    servos = {j.address: Servo(j.address) for j in hw.joints}
    head = servos[next(j.address for j in hw.joints if j.name == "head_y")]
    with DynamixelPtyServer(DynamixelBus(list(servos.values()))) as server:
        start = head.get("Present Position")
        proc = _moving(["-p", "mh5", "--hardware", "upper_body", "-t",
                        f"upper_body=serial://{server.port}?baud=2000000", "jog", "head_y",
                        "--to", "0.3", "--velocity", "0.03"],
                       lambda: head.get("Present Position") != start)

        def stopped() -> bool:
            return abs(head.get("Goal Position") - head.get("Present Position")) <= 2

        assert _safe_after(proc, sig, stopped) < 1.0
        here = head.get("Present Position")
        time.sleep(0.3)
        assert abs(head.get("Present Position") - here) <= 2  # and it stays there
        assert abs(here - (0.3 / 0.001533980787886 + 2047)) > 20  # short of the goal


@pytest.mark.parametrize("sig", SIGNALS)
def test_a_bioscara_homing_stops_and_disables(sig):
    from deltoctl.families.bioscara.codec import BUSY, NOTENABLED
    from deltoctl.families.bioscara.emulator import joints_for_block
    from deltoctl.sim.i2c_bus import I2CSocketServer, SimSMBus

    hw = load_profile("bioscara-arm").hardware[0]
    joints = joints_for_block(hw, park=30.0)  # far from its stop: homing takes a while
    j2 = joints[0x12]
    with I2CSocketServer(SimSMBus(joints)) as server:
        proc = _moving(["-p", "bioscara-arm", "-t", server.url, "home", "-j", "j2"],
                       lambda: j2.homing is not None)

        def safe() -> bool:
            return j2.homing is None and not j2.flags & BUSY and bool(j2.flags & NOTENABLED)

        assert _safe_after(proc, sig, safe) < 1.0


def test_a_delto_move_that_loses_its_link_stops_and_does_not_resume():
    from deltoctl.families.delto.emulator import DeltoServer, firmware_for_profile

    firmware = firmware_for_profile(load_profile("dg-5f-right"))
    with DeltoServer(firmware) as server:
        proc = _moving(["-p", "dg-5f-right", "-t", server.endpoint, "jog", "rj_dg_2_2",
                        "--to", "0.5", "--velocity", "0.02"],
                       lambda: any(firmware.duty))
        server.drop_connections()  # the cable is pulled for a moment; the gripper stays up
        _, err = proc.communicate(timeout=15)
        assert proc.returncode == 1, err
        assert "does not resume" in err and "Traceback" not in err
        assert eventually(lambda: not any(firmware.duty), timeout=3)
        assert not math.isnan(firmware.position[5])

