"""deltoctl report as it runs and when it fails: its stages on stderr, a servo that does not
answer as a failing row named by its joint (judged as detect judges it), SIMULATED beside the
verdict of a rehearsal, identity fields as words."""

from __future__ import annotations

import json
import re
from pathlib import Path

from tests.app.test_report import RELAXED, hand, parse_html, unwrap
from tests.conftest import REPO, mh5_targets

MISSING = ("--sim", "--sim-option", "missing=head_y")
HEAD_Y = "detect.upper_body.head_y"


def mh5(tmp_path):
    """The MH5's profile with relaxed timing limits."""
    path = tmp_path / "mh5.yaml"
    path.write_text((REPO / "profiles" / "mh5.yaml").read_text() + RELAXED % "")
    return str(path)


def check_row(tree, check_id):
    """The cells of the HTML report's row of check ``check_id``."""
    for row in tree.findall(".//table[@id='checks']//tr[@class='check']"):
        cells = row.findall("td")
        if cells[0].find("code").text == check_id:
            return cells
    raise AssertionError(f"no row {check_id}")


def test_a_servo_that_does_not_answer_is_a_failing_row_named_by_its_joint(cli, tmp_path):
    out = tmp_path / "r.html"
    result = cli("-p", mh5(tmp_path), *MISSING, "report", "-o", str(out), "--json")
    assert result.exit_code == 1, result.stderr
    assert f"acceptance failed: {HEAD_Y}: head_y (ID 52) does not answer" in result.stderr
    doc = unwrap(json.loads(result.stdout))
    assert doc["failed"] == [HEAD_Y]
    row = next(c for c in doc["checks"] if c["id"] == HEAD_Y)
    assert (row["what"], row["value"], row["verdict"]) == (
        "head_y (ID 52) does not answer", "no answer", "fail")
    answering = next(c for c in doc["checks"] if c["id"] == "detect.upper_body.head_p")
    assert answering["verdict"] == "pass"
    _, tree = parse_html(out)
    cells = check_row(tree, HEAD_Y)
    assert cells[1].text == "head_y (ID 52) does not answer"
    assert cells[-1].find("span").get("class") == "fail"


def test_the_terminal_shows_the_stages_the_failing_row_and_simulated(cli, tmp_path):
    result = cli("-p", mh5(tmp_path), *MISSING, "report", "-o", str(tmp_path / "r.html"))
    assert result.exit_code == 1, result.stderr
    row = next(line for line in result.stdout.splitlines() if line.startswith(HEAD_Y))
    assert row.split()[-1] == "FAIL" and "no answer" in row
    assert "verdict: SIMULATED (upper_body, lower_body, i2c): FAIL" in result.stdout
    stages = [line.removeprefix("report: ") for line in result.stderr.splitlines()
              if line.startswith("report: ")]
    assert stages[:7] == ["connect", "identify", "detect", "configuration",
                          "link quality: upper_body", "link quality: lower_body",
                          "link quality: i2c"]
    assert stages[7] == "sensors"  # no motion without --yes


def test_detect_and_report_judge_a_missing_servo_alike(cli, tmp_path):
    detect = cli("-p", mh5(tmp_path), *MISSING, "detect", "--json")
    assert detect.exit_code == 1, detect.stderr
    assert f"{HEAD_Y}: head_y (ID 52) does not answer" in detect.stderr
    found = json.loads(detect.stdout)
    assert found["result"]["failed"] == [HEAD_Y] and found["exit_code"] == 1
    result = cli("-p", mh5(tmp_path), *MISSING, "report", "-o", str(tmp_path / "r.html"),
                 "--json")
    doc = unwrap(json.loads(result.stdout))
    in_report = [c for c in doc["checks"] if c["id"].startswith("detect.")]
    assert sorted(in_report, key=lambda c: c["id"]) == sorted(found["result"]["checks"],
                                                             key=lambda c: c["id"])


def test_a_servo_the_profile_does_not_declare_warns_in_both(cli, tmp_path, mh5_buses):
    from deltoctl.families.dynamixel.emulator import Servo

    mh5_buses["upper_body"].bus.servos[99] = Servo(99)
    targets = mh5_targets(mh5_buses)
    detect = cli("-p", mh5(tmp_path), *targets, "detect", "--json")
    assert detect.exit_code == 3, detect.stderr
    assert "detect.upper_body.id_99: ID 99: XL430-W250 (1060), the profile says no servo" \
        in detect.stderr
    out = tmp_path / "r.html"
    result = cli("-p", mh5(tmp_path), *targets, "report", "-o", str(out), "--json")
    assert result.exit_code == 3, result.stderr
    doc = unwrap(json.loads(result.stdout))
    assert doc["verdict"] == "warn" and doc["failed"] == []
    assert next(c for c in doc["checks"] if c["id"] == "detect.upper_body.id_99")[
        "verdict"] == "warn"
    assert doc["simulated"] == []  # devices behind their links: no rehearsal
    text, tree = parse_html(out)
    assert tree.find(".//span[@id='simulated']") is None and "SIMULATED" not in text


