"""Remote verbs as local ones: a remote record's own file names (absolute, '..', '~') are the
caller's; a `--sim` agent's verbs say simulated; a refused --log-file makes no file; a refused
fleet run names its robots; a remote record reports the robot's loop figures; `fleet run`
exits cleanly under load (no abort while Zenoh shuts down)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

pytest.importorskip("zenoh")

from deltoctl.fleet import lab
from tests.fleet.test_fleet import Bench, deltoctl

LOCAL_LOOP = ("lateness_p50_ms", "lateness_p99_ms", "packets", "errors", "error_rate_perc")


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    b = Bench(tmp_path_factory.mktemp("gaps"), "hand-9", "dg-5f-right")
    yield b
    b.close()


@pytest.mark.parametrize("where", ["absolute", "parent", "home"])
def test_a_remote_record_writes_any_file_of_the_caller(bench, tmp_path, where):
    (tmp_path / "here" / "~").mkdir(parents=True)  # a literal ~, as a local record reads it
    name = {"absolute": str(tmp_path / "abs.mcap"), "parent": "../up.mcap",
            "home": "~/deltoctl-remote-gaps.mcap"}[where]
    home = tmp_path / "home"
    home.mkdir()
    result = subprocess.run(
        [*lab.deltoctl_command(), "--zenoh-config", str(bench.config), "--robot", bench.robot,
         "record", name, "--duration", "0.3", "--json"], capture_output=True, text=True,
        timeout=60, cwd=tmp_path / "here", env={**_env(), "HOME": str(home)},
        stdin=subprocess.DEVNULL)
    assert result.returncode == 0, result.stderr
    written = {"absolute": tmp_path / "abs.mcap", "parent": tmp_path / "up.mcap",
               "home": tmp_path / "here" / "~" / "deltoctl-remote-gaps.mcap"}[where]
    assert written.stat().st_size > 0
    loop = json.loads(result.stdout)["result"]["loop"]
    assert set(LOCAL_LOOP) <= set(loop)  # the robot's figures, as a local record has them
    assert loop["packets"] >= loop["cycles"] > 0


def test_a_remote_verb_still_cannot_name_a_file_outside_the_agents_directory(bench):
    result = bench.remote("profile", "export", "dg-5f-right", "-o", "/tmp/x.yaml")
    assert result.returncode == 2
    assert "agent's directory only" in result.stderr


def test_a_sim_agents_verbs_and_recordings_say_simulated(bench, tmp_path):
    identify = bench.remote("identify", "--json")
    assert identify.returncode == 0, identify.stderr
    assert all(b["simulated"] for b in json.loads(identify.stdout)["blocks"])
    out = tmp_path / "sim.mcap"
    record = bench.remote("record", str(out), "--duration", "0.3")
    assert record.returncode == 0, record.stderr
    from deltoctl.record.reader import open_recording

    identities = open_recording(out).metadata["identify"]
    assert all(json.loads(text)["simulated"] is True for text in identities.values())


def test_a_refused_log_file_is_not_created(bench, tmp_path):
    log = tmp_path / "refused.log"
    result = bench.remote("--log-file", str(log), "identify")
    assert result.returncode == 2
    assert "--log-file is not taken remotely" in result.stderr
    assert not log.exists()


def test_a_refused_fleet_run_names_its_robots(bench):
    result = deltoctl("--zenoh-config", str(bench.config), "fleet", "run", "profile",
                      "export", "dg-5f-right", "-o", "/tmp/x.yaml")
    assert result.returncode == 2
    assert "agent's directory only" in result.stderr
    assert f"robot {bench.robot}:" in result.stderr
    assert "robot *" not in result.stderr


def _env() -> dict[str, str]:
    import os

    return {k: v for k, v in os.environ.items() if not k.startswith("DELTOCTL_")}


BUSY = "while True: pass"


@pytest.mark.slow
def test_fleet_run_exits_cleanly_under_load(bench):
    """Two busy loops beside it, 30 runs: none ends in an abort (exit 134) while Zenoh's
    threads are still calling back into an interpreter that is shutting down."""
    busy = [subprocess.Popen([sys.executable, "-c", BUSY]) for _ in range(2)]
    try:
        codes = [deltoctl("--zenoh-config", str(bench.config), "fleet", "run", "--wait", "1",
                          "identify", "--json", timeout=120).returncode for _ in range(30)]
    finally:
        for proc in busy:
            proc.kill()
            proc.wait()
    assert codes == [0] * 30, codes


def test_a_remote_record_fills_serial_and_refuses_an_existing_file(bench, tmp_path):
    result = bench.remote("record", str(tmp_path / "r-{serial}.mcap"), "--duration", "0.2")
    assert result.returncode == 0, result.stderr
    (written,) = tmp_path.iterdir()
    assert written.name.startswith("r-127.0.0.1-") and written.stat().st_size > 0
    again = bench.remote("record", str(written), "--duration", "0.2")
    assert again.returncode == 2 and "exists" in again.stderr
    forced = bench.remote("record", str(written), "--duration", "0.2", "--force")
    assert forced.returncode == 0, forced.stderr
