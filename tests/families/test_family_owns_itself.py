"""A family owns everything about itself, declared in its descriptor and found through the
registry: the toy family (tests/toyfamily/: descriptor, its own ``toy://`` transport, driver,
emulator) brings its link, its `sim serve` fault, its restore permission and its identity
fields, and runs the verbs, `sim serve` and `doctor` — in-process and as an installed package
through the entry points — with no file of deltoctl naming it."""

from __future__ import annotations

import configparser
import contextlib
import inspect
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from deltoctl import registry
from deltoctl.errors import DeltoctlError
from tests.conftest import REPO
from tests.families.conftest import PROFILE
from tests.toyfamily import ENTRY_POINTS, FAMILY


@pytest.fixture
def installed(tmp_path):
    """The toy family as an installed package: a dist-info whose entry points name its
    descriptor and its transport; ``run(*args)`` runs deltoctl in a process that finds it."""
    dist = tmp_path / "site" / "toyfamily-1.0.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: toyfamily\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text("".join(
        f"[{group}]\n" + "".join(f"{name} = {ref}\n" for name, ref in refs.items())
        for group, refs in ENTRY_POINTS.items()))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(dist.parent), str(REPO)]),
           "COLUMNS": "200"}
    profile = tmp_path / "toy-robot.yaml"
    profile.write_text(PROFILE)

    def run(*args: str, **kwargs) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "deltoctl", *args], env=env,
                              capture_output=True, text=True, timeout=60, **kwargs)

    run.env, run.profile = env, str(profile)  # type: ignore[attr-defined]
    return run


def _document(result) -> dict:
    doc = json.loads(result.stdout)
    return doc.get("result", doc)


