"""One suite for the simulators and the robot: `profile tests` writes it, the plugin's options
and deltoctl.toml point it at a robot (here a `sim serve` process standing in for hardware)."""

from __future__ import annotations

import json
import os
import selectors
import signal
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from deltoctl.schemas_lookup import schema_file
from tests.conftest import REPO

pytest_plugins = ["pytester"]
jsonschema = pytest.importorskip("jsonschema")

SUITES = {"dg-5f-right": "test_dg_5f_right.py", "mh5": "test_mh5.py"}
SUITE_TESTS = ["test_identify", "test_detect", "test_config_matches_the_golden_snapshot",
               "test_link_quality", "test_homing"]


def served(profile: str):
    """`deltoctl sim serve PROFILE` in its own process, and the targets it prints (its
    --json line: {"buses": {bus: URL}})."""
    proc = subprocess.Popen([sys.executable, "-m", "deltoctl", "--json", "sim", "serve",
                             profile], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    with selectors.DefaultSelector() as sel:
        sel.register(proc.stdout, selectors.EVENT_READ)
        if not sel.select(timeout=60):
            proc.kill()
            raise AssertionError(f"sim serve {profile} printed nothing: {proc.stderr.read()}")
    buses = json.loads(proc.stdout.readline())["buses"]
    return proc, [f"{bus}={url}" for bus, url in buses.items()]


@pytest.fixture(scope="module")
def served_robots():
    servers = {profile: served(profile) for profile in SUITES}
    yield {profile: targets for profile, (_, targets) in servers.items()}
    for proc, _ in servers.values():
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=30)


@pytest.fixture(scope="module")
def suites(tmp_path_factory):
    """The suites `profile tests` writes, one folder each."""
    from typer.testing import CliRunner

    from deltoctl.cli.main import app

    folders = {}
    for profile in SUITES:
        out = tmp_path_factory.mktemp(f"suite-{profile}") / "tests"
        result = CliRunner().invoke(app, ["--json", "profile", "tests", profile, "-o", str(out)])
        assert result.exit_code == 0, result.stderr
        document = json.loads(result.stdout)
        jsonschema.validate(document, json.loads(schema_file("profile tests").read_text()))
        written = document["result"]
        assert written["tests"] == SUITE_TESTS
        assert Path(written["test_file"]) == out / SUITES[profile]
        assert Path(written["golden"]).is_file()
        folders[profile] = out
    return folders


def hardware(profile: str, targets: list[str]) -> list[str]:
    return ["--deltoctl-profile", profile, *(f"--deltoctl-target={t}" for t in targets)]


def junit(path: Path) -> dict[str, str]:
    suite = ET.parse(path).getroot().find("testsuite")
    assert suite is not None
    return {k: suite.get(k, "") for k in ("tests", "failures", "errors", "skipped")}


@pytest.mark.parametrize("profile", list(SUITES))
def test_generated_suite_passes_on_the_simulators(pytester, suites, profile, tmp_path):
    report = tmp_path / "results.xml"
    result = pytester.runpytest_subprocess(suites[profile], "--strict-markers", f"--junitxml={report}")
    result.assert_outcomes(passed=len(SUITE_TESTS))
    assert junit(report) == {"tests": "5", "failures": "0", "errors": "0", "skipped": "0"}


@pytest.mark.parametrize("profile", list(SUITES))
def test_generated_suite_runs_on_a_served_robot(pytester, suites, served_robots, profile,
                                                tmp_path):
    """The same files against a robot reached by URL: the devices are the served ones, not
    simulators of the test's own; homing runs only when motion is allowed."""
    targets = served_robots[profile]
    (suites[profile] / "test_the_robot_under_test.py").write_text(
        "def test_blocks_are_the_targets(deltoctl_robot):\n"
        "    robot = deltoctl_robot()\n"
        "    assert {b.url for b in robot.blocks} == "
        + repr({t.split("=", 1)[1] for t in targets}) + "\n"
        "    assert [b.simulated for b in robot.blocks] == [None] * len(robot.blocks)\n")
    report = tmp_path / "results.xml"
    result = pytester.runpytest_subprocess(suites[profile], *hardware(profile, targets), "-rs",
                                f"--junitxml={report}")
    result.assert_outcomes(passed=len(SUITE_TESTS), skipped=1)
    result.stdout.fnmatch_lines([f"deltoctl: {profile} on {' '.join(targets)} (command line); "
                                 "motion: skipped (tests marked deltoctl_moves)",
                                 "SKIPPED * moves the robot: on hardware it runs only with "
                                 "--deltoctl-allow-motion"])
    assert junit(report) == {"tests": "6", "failures": "0", "errors": "0", "skipped": "1"}
    result = pytester.runpytest_subprocess(suites[profile], *hardware(profile, targets),
                                "--deltoctl-allow-motion")
    result.assert_outcomes(passed=len(SUITE_TESTS) + 1)
    (suites[profile] / "test_the_robot_under_test.py").unlink()


