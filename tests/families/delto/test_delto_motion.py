"""home and jog on the emulator: limits, confirmation, settling, Ctrl-C leaves duty 0."""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from deltoctl.families.delto.emulator import DeltoServer, firmware_for_profile
from deltoctl.profile.catalog import load_profile
from tests.conftest import joints_of


@pytest.fixture
def server():
    with DeltoServer(firmware_for_profile(load_profile("dg-5f-right"))) as srv:
        yield srv


def test_jog_moves_the_joint(cli, server):
    target = ("-p", "dg-5f-right", "-t", server.endpoint)
    result = cli(*target, "jog", "rj_dg_2_2", "15deg", "--yes", "--json")
    assert result.exit_code == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["result"]["settled"] is True
    assert joints_of(report, "position")["rj_dg_2_2"] == pytest.approx(math.radians(15),
                                                                      abs=math.radians(2))
    assert server.firmware.position[5] == pytest.approx(math.radians(15), abs=math.radians(2))
    result = cli(*target, "jog", "rj_dg_2_2", "-5deg", "--yes", "--json")  # negative, relative
    assert joints_of(json.loads(result.stdout), "position")["rj_dg_2_2"] == pytest.approx(
        math.radians(10), abs=math.radians(2))
    result = cli(*target, "jog", "rj_dg_2_2", "--to", "0.05", "--velocity", "1", "--yes")
    assert result.exit_code == 0
    assert server.firmware.duty == [0] * 20


def test_jog_refusals(cli, server):
    target = ("-p", "dg-5f-right", "-t", server.endpoint)
    outside = cli(*target, "jog", "rj_dg_2_2", "-10deg", "--yes")  # lower limit is 0°
    assert outside.exit_code == 5 and "outside its limits" in outside.stderr
    too_far = cli(*target, "jog", "rj_dg_2_2", "45deg", "--yes")
    assert too_far.exit_code == 5 and "max_jog_step" in too_far.stderr
    unconfirmed = cli(*target, "jog", "rj_dg_2_2", "5deg")
    assert unconfirmed.exit_code == 5 and "--yes" in unconfirmed.stderr
    assert cli(*target, "jog", "rj_dg_9_9", "5deg", "--yes").exit_code == 2
    assert cli(*target, "jog", "rj_dg_2_2", "5 furlongs", "--yes").exit_code == 2
    assert server.firmware.position[5] == 0.0


def test_home_settles_or_names_the_stalled_joints(cli, server, tmp_path):
    fw = server.firmware
    fw.position[0] = 0.3
    result = cli("-p", "dg-5f-right", "-t", server.endpoint, "home", "--yes", "--json")
    assert result.exit_code == 0, result.stderr
    assert abs(fw.position[0]) < math.radians(2)
    # a home pose from the profile, and a stalled joint that cannot reach it
    text = Path(load_profile("dg-5f-right").source).read_text().replace("  home_timeout: 10", "  home_timeout: 1\n"
                                        "  home_pose: {rj_dg_1_1: 10deg, rj_dg_3_2: 20deg}")
    custom = tmp_path / "right.yaml"
    custom.write_text(text)
    fw.faults.stalled.add(9)  # rj_dg_3_2 cannot move
    result = cli("-p", str(custom), "-t", server.endpoint, "home", "--yes")
    assert result.exit_code == 1
    assert "rj_dg_3_2" in result.stderr and "did not settle" in result.stderr
    assert fw.position[0] == pytest.approx(math.radians(10), abs=math.radians(2))
    assert fw.duty == [0] * 20


def test_ctrl_c_during_a_jog_leaves_duty_zero(server):
    proc = subprocess.Popen(
        [sys.executable, "-m", "deltoctl", "-p", "dg-5f-right", "-t", server.endpoint, "jog",
         "rj_dg_2_2", "25deg", "--velocity", "2deg", "--yes"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 10
    while max(abs(d) for d in server.firmware.duty) == 0 and time.monotonic() < deadline:
        time.sleep(0.02)
    assert any(server.firmware.duty), "the jog never started"
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=10)
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    time.sleep(0.05)
    assert server.firmware.duty == [0] * 20
    assert server.firmware.position[5] < math.radians(20)


def test_the_progress_bar_stays_off_stdout(server, tmp_path):
    """A person watching stderr sees the bar; the result piped from stdout stays clean."""
    import os
    import pty
    import threading

    watcher, terminal = pty.openpty()
    drawn: list[bytes] = []

    def drain() -> None:  # read as it is drawn, so a full pty buffer never blocks deltoctl
        while True:
            try:
                chunk = os.read(watcher, 4096)
            except OSError:  # the terminal side is closed and everything was read
                return
            if not chunk:
                return
            drawn.append(chunk)

    reader = threading.Thread(target=drain)
    reader.start()
    try:
        out = subprocess.run(
            [sys.executable, "-m", "deltoctl", "-p", "dg-5f-right", "-t", server.endpoint,
             "jog", "rj_dg_2_2", "10deg", "--yes"],
            stdout=subprocess.PIPE, stderr=terminal, text=True, timeout=30)
    finally:
        os.close(terminal)
        reader.join(timeout=5)
        os.close(watcher)
    assert out.returncode == 0
    assert out.stdout.splitlines() == [out.stdout.strip()]  # the result line alone
    assert out.stdout.startswith("jog rj_dg_2_2: settled")
    assert b"jog" in b"".join(drawn)  # the bar's label went to the terminal
