"""`sim serve` prints targets a shell takes as they are, and says what it serves, so that a
later `--sim` of the same profile drives it (homed by the command before) instead of a fresh
simulator; what it says is untrusted."""

import json
import os
import shlex
import subprocess
import sys

import pytest

from deltoctl.sim.running import is_local_simulator, sims_dir


@pytest.fixture
def serve():
    """Start `deltoctl sim serve ARGS…`; returns its process and first stdout line."""
    procs = []

    def start(*args: str) -> tuple[subprocess.Popen, str]:
        proc = subprocess.Popen([sys.executable, "-m", "deltoctl", "sim", "serve", *args],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                stdin=subprocess.DEVNULL)
        procs.append(proc)
        return proc, proc.stdout.readline()

    yield start
    for proc in procs:
        proc.terminate()
        proc.communicate(timeout=10)


def test_sim_serve_target_lines_survive_a_shell(serve):
    proc, first = serve("mh5")
    lines = [first] + [proc.stdout.readline() for _ in range(2)]
    words = [shlex.split(line) for line in lines]  # as sh reads a pasted line
    assert [w[0] for w in words] == ["--target"] * 3 and all(len(w) == 2 for w in words)
    buses = dict(w[1].split("=", 1) for w in words)
    assert buses["upper_body"].endswith("?baud=2000000&rs485=1")  # the & is not sh's


def test_sim_serve_env_line_sets_deltoctl_target_for_every_command(serve):
    _, line = serve("mh5", "--hardware", "i2c", "--hardware", "upper_body", "--env")
    assert line.startswith("export DELTOCTL_TARGET=")
    got = subprocess.run(["sh", "-c", f'{line.strip()}; printf %s "$DELTOCTL_TARGET"'],
                         capture_output=True, text=True, check=True).stdout
    assert got.startswith("upper_body=serial:///dev/pts/") and "&rs485=1 i2c=" in got
    env = {**os.environ, "DELTOCTL_TARGET": got}
    done = subprocess.run([sys.executable, "-m", "deltoctl", "-p", "mh5", "--hardware", "i2c",
                           "--hardware", "upper_body", "connect", "-n", "1", "--json"],
                          capture_output=True, text=True, env=env, timeout=60)
    assert done.returncode == 0, done.stderr
    assert {b["target"] for b in json.loads(done.stdout)["blocks"]} == set(
        t.split("=", 1)[1] for t in got.split())


def test_env_or_json_not_both(cli):
    result = cli("sim", "serve", "mh5", "--env", "--json")
    assert result.exit_code == 2 and "--env or --json" in result.stderr


def test_sim_uses_the_running_sim_serve_so_homing_lasts(cli, serve):
    proc, _ = serve("bioscara-arm")
    entry = json.loads(next(sims_dir().glob("*.json")).read_text())
    assert entry["pid"] == proc.pid and entry["profile"] == "bioscara-arm"
    homed = cli("-p", "bioscara-arm", "--sim", "home", "--yes")
    assert homed.exit_code == 0, homed.stderr
    assert f"using sim serve (pid {proc.pid}) of bioscara-arm" in homed.stderr
    jogged = cli("-p", "bioscara-arm", "--sim", "jog", "j1", "-5deg", "--yes")
    assert jogged.exit_code == 0, jogged.stderr
    connected = cli("-p", "bioscara-arm", "--sim", "connect", "-n", "1", "--json")
    block, = json.loads(connected.stdout)["blocks"]
    assert block["simulated"] and block["target"] == entry["buses"]["i2c"]
    fresh = cli("-p", "bioscara-arm", "--sim-fresh", "jog", "j1", "-5deg", "--yes")
    assert fresh.exit_code == 5 and "not homed" in fresh.stderr
    assert "using sim serve" not in fresh.stderr
    other = cli("-p", "bioscara-arm", "--sim", "--sim-option", "stall=j3", "jog", "j1",
                "-5deg", "--yes")  # other faults: a simulator of its own
    assert other.exit_code == 5 and "using sim serve" not in other.stderr
    proc.terminate()
    proc.communicate(timeout=10)
    assert not list(sims_dir().glob("*.json"))  # said no more once it stopped


def test_a_fresh_sim_refusing_not_homed_says_how_to_keep_one(cli):
    result = cli("-p", "bioscara-arm", "--sim", "jog", "j1", "-5deg", "--yes")
    assert result.exit_code == 5 and "not homed" in result.stderr
    assert "each --sim starts a fresh simulator" in result.stderr
    assert "deltoctl sim serve bioscara-arm" in result.stderr
    assert "--sim-fresh" in cli("-h").stdout


def _entry(pid: int, buses: dict[str, str], profile: str = "bioscara-arm") -> dict:
    from deltoctl.profile.catalog import load_profile
    from deltoctl.sim.running import profile_hash

    prof = load_profile(profile)
    return {"pid": pid, "profile": profile, "hash": profile_hash(prof), "faults": {},
            "blocks": [hw.name for hw in prof.hardware], "buses": buses}


def _write(entry: dict) -> None:
    folder = sims_dir()
    for d in (folder.parent, folder):
        d.mkdir(mode=0o700, exist_ok=True)
    path = folder / f"{entry['pid']}.json"
    path.write_text(json.dumps(entry))
    path.chmod(0o600)


@pytest.fixture
def a_deltoctl_process():
    """A live process whose command line names deltoctl (a pid a server could hold)."""
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)", "deltoctl"])
    yield proc.pid
    proc.kill()
    proc.wait()