def test_deltoctl_toml_names_the_robot(pytester, served_robots, monkeypatch):
    """Found from the invocation folder up to the rootdir; the command line wins; motion is
    never allowed by the file."""
    targets = served_robots["mh5"]
    pytester.makeini("[pytest]\n")
    pytester.path.joinpath("deltoctl.toml").write_text(
        "[pytest]\nprofile = 'mh5'\ntarget = " + json.dumps(targets) + "\n")
    sub = pytester.mkdir("bench")
    sub.joinpath("test_robot.py").write_text(
        "import pytest\n\n"
        "def test_targets(deltoctl_sim):\n"
        f"    assert deltoctl_sim.buses('mh5') == {dict(t.split('=', 1) for t in targets)!r}\n"
        "\n"
        "@pytest.mark.deltoctl_moves\n"
        "def test_moves(deltoctl_robot):\n"
        "    deltoctl_robot().home(['head_y'])\n")
    monkeypatch.chdir(sub)
    result = pytester.runpytest_subprocess("-rs")
    result.assert_outcomes(skipped=2)  # the targets drive hardware: with motion allowed only
    result.stdout.fnmatch_lines([f"deltoctl: mh5 on * ({pytester.path / 'deltoctl.toml'}); "
                                 "motion: skipped*",
                                 "SKIPPED * needs the simulators: the robot under test is "
                                 "hardware*"])
    pytester.runpytest_subprocess("--deltoctl-allow-motion").assert_outcomes(passed=2)
    # the command line over the file: its profile without targets serves the simulators
    result = pytester.runpytest_subprocess("--deltoctl-target=upper_body=serial:///dev/null",
                                          "--deltoctl-profile=dg-5f-right")
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    assert "unknown bus 'upper_body'" in result.stderr.str()


def test_hardware_skips_what_needs_a_simulator(pytester, served_robots):
    """On hardware, a test that asks for simulator faults, or is written for another
    profile, is skipped; on the simulators the same tests run."""
    pytester.makepyfile(
        "def test_faults(deltoctl_robot):\n"
        "    deltoctl_robot('dg-5f-right', firmware='2.7')\n"
        "def test_sim_faults(deltoctl_sim):\n"
        "    deltoctl_sim('dg-5f-right', firmware='2.7')\n"
        "def test_other_profile(deltoctl_robot):\n"
        "    deltoctl_robot('bioscara-arm')\n")
    result = pytester.runpytest_subprocess(*hardware("dg-5f-right", served_robots["dg-5f-right"]), "-rs")
    result.assert_outcomes(skipped=3)
    result.stdout.fnmatch_lines(["SKIPPED * simulator faults (firmware) need the simulators*",
                                 "SKIPPED * written for bioscara-arm; the robot under test is "
                                 "dg-5f-right"])
    pytester.runpytest_subprocess().assert_outcomes(passed=3)


def test_a_robot_needs_a_profile(pytester):
    pytester.makepyfile("def test_it(deltoctl_robot):\n    deltoctl_robot()\n")
    result = pytester.runpytest_subprocess()
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines(["*deltoctl: no profile: name one in the fixture, or pass "
                                 "--deltoctl-profile NAME|PATH"])
    # an unreachable robot fails the tests that open it, with deltoctl's error
    result = pytester.runpytest_subprocess("--deltoctl-profile=dg-5f-right",
                                "--deltoctl-target=tcp://127.0.0.1:1")
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines(["E * deltoctl.errors.Unreachable: *127.0.0.1:1*"])


@pytest.mark.parametrize(("args", "toml", "error"), [
    (["--deltoctl-target=upper_body=serial:///dev/null"], None,
     "--deltoctl-target needs the robot's profile: pass --deltoctl-profile NAME|PATH"),
    (["--deltoctl-profile=mh5", "--deltoctl-target=arm=serial:///dev/null"], None,
     "deltoctl (command line): --target names unknown bus 'arm'"),
    (["--deltoctl-profile=mh5", "--deltoctl-target=upper_body=bogus://x"], None,
     "deltoctl (command line): 'bogus://x': "),
    (["--deltoctl-profile=mh5", "--deltoctl-target=serial:///dev/null"], None,
     "mh5 has several buses (upper_body, lower_body, i2c): name each target, BUS=URL"),
    (["--deltoctl-profile=no-such-robot"], None, "deltoctl (command line): "),
    ([], "[pytest\nprofile = 'mh5'\n", "deltoctl.toml: not valid TOML: "),
    ([], "[pytest]\nprofiles = 'mh5'\n", "[pytest] has no key 'profiles' (its keys: profile, "
                                          "target)"),
    ([], "[pytest]\nprofile = 'mh5'\ntarget = 3\n", "[pytest] target is a list of \"BUS=URL\" "
                                                    "strings; got 3"),
    ([], "[pytest]\nprofile = 5\n", "[pytest] profile is a catalog name or a file, as a string"),
    ([], "pytest = 'mh5'\n", "[pytest] is a table"),
    ([], "[pytest]\ntarget = ['upper_body=tcp://x:1']\n", "--deltoctl-target needs the "
                                                          "robot's profile"),
    ([], "[pytest]\nprofile = 'mh5'\nallow_motion = true\n", "has no key 'allow_motion'"),
])
def test_bad_options_and_files_are_one_usage_error(pytester, args, toml, error):
    pytester.makeini("[pytest]\n")
    if toml is not None:
        pytester.path.joinpath("deltoctl.toml").write_text(toml)
    pytester.makepyfile("def test_never_runs():\n    raise AssertionError\n")
    result = pytester.runpytest_subprocess(*args)
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    err = result.stderr.str()
    assert "ERROR: " in err and error in err, err
    assert "Traceback" not in err


