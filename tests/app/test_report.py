"""deltoctl report: the acceptance sequence on simulated robots behind their real transports,
one self-contained HTML5 report (parsed by html5lib; in headless Chromium where installed)
and its JSON twin, each check with an id, a limit, a value, a unit and a verdict."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from deltoctl.app.report import report_hash
from deltoctl.families.delto.emulator import DeltoServer, firmware_for_profile
from deltoctl.profile.catalog import load_profile
from tests.conftest import REPO

KEYS = {"id", "what", "value", "unit", "limit", "verdict"}
# timing limits no loaded test machine misses: the tests judge behaviour, not speed
RELAXED = "report: {rtt_p50_ms: 1000, rtt_p99_ms: 1000, jitter_p99_ms: 1000, " \
          "loop_rate_ratio: 0.01%s}\n"


def hand(tmp_path, extra=""):
    """The DG-4F's profile with relaxed timing limits (and ``extra`` ones)."""
    path = tmp_path / "hand.yaml"
    path.write_text((REPO / "profiles" / "dg-4f.yaml").read_text() + RELAXED % extra)
    return str(path)


def parse_html(path):
    """The page as a strict HTML5 parser reads it (any parse error raises)."""
    html5lib = pytest.importorskip("html5lib")
    text = path.read_text(encoding="utf-8")
    return text, html5lib.HTMLParser(strict=True, namespaceHTMLElements=False).parse(text)


def assert_self_contained(text, tree):
    """Nothing in the page is fetched: no src, href or CSS url(), no script."""
    assert tree.findall(".//script") == [] and tree.findall(".//link") == []
    for element in tree.iter():
        assert "src" not in element.attrib and "href" not in element.attrib, element.tag
    assert "url(" not in text and "@import" not in text


def unwrap(doc):
    """The report, inside the JSON envelope every verb's document may come in."""
    return doc["result"] if "result" in doc and "verb" in doc else doc


def report(cli, tmp_path, *args, profile=None, target=None, name="r"):
    profile = profile or hand(tmp_path)
    out = tmp_path / f"{name}.html"
    where = ("-t", target) if target else ("--sim",)
    result = cli("-p", profile, *where, "report", "-o", str(out), "--json", *args)
    return result, out


def test_a_sound_gripper_passes_and_both_files_agree(cli, tmp_path):
    result, out = report(cli, tmp_path, "--operator", "A. Tester")
    assert result.exit_code == 0, result.stderr
    doc = unwrap(json.loads(result.stdout))
    assert doc["verdict"] == "pass" and doc["failed"] == []
    assert json.loads(out.with_suffix(".json").read_text()) == doc
    assert doc["report_sha256"] == report_hash(doc)
    header = doc["header"]
    assert header["operator"] == "A. Tester" and header["profile"]["name"] == "dg-4f"
    assert header["profile"]["sha256"] and header["start"] <= header["end"]
    for c in doc["checks"]:
        assert set(c) >= KEYS and set(c["limit"]) == {"min", "max"}, c
    ids = {c["id"] for c in doc["checks"]}
    assert {"link.dg4f_driver.rtt_p99", "link.dg4f_driver.error_rate",
            "detect.dg4f_driver.fingertip_f_t_sensors"} <= ids
    skipped = {c["id"] for c in doc["checks"] if c["verdict"] == "skip"}
    assert {"motion", "sensors.actuated"} <= skipped  # without --yes: no motion, no tare
    assert "fingertip_finger_1.residual_force" not in ids
    (block,) = doc["sections"]["identity"]["blocks"]
    assert block["identity"]["firmware"] == "3.0" and block["simulated"] is True
    assert re.fullmatch(r"[0-9a-f]{64}", doc["sections"]["configuration"]["fingerprint"])

    text, tree = parse_html(out)
    assert_self_contained(text, tree)
    assert tree.find(".//span[@id='verdict']").text == "PASS"
    assert tree.find(".//span[@id='report-hash']").text == doc["report_sha256"]
    rows = tree.findall(".//table[@id='checks']/tbody/tr[@class='check']") or \
        tree.findall(".//table[@id='checks']//tr[@class='check']")
    assert len(rows) == len(doc["checks"])
    assert "A. Tester" in text and "Sign-off" in text


def test_a_failing_check_is_exit_1_naming_it_and_the_report_is_kept(cli, tmp_path):
    firmware = firmware_for_profile(load_profile("dg-4f"), firmware=(2, 2), seed=2)
    with DeltoServer(firmware) as server:  # before 2.3: no tare
        result, out = report(cli, tmp_path, "--yes", target=server.endpoint, profile=hand(tmp_path, ", homes: 1"))
    assert result.exit_code == 1
    assert "acceptance failed: fingertip_finger_" in result.stderr
    doc = json.loads(out.with_suffix(".json").read_text())
    assert doc["verdict"] == "fail" and doc["checks"][0]["verdict"] == "fail"
    assert all(re.fullmatch(r"fingertip_finger_\d\.residual_(force|torque)", f)
               for f in doc["failed"]) and "fingertip_finger_1.residual_force" in doc["failed"]
    _, tree = parse_html(out)
    assert tree.find(".//span[@id='verdict']").text == "FAIL"