@contextlib.contextmanager
def _served(run, *options: str):
    """`deltoctl sim serve` of the toy profile in its own process; yields {bus: URL}."""
    proc = subprocess.Popen([sys.executable, "-m", "deltoctl", "sim", "serve", run.profile,
                             "--json", *options], env=run.env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        assert line, proc.stderr.read()
        yield json.loads(line)["buses"]
    finally:
        proc.terminate()
        proc.wait(timeout=10)


# -- the measure: a family with its own link, fault, permission and identity -----------------

def test_the_toy_runs_the_verbs_on_its_own_link(cli, toy, tmp_path):
    result = cli("-p", toy, "--sim", "--json", "connect", "-n", "3")
    assert result.exit_code == 0, result.stderr
    blocks = _document(result)["blocks"]
    assert [(b["family"], b["target"][:6]) for b in blocks] == [("toy", "toy://")] * 2
    identity = _document(cli("-p", toy, "--sim", "--json", "identify"))["blocks"]
    assert identity[0]["identity"] == {"version": "toy 1.0", "joints": 2}
    detect = cli("-p", toy, "--sim", "detect")
    assert detect.exit_code == 0 and "toy 1.0" in detect.stdout
    result = cli("-p", toy, "--sim", "--json", "stream", "-r", "50", "-d", "0.1")
    assert result.exit_code == 0, result.stderr
    out = tmp_path / "toy.mcap"
    assert cli("-p", toy, "--sim", "record", str(out), "-d", "0.2").exit_code == 0
    assert out.stat().st_size > 0
    snapshot = tmp_path / "snap.yaml"
    assert cli("-p", toy, "--sim", "config", "snapshot", "-o", str(snapshot)).exit_code == 0
    assert yaml.safe_load(snapshot.read_text())["blocks"]["toy_left"]["parts"] == {
        "pendulums": {"period": {"value": 2.0, "unit": "s", "access": "RW"}}}


def test_the_toy_fault_reaches_its_emulator_from_the_api_and_the_fixture(toy, deltoctl_robot):
    from deltoctl import open_robot

    with open_robot(toy, sim={"frozen": True}) as robot:
        values = robot.system.read()
    assert values["l1/position"] == values["l2/position"] == values["r1/position"] == 0.0
    robot = deltoctl_robot(toy)  # not frozen: the pendulums swing
    assert any(v != 0.0 for k, v in robot.system.read().items() if k.endswith("/position"))
    with pytest.raises(DeltoctlError, match="--frozen takes true or false"):
        deltoctl_robot(toy, frozen="yes")


def test_the_toy_package_serves_passes_doctor_and_restores_with_its_permission(
        installed, cli, toy, tmp_path):
    help_text = installed("sim", "serve", "-h").stdout
    assert "--frozen" in help_text and "pendulums stand still" in help_text
    with _served(installed, "--frozen") as buses:
        targets = [a for bus, url in buses.items() for a in ("-t", f"{bus}={url}")]
        stream = installed("-p", installed.profile, *targets, "--json", "stream", "-r", "20",
                           "-d", "0.2")
        assert stream.returncode == 0, stream.stderr
        last = json.loads(stream.stdout.splitlines()[-1])["values"]
        assert last["l1/position"] == last["r1/position"] == 0.0  # the fault, served
        doctor = installed("-p", installed.profile, *targets, "doctor", "--json")
        assert doctor.returncode == 0, doctor.stdout
        checks = _document(doctor)["checks"]
        assert [(c["check"], c["subject"]) for c in checks[1:]] == [
            ("reachable", "left"), ("reachable", "right")]
        # its permission: a new period is refused without it, written with it
        snapshot = tmp_path / "snap.yaml"
        assert cli("-p", toy, *targets, "config", "snapshot", "-o", str(snapshot)).exit_code == 0
        doc = yaml.safe_load(snapshot.read_text())
        doc["blocks"]["toy_left"]["parts"]["pendulums"]["period"]["value"] = 3.0
        snapshot.write_text(yaml.safe_dump(doc))
        refused = cli("-p", toy, *targets, "config", "restore", str(snapshot), "--yes")
        assert refused.exit_code == 5
        assert "a new period restarts every swing" in refused.stderr
        assert "pass --allow toy-rewind once the pendulums may restart" in refused.stderr
        restored = cli("-p", toy, *targets, "--json", "config", "restore", str(snapshot),
                       "--yes", "--allow", "toy-rewind")
        assert restored.exit_code == 0, restored.stderr
        assert _document(restored)["summary"] == {"verified": 1}
    refused = installed("-p", installed.profile, *targets, "doctor")
    assert refused.returncode == 4
    assert "fix: start the pendulums: deltoctl sim serve PROFILE" in refused.stdout


def test_the_toy_identity_is_shown_by_its_declared_fields(cli, toy):
    from deltoctl.render.fleet import identity_text

    blocks = _document(cli("-p", toy, "--sim", "--json", "identify"))["blocks"]
    identity = {b["name"]: {"family": b["family"], **b["identity"]} for b in blocks}
    assert identity_text(identity) == ("toy_left: toy 1.0 (2 pendulums); "
                                       "toy_right: toy 1.0 (1 pendulums)")


def test_a_url_of_no_known_transport_is_one_error_naming_the_known_ones(cli, toy):
    result = cli("-t", "ethercat://eth0", "doctor")
    assert result.exit_code == 2
    assert "unknown scheme 'ethercat'" in result.stdout and "toy://HOST:PORT" in result.stdout
    result = cli("-t", "toy://127.0.0.1", "doctor")  # the toy transport's own parse
    assert result.exit_code == 2 and "expected toy://HOST:PORT" in result.stdout


# -- capabilities are checked against the driver ---------------------------------------------

def _jogging_toy() -> registry.Family:
    return registry.Family("jogtoy", "tests.toyfamily.driver:ToyDriver",
                           plugins=("toy_hardware/JogToy",), schemes=("toy",),
                           emulator="tests.toyfamily.emulator:serve",
                           serve_options=FAMILY.serve_options,
                           capabilities=frozenset({"identify", "jog"}))


def test_a_capability_without_its_method_is_refused_at_registration():
    with pytest.raises(ValueError, match=r"jog needs move\(\)"):
        registry.register(_jogging_toy())
    assert registry.get("jogtoy") is None
    for family in registry.families().values():  # the built-in ones have every method
        assert registry.unimplemented(family, family.driver_class()) == ""


def test_a_family_naming_homing_joints_needs_a_homing_routine():
    from dataclasses import replace

    homing = replace(FAMILY, name="homingtoy", homing_joints="tests.toyfamily:FAMILY")
    with pytest.raises(ValueError, match=r"homing_joints needs home\(\)"):
        registry.register(homing)
    assert registry.get("homingtoy") is None


def test_a_capability_without_its_method_is_one_error_on_first_use(cli, toy, tmp_path,
                                                                    monkeypatch):
    # as a family found through an entry point: checked when its driver is first loaded
    monkeypatch.setitem(registry.families(), "jogtoy", _jogging_toy())
    path = tmp_path / "jogtoy.yaml"
    path.write_text(PROFILE.replace("ToySystem", "JogToy"))
    result = cli("-p", str(path), "--sim", "connect")
    assert result.exit_code == 1
    assert "family 'jogtoy'" in result.stderr and "jog needs move()" in result.stderr
    assert "Traceback" not in result.stderr


# -- sim serve's options are the families' ---------------------------------------------------

def test_sim_serve_takes_every_declared_option_and_checks_each_value(cli):
    spelled = ["--firmware", "--short-version", "--model-id", "--input-1", "--delay", "--stall",
               "--missing", "--pace", "--wrong-baud", "--who-am-i", "--orientation"]
    help_text = cli("sim", "serve", "-h").stdout
    assert all(flag in help_text for flag in spelled)
    declared = {o.flag for f in registry.families().values() for o in f.serve_options}
    assert declared >= set(spelled)
    result = cli("sim", "serve", "dg-4f", "--delay", "11")
    assert result.exit_code == 2 and "--delay takes a number from 0 to 10" in result.stderr
    result = cli("sim", "serve", "mh5", "--orientation", "1,2,3,4")
    assert result.exit_code == 2 and "--orientation takes comma-separated" in result.stderr


def test_open_robot_refuses_an_option_no_family_of_the_profile_declares():
    from deltoctl import open_robot

    with pytest.raises(DeltoctlError, match="'bogus': not for rrbot-gpio"), \
            open_robot("rrbot-gpio", sim={"bogus": 1}):
        pass


# -- nothing outside a family names it ---------------------------------------------------------

NEUTRAL = ["deltoctl/cli/sim_cmd.py", "deltoctl/cli/doctor_cmd.py", "deltoctl/app/doctor.py",
           "deltoctl/app/config.py", "deltoctl/cli/fleet_cmd.py", "deltoctl/render/fleet.py"]


def _named(text: str) -> list[str]:
    """The families, their parts and permissions, and the transports' schemes (as a URL's,
    ``can://``, or a string, ``"can"``: a scheme may be an English word) a text names."""
    words = {f.name for f in registry.families().values()} | {"gripper", "servo", "imu"}
    words |= {p.name for f in registry.families().values() for p in f.permissions}
    schemes = "|".join(re.escape(s) for s in registry.transport_refs())
    pattern = (r"(?<![\w-])(" + "|".join(re.escape(w) for w in sorted(words)) + r")(?![\w-])"
               rf"|(?<![\w+-])({schemes})(?=://)|[\"']({schemes})[\"']")
    found = re.findall(pattern, text, flags=re.IGNORECASE)
    return sorted({next(g for g in groups if g).lower() for groups in found})


def test_the_shared_code_names_no_family_and_no_scheme():
    from deltoctl.sim.serve import ServeOptions

    texts = {path: (REPO / path).read_text() for path in NEUTRAL}
    texts["ServeOptions"] = inspect.getsource(ServeOptions)
    assert {where: _named(text) for where, text in texts.items()} == {w: [] for w in texts}
    assert _named("a Dynamixel servo can be on serial://, 'i2c' or torque-off") == [
        "dynamixel", "i2c", "serial", "servo", "torque-off"]  # what the grep looks for


# -- the import-linter contract keeps every registered family apart --------------------------

def _contract_gaps(pyproject: str, importlinter: str) -> list[str]:
    """The families pyproject.toml registers that the families-independent contract does
    not name (and the modules it names that no family is)."""
    section = re.search(r'^\[project\.entry-points\."deltoctl\.families"\]\n(.*?)(?=^\[|\Z)',
                        pyproject, flags=re.MULTILINE | re.DOTALL)
    assert section is not None, "pyproject.toml registers no family"
    refs = re.findall(r'^\s*[\w-]+\s*=\s*"([^"]+)"', section.group(1), flags=re.MULTILINE)
    registered = {ref.partition(":")[0] for ref in refs}
    config = configparser.ConfigParser()
    config.read_string(importlinter)
    contract = set(config["importlinter:contract:families-independent"]["modules"].split())
    return sorted(registered ^ contract)


def test_the_independence_contract_names_every_registered_family():
    pyproject = (REPO / "pyproject.toml").read_text()
    importlinter = (REPO / ".importlinter").read_text()
    assert _contract_gaps(pyproject, importlinter) == []
    forgotten = pyproject.replace(
        '[project.entry-points."deltoctl.families"]\n',
        '[project.entry-points."deltoctl.families"]\ncan = "deltoctl.families.can:FAMILY"\n')
    assert _contract_gaps(forgotten, importlinter) == ["deltoctl.families.can"]


def test_a_family_package_needs_no_file_of_deltoctl():
    """The toy's whole definition is its folder: nothing of deltoctl names it."""
    toy = REPO / "tests" / "toyfamily"
    assert {p.name for p in toy.glob("*.py")} == {"__init__.py", "driver.py", "emulator.py",
                                                  "transport.py"}
    sources = [p for p in (REPO / "deltoctl").rglob("*") if p.suffix in (".py", ".toml")]
    assert not [str(p) for p in [*sources, REPO / "pyproject.toml", REPO / ".importlinter"]
                if re.search(r"\btoy(family)?\b", Path(p).read_text(errors="replace"))]