def test_other_tables_of_deltoctl_toml_are_not_read(pytester):
    pytester.makeini("[pytest]\n")
    pytester.path.joinpath("deltoctl.toml").write_text("[fleet]\nrobots = 3\n")
    pytester.makepyfile("def test_it(deltoctl_sim):\n    assert deltoctl_sim('dg-4f')\n")
    pytester.runpytest_subprocess().assert_outcomes(passed=1)


def test_profile_tests_leaves_files_alone_and_names_come_in_as_literals(cli, tmp_path):
    """A profile's name cannot put code into the suite; a profile file is found from the
    test file's folder; existing files are overwritten only with --force."""
    text = (REPO / "profiles" / "dg-3f-m.yaml").read_text()
    lines = text.splitlines()
    name = next(i for i, line in enumerate(lines) if line.startswith("name:"))
    lines[name] = "name: 'x\"\"\" + __import__(''os'').system(''touch pwned'') + \"\"\"'"
    profile = tmp_path / "robots" / "odd.yaml"
    profile.parent.mkdir()
    profile.write_text("\n".join(lines) + "\n")
    out = tmp_path / "suite"
    result = cli("profile", "tests", str(profile), "-o", str(out))
    assert result.exit_code == 0, result.stderr
    (test_file,) = out.glob("test_*.py")
    source = test_file.read_text()
    compile(source, str(test_file), "exec")
    assert "PROFILE = str(Path(__file__).parent / '../robots/odd.yaml')" in source
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           "-k", "identify or config", str(out)], cwd=tmp_path,
                          capture_output=True, text=True, env={**os.environ}, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "2 passed" in proc.stdout
    assert not (tmp_path / "pwned").exists()
    again = cli("profile", "tests", str(profile), "-o", str(out))
    assert again.exit_code == 2 and "exists: pass --force to overwrite" in again.stderr
    assert cli("profile", "tests", str(profile), "-o", str(out), "--force").exit_code == 0
    missing = cli("profile", "tests", "no-such-robot", "-o", str(out))
    assert missing.exit_code == 2 and "Traceback" not in missing.stderr


def test_simulator_tests_do_not_drive_the_robot_under_test(pytester, served_robots):
    """On hardware, a test written for the simulators is skipped (its CLI jog would move the
    robot), and the robot the fixture opens refuses motion and actuation, before a byte is
    sent, unless --deltoctl-allow-motion; with it, deltoctl_sim(profile) gives the robot's
    target (the default firmware asks for no fault)."""
    target = served_robots["dg-5f-right"]
    pytester.makepyfile(
        "import pytest\n"
        "from deltoctl.errors import Refused\n\n"
        "def test_sim(deltoctl_sim):\n"
        f"    assert deltoctl_sim('dg-5f-right') == {target[0].split('=', 1)[-1]!r}\n\n"
        "def test_refused(deltoctl_robot):\n"
        "    robot = deltoctl_robot()\n"
        "    for call in (lambda: robot.jog({'rj_dg_1_2': '1deg'}), lambda: robot.home(),\n"
        "                 lambda: robot.set_gpio('gpio/output_1', 1.0),\n"
        "                 lambda: robot.system.set_command('rj_dg_1_2/effort', 0.0),\n"
        "                 lambda: robot.calibrate_ft(samples=5)):\n"
        "        with pytest.raises(Refused, match='allows no motion') as refused:\n"
        "            call()\n"
        "        assert '--deltoctl-allow-motion' in refused.value.hint\n"
        "    assert robot.identify()['blocks']  # reading still works\n")
    args = hardware("dg-5f-right", target)
    result = pytester.runpytest_subprocess(*args, "-rs")
    result.assert_outcomes(passed=1, skipped=1)
    result.stdout.fnmatch_lines(["SKIPPED * needs the simulators*"])
    result = pytester.runpytest_subprocess(*args, "--deltoctl-allow-motion", "-k", "not refused")
    result.assert_outcomes(passed=1, deselected=1)