def test_golden_snapshot_differences_fail(cli, tmp_path):
    import yaml

    with DeltoServer(firmware_for_profile(load_profile("dg-4f"), seed=4)) as server:
        snap = tmp_path / "approved.yaml"
        result = cli("-p", hand(tmp_path), "-t", server.endpoint, "config", "snapshot", "-o",
                     str(snap))
        assert result.exit_code == 0, result.stderr
        result, _ = report(cli, tmp_path, "--golden", str(snap), target=server.endpoint)
        assert result.exit_code == 0, result.stderr
        same = unwrap(json.loads(result.stdout))
        assert next(c for c in same["checks"] if c["id"] == "config.golden")["value"] == 0
        # the approved configuration said otherwise on one item
        doc = yaml.safe_load(snap.read_text())
        (block,) = doc["blocks"].values()
        part, items = next((p, i) for p, i in block["parts"].items()
                           if any(isinstance(e.get("value"), bool) for e in i.values()))
        item = next(k for k, e in items.items() if isinstance(e.get("value"), bool))
        items[item]["value"] = not items[item]["value"]
        snap.write_text(yaml.safe_dump(doc))
        result, _ = report(cli, tmp_path, "--golden", str(snap), target=server.endpoint,
                           name="r2")
    assert result.exit_code == 1
    differ = unwrap(json.loads(result.stdout))
    name = f"config.{next(iter(differ['sections']['configuration']['blocks']))}/{part}/{item}"
    assert name in differ["failed"] and "config.golden" in differ["failed"]
    assert differ["sections"]["configuration"]["fingerprint"] == \
        same["sections"]["configuration"]["fingerprint"]


SVG = "{http://www.w3.org/2000/svg}"


@pytest.mark.parametrize("hidden", [(), ("numpy", "matplotlib", "plotext")],
                         ids=["with the plot extra", "without it"])
def test_a_recording_is_plotted_and_hashed(cli, tmp_path, monkeypatch, hidden):
    """The figures are inline SVG drawn with the standard library: a path per interface,
    axes with ticks and the unit, a legend — with or without deltoctl[plot]."""
    for module in hidden:
        monkeypatch.setitem(sys.modules, module, None)  # `import numpy` fails
    result, out = report(cli, tmp_path, "--record", "0.5")
    assert result.exit_code == 0, result.stderr
    recording = unwrap(json.loads(result.stdout))["sections"]["recording"]
    mcap = out.with_suffix(".mcap")
    import hashlib

    assert recording["file"] == str(mcap) and "note" not in recording
    assert recording["sha256"] == hashlib.sha256(mcap.read_bytes()).hexdigest()
    assert [(p["title"], p["unit"]) for p in recording["plots"]] == [("positions", "rad"),
                                                                     ("forces", "N")]
    text, tree = parse_html(out)
    assert_self_contained(text, tree)
    assert "pip install" not in text
    svgs = tree.findall(f".//{SVG}svg")
    assert len(svgs) == 2
    positions, forces = svgs
    paths = positions.findall(f"{SVG}path")
    assert len(paths) == 8 and len(paths[0].get("d").split("L")) > 10
    names = [p.get("data-name") for p in paths]
    assert names == [s["name"] for s in recording["plots"][0]["series"]]
    labels = [t.text for t in positions.iter(f"{SVG}text")]
    assert "time [s]" in labels and "rad" in labels and names[0] in labels  # axes, legend
    assert len(forces.findall(f"{SVG}path")) == 8 and "N" in [t.text for t in
                                                             forces.iter(f"{SVG}text")]


def test_motion_checks_run_only_with_yes(cli, tmp_path):
    profile = hand(tmp_path, ", homes: 1")
    result = cli("-p", profile, "--sim", "--yes", "report", "-o",
                 str(tmp_path / "m.html"), "--json")
    assert result.exit_code == 0, result.stderr
    doc = unwrap(json.loads(result.stdout))
    assert doc["header"]["limits"]["homes"] == 1 and doc["header"]["limits"]["jitter_p99_ms"] == 1000
    motion = {c["id"]: c for c in doc["checks"] if c["id"].startswith("motion.")}
    # each joint: returns home, soft limits and back
    assert len(motion) == 2 * len(load_profile("dg-4f").joints())
    error = motion["motion.j_dg_1_1.following_error"]
    assert error["unit"] == "rad" and error["verdict"] == "pass"
    assert motion["motion.j_dg_2_2.home_repeatability"]["value"] == 0  # one return
    assert "fingertip_finger_1.residual_force" in {c["id"] for c in doc["checks"]}  # tared