def test_the_file_of_a_server_that_is_gone_is_ignored_and_removed(cli, serve):
    proc, _ = serve("bioscara-arm")
    entry = json.loads(next(sims_dir().glob("*.json")).read_text())
    proc.kill()  # killed with -9: its file stays
    proc.communicate(timeout=10)
    _write(entry)
    stale = sims_dir() / f"{proc.pid}.json"
    assert stale.exists()
    result = cli("-p", "bioscara-arm", "--sim", "connect", "-n", "1")
    assert result.exit_code == 0, result.stderr
    assert "using sim serve" not in result.stderr and "warning" not in result.stderr
    assert not stale.exists()


@pytest.mark.parametrize("url", ["i2c+tcp://10.1.2.3:5000", "serial:///dev/ttyUSB0",
                                 "i2c:///dev/i2c-1"])
def test_a_server_file_naming_hardware_or_another_host_is_refused(cli, a_deltoctl_process, url):
    _write(_entry(a_deltoctl_process, {"i2c": url}))
    result = cli("-p", "bioscara-arm", "--sim", "connect", "-n", "1")
    assert result.exit_code == 0, result.stderr  # on a fresh simulator
    assert "using sim serve" not in result.stderr
    assert "is not a simulator of this computer" in result.stderr and url in result.stderr


def test_a_sims_dir_others_may_enter_is_not_read(cli, serve):
    serve("bioscara-arm")
    sims_dir().chmod(0o755)
    result = cli("-p", "bioscara-arm", "--sim", "connect", "-n", "1")
    assert result.exit_code == 0, result.stderr
    assert "using sim serve" not in result.stderr and "0700 expected" in result.stderr


def test_a_malformed_server_file_is_a_warning():
    from deltoctl.profile.catalog import load_profile
    from deltoctl.sim.running import find

    folder = sims_dir()
    folder.parent.mkdir(mode=0o700)
    folder.mkdir(mode=0o700)
    (folder / "1.json").write_text("{not json")
    (folder / "1.json").chmod(0o600)
    warnings: list[str] = []
    assert find(load_profile("bioscara-arm"), {}, [], warnings.append) is None
    assert len(warnings) == 1 and "1.json" in warnings[0]


@pytest.mark.parametrize(("url", "local"), [
    ("tcp://127.0.0.1:502", True), ("i2c+tcp://[::1]:7", True), ("tcp://localhost:1", True),
    ("serial:///dev/pts/4?baud=1000000&rs485=1", True), ("tcp://192.168.1.2:502", False),
    ("serial:///dev/ttyUSB0", False), ("serial:///dev/pts/../ttyS0", False),
    ("tcp://127.0.0.1.example.com:1", False), ("nonsense", False)])
def test_only_loopback_hosts_and_pseudo_terminals_are_simulators(url, local):
    assert is_local_simulator(url) is local


def test_a_sim_serve_beyond_loopback_is_not_offered_to_sim(serve):
    _, line = serve("bioscara-arm", "--host", "0.0.0.0")
    assert "0.0.0.0" in line and not list(sims_dir().glob("*.json"))


def test_deltoctl_target_holds_several_targets_and_t_wins(cli, serve):
    _, line = serve("bioscara-arm")
    target = shlex.split(line)[1]
    two = {"DELTOCTL_TARGET": f"{target} nope=tcp://127.0.0.1:1"}
    result = cli("-p", "bioscara-arm", "connect", "-n", "1", env=two)
    assert result.exit_code == 2 and "unknown bus 'nope'" in result.stderr
    result = cli("-p", "bioscara-arm", "-t", target, "connect", "-n", "1", env=two)
    assert result.exit_code == 0, result.stderr


@pytest.mark.parametrize("item", ["host=0.0.0.0", "port=502", "profile=mh5", "lost=1",
                                  "missing=head_y"])  # missing: a Dynamixel option
def test_a_sim_option_the_profiles_simulator_does_not_declare_is_refused(cli, item):
    """Where the simulator listens is not a --sim-option (host=0.0.0.0 would serve every
    interface), nor is a name no family of the profile declares."""
    result = cli("-p", "dg-5f-right", "--sim-fresh", "--sim-option", item, "identify")
    assert result.exit_code == 2, result.output
    name = item.split("=")[0]
    assert f"--sim-option {name!r}: not for dg-5f-right" in result.stderr
    assert "firmware" in result.stderr and "stall" in result.stderr  # what it takes


def test_a_read_only_sims_dir_is_a_warning_and_the_server_goes_on_unregistered(monkeypatch):
    import errno

    from deltoctl.profile.catalog import load_profile
    from deltoctl.sim import running

    folder = sims_dir()
    folder.parent.mkdir(mode=0o700)
    folder.mkdir(mode=0o500)

    def read_only(*args, **kwargs):  # as the file system says it, whoever runs the test
        raise OSError(errno.EROFS, "Read-only file system")

    if os.geteuid() == 0:  # root writes into a 0500 directory
        monkeypatch.setattr(running.tempfile, "mkstemp", read_only)
    warnings: list[str] = []
    with running.registered(load_profile("bioscara-arm"), {}, ["bioscara_arm"],
                            {"i2c": "i2c+tcp://127.0.0.1:7"}, warnings.append) as path:
        assert path is None
    assert len(warnings) == 1 and "--sim will not find this simulator" in warnings[0]
    assert list(folder.iterdir()) == []