def test_a_rehearsal_says_simulated_where_the_verdict_is(cli, tmp_path):
    out = tmp_path / "r.html"
    result = cli("-p", hand(tmp_path), "--sim", "report", "-o", str(out), "--json")
    assert result.exit_code == 0, result.stderr
    doc = unwrap(json.loads(result.stdout))
    assert doc["verdict"] == "pass" and doc["simulated"] == ["dg4f_driver"]
    _, tree = parse_html(out)
    assert tree.find(".//span[@id='simulated']").text == "SIMULATED"
    assert "(SIMULATED)" in tree.find(".//title").text
    assert "rehearsal" in tree.find(".//p[@class='simulated-note']").text


def test_the_stages_of_motion_show_per_block_and_json_shows_none(cli, tmp_path):
    profile = hand(tmp_path, ", homes: 1")
    result = cli("-p", profile, "--sim", "--yes", "report", "-o", str(tmp_path / "m.html"))
    assert result.exit_code == 0, result.stderr
    stages = [line.removeprefix("report: ") for line in result.stderr.splitlines()
              if line.startswith("report: ")]
    assert stages[stages.index("motion: dg4f_driver"):stages.index("sensors")] == [
        "motion: dg4f_driver", "motion: dg4f_driver: return home 1 of 1",
        "motion: dg4f_driver: 18 joints to their lower soft limits",
        "motion: dg4f_driver: 18 joints to their upper soft limits"]
    quiet = cli("-p", profile, "--sim", "report", "-o", str(tmp_path / "j.html"), "--json")
    assert quiet.exit_code == 0, quiet.stderr
    assert not any(line.startswith("report: ") and "j.html" not in line
                   for line in quiet.stderr.splitlines())
    unwrap(json.loads(quiet.stdout))  # stdout holds the document only


def test_identity_fields_read_as_words(cli, tmp_path):
    out = tmp_path / "r.html"
    assert cli("-p", hand(tmp_path), "--sim", "report", "-o", str(out)).exit_code == 0
    _, tree = parse_html(out)
    fields = {row.find("th").text: row.find("td") for row in tree.iter("tr")
              if row.find("th") is not None and row.find("td") is not None}
    assert "configured model" in fields and "configured_model" not in fields
    assert fields["model match"].text == "yes"
    identify = cli("-p", "dg-4f", "--sim", "identify")
    assert identify.exit_code == 0, identify.stderr
    assert re.search(r"^configured model +DG-4F", identify.stdout, re.M)
    assert re.search(r"^model match +yes$", identify.stdout, re.M)
    assert "configured_model" not in identify.stdout and "True" not in identify.stdout


def test_motion_checks_leave_out_a_servo_that_does_not_answer(cli, tmp_path):
    path = tmp_path / "mh5.yaml"
    path.write_text((REPO / "profiles" / "mh5.yaml").read_text() + RELAXED % ", homes: 1")
    result = cli("-p", str(path), *MISSING, "--yes", "report", "-o", str(tmp_path / "m.html"),
                 "--json")
    assert result.exit_code == 1, result.stderr
    assert "Traceback" not in result.stderr and "internal error" not in result.stderr
    doc = unwrap(json.loads(result.stdout))
    checks = {c["id"]: c for c in doc["checks"]}
    assert checks["motion.head_y"]["verdict"] == "skip"
    assert checks["motion.head_p.following_error"]["verdict"] == "pass"
    assert doc["failed"] == [HEAD_Y]


def test_a_figure_out_of_its_limit_is_named_with_its_value_and_limit(cli, tmp_path):
    strict = tmp_path / "strict.yaml"  # a round trip under a nanosecond: never met
    strict.write_text(Path(hand(tmp_path)).read_text().replace("rtt_p50_ms: 1000",
                                                               "rtt_p50_ms: 1e-6"))
    result = cli("-p", str(strict), "--sim", "report", "-o", str(tmp_path / "r.html"))
    assert result.exit_code == 1, result.stderr
    assert re.search(r"acceptance failed: link\.dg4f_driver\.rtt_p50: dg4f_driver: round trip, "
                     r"median is [0-9.e-]+ ms, not ≤ 1e-06", result.stderr), result.stderr