def test_a_report_without_yes_writes_nothing_to_the_sensors(cli, tmp_path, monkeypatch):
    """A report without --yes only reads: no F/T tare (SET_FT_OFFSET), no IMU self-test."""
    import deltoctl.app.calibrate as calibrate
    import deltoctl.app.imu_calibration as imu_calibration

    def refuse(*_, **__):
        raise AssertionError("a report without --yes wrote to a sensor")

    monkeypatch.setattr(calibrate, "tare_ft", refuse)
    monkeypatch.setattr(imu_calibration, "self_test_checks", refuse)
    result, _ = report(cli, tmp_path)
    assert result.exit_code == 0, result.stderr
    result = cli("-p", "mh5", "--sim", "report", "-o", str(tmp_path / "mh5.html"), "--json")
    assert result.exit_code in (0, 3) or "link." in result.stderr, result.stderr


@pytest.mark.parametrize("section, message", [
    ("report:\n  rtt_p99: 5\n", "unknown key 'rtt_p99' in report"),
    ("report:\n  homes: -2\n", "homes must be"),
])
def test_a_bad_report_section_is_exit_2(cli, tmp_path, section, message):
    profile = tmp_path / "hand.yaml"
    profile.write_text((REPO / "profiles" / "dg-4f.yaml").read_text() + section)
    result = cli("-p", str(profile), "--sim", "report", "-o", str(tmp_path / "x.html"))
    assert result.exit_code == 2 and message in result.stderr, result.stderr
    assert "Traceback" not in result.stderr


@pytest.mark.parametrize("args, message", [
    (("-o", "x.txt"), "the report is an .html file"),
    (("--record", "-1"), "--record must be a positive number"),
    (("--golden", "nowhere.yaml"), "--golden nowhere.yaml: no such file"),
])
def test_bad_options_are_exit_2(cli, tmp_path, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)
    result = cli("-p", "dg-4f", "--sim", "report", *args)
    assert result.exit_code == 2 and message in result.stderr, result.stderr
    assert not list(tmp_path.glob("*.html"))


CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser") or (
    "/usr/bin/chromium" if shutil.os.path.exists("/usr/bin/chromium") else None)


@pytest.mark.skipif(CHROMIUM is None, reason="headless Chromium is not installed")
def test_the_report_renders_in_a_browser(cli, tmp_path):
    result, out = report(cli, tmp_path)
    assert result.exit_code == 0, result.stderr
    shot = tmp_path / "shot.png"
    subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                    "--disable-background-networking", f"--user-data-dir={tmp_path / 'ud'}",
                    f"--screenshot={shot}", "--window-size=1000,1400", out.as_uri()],
                   check=True, timeout=120, capture_output=True)
    data = shot.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000  # more than a blank page


def test_fleet_run_report_gathers_every_robot_the_worst_first(tmp_path):
    """Two robots' agents over Zenoh (one whose link limits it cannot meet): one fleet
    report, a table per robot, the failing one first."""
    pytest.importorskip("zenoh")
    from deltoctl.fleet import lab
    from tests.fleet.test_fleet import deltoctl

    relaxed = hand(tmp_path)
    strict = tmp_path / "strict.yaml"  # a round trip under a nanosecond: never met
    strict.write_text(Path(relaxed).read_text().replace("rtt_p50_ms: 1000", "rtt_p50_ms: 1e-6"))
    router = lab.Router()
    agent_config = lab.write_config(tmp_path / "agent.json5", "client",
                                    connect=[router.endpoint])
    config = lab.write_config(tmp_path / "caller.json5", "client", connect=[router.endpoint])
    agents = [lab.AgentProcess(robot, profile, ["--allow-unauthenticated-motion"],
                               cwd=str(tmp_path), config=agent_config)
              for robot, profile in (("hand-a", relaxed), ("hand-b", str(strict)))]
    try:
        for agent in agents:
            agent.wait_ready()
        result = deltoctl("--zenoh-config", str(config), "fleet", "run", "report", "--json",
                          cwd=str(tmp_path))
    finally:
        for agent in agents:
            agent.stop()
        router.close()
    assert result.returncode == 1, result.stderr
    doc = unwrap(json.loads(result.stdout))
    assert doc["kind"] == "deltoctl_fleet_report" and doc["verdict"] == "fail"
    assert [r["robot"] for r in doc["robots"]] == ["hand-b", "hand-a"]  # the worst first
    worst, best = doc["robots"]
    assert worst["failed"] == ["link.dg4f_driver.rtt_p50"] and worst["exit_code"] == 1
    assert best["verdict"] == "pass" and best["report"]["header"]["profile"]["name"] == "dg-4f"
    assert doc["report_sha256"] == report_hash(doc)
    (page,) = tmp_path.glob("fleet-report-*.html")
    text, tree = parse_html(page)
    assert_self_contained(text, tree)
    assert [h.text.strip() for h in tree.findall(".//h2[@class='robot']")] == ["hand-b",
                                                                               "hand-a"]
