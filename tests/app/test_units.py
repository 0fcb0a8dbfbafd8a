"""Quantities are checked against the joint they move: an angle on a prismatic joint or a
length on a revolute one is refused (exit 2) naming the joint's unit, before anything moves;
moves are echoed in the unit typed (else degrees or millimetres)."""

from __future__ import annotations

import contextlib
import itertools
import json

import pytest

import deltoctl
from deltoctl.errors import InvalidInput
from deltoctl.profile.catalog import load_profile


@pytest.fixture
def served():
    """``serve(profile_name)``: the profile's simulated devices as `sim serve` starts them;
    returns the ``-t BUS=URL`` arguments."""
    from deltoctl.sim.serve import ServeOptions, serve_profile

    with contextlib.ExitStack() as stack:
        def serve(name):
            buses = serve_profile(stack, load_profile(name), ServeOptions())["buses"]
            return [a for bus, url in buses.items() for a in ("-t", f"{bus}={url}")]
        yield serve


def positions(cli, *args):
    """Every joint's position, as the devices report it now."""
    result = cli(*args, "--json", "stream", "-d", "0.05")
    assert result.exit_code == 0, result.stderr
    values = json.loads(result.stdout.splitlines()[-1])["values"]
    return {k: v for k, v in values.items() if k.endswith("/position")}


@pytest.mark.parametrize(("profile", "homed", "jog", "unit"), [
    ("bioscara-arm", "j2", ("j2", "--", "-5deg"), "a length in m or mm"),
    ("bioscara-arm", "j3", ("j3", "--", "-10mm"), "an angle in rad or deg"),
    ("dg-5f-right", None, ("rj_dg_2_2", "5mm"), "an angle in rad or deg"),
])
def test_a_unit_that_is_not_the_joints_is_refused_and_nothing_moves(cli, served, profile,
                                                                   homed, jog, unit):
    device = ("-p", profile, *served(profile))
    if homed:
        assert cli(*device, "home", "-j", homed, "--yes").exit_code == 0
    before = positions(cli, *device)
    result = cli(*device, "--yes", "jog", *jog)
    assert result.exit_code == 2, result.output
    assert unit in result.stderr and jog[0] in result.stderr
    assert positions(cli, *device) == pytest.approx(before, abs=1e-6)


def test_a_speed_in_mm_per_second_on_a_revolute_joint_is_refused(cli, served):
    device = ("-p", "dg-5f-right", *served("dg-5f-right"))
    before = positions(cli, *device)
    result = cli(*device, "--yes", "jog", "rj_dg_2_2", "5deg", "--velocity", "10mm/s")
    assert result.exit_code == 2
    assert "rad/s or deg/s" in result.stderr and "mm/s" in result.stderr
    assert positions(cli, *device) == pytest.approx(before, abs=1e-6)
    assert cli(*device, "--yes", "jog", "rj_dg_2_2", "5deg", "--velocity",
               "20deg/s").exit_code == 0


def test_the_library_checks_units_against_the_joint():
    with deltoctl.open_robot("bioscara-arm", sim=True) as robot:
        robot.home(["j2", "j3"])
        before = robot.read()["j2/position"]
        with pytest.raises(InvalidInput, match="j2 is a prismatic joint"):
            robot.jog({"j2": "-5deg"})
        with pytest.raises(InvalidInput, match="j3 is a revolute joint"):
            robot.move({"j3": "10mm"})
        with pytest.raises(InvalidInput, match="m/s or mm/s"):
            robot.move({"j2": "10mm"}, velocity="5deg/s")
        assert robot.read()["j2/position"] == pytest.approx(before, abs=1e-6)
        assert robot.jog_targets({"j2": "2mm"})["j2"] == pytest.approx(before + 0.002)


def test_a_jog_is_echoed_in_the_unit_typed(cli):
    """Without --yes and a terminal the move is refused (exit 5), its description shown."""
    sim = ("--sim", "-p", "dg-5f-right")
    result = cli(*sim, "jog", "rj_dg_2_2", "5deg")
    assert result.exit_code == 5
    assert "from 0.00° to 5.00° (+5.00°)" in result.stderr
    result = cli(*sim, "jog", "rj_dg_2_2", "0.1")  # a bare number: rad, shown in degrees
    assert "(+5.73°)" in result.stderr
    result = cli(*sim, "jog", "rj_dg_2_2", "0.1rad")
    assert "(+0.1000 rad)" in result.stderr


def test_a_prismatic_jog_is_echoed_in_millimetres():
    from deltoctl.app.motion import jog_targets

    with deltoctl.open_robot("bioscara-arm", sim=True) as robot:
        robot.home(["j2"])
        start = robot.read()["j2/position"]
        _, moves = jog_targets(robot.system, [("j2", "2mm")])
        assert f"to {(start + 0.002) * 1000:.2f} mm (+2.00 mm)" in moves[0]
        _, moves = jog_targets(robot.system, [("j2", "-0.001")])  # metres, shown in mm
        assert "(-1.00 mm)" in moves[0]


def test_a_home_pose_in_mm_on_a_revolute_joint_is_a_profile_error(cli, tmp_path):
    text = load_profile("bioscara-arm").source
    with open(text, encoding="utf-8") as f:
        lines = f.read().splitlines()
    at = next(n for n, line in enumerate(lines) if line.strip().startswith("max_jog_step"))
    lines.insert(at + 1, "  home_pose: {j1: 5mm}")
    bad = tmp_path / "arm.yaml"
    bad.write_text("\n".join(lines) + "\n", encoding="utf-8")
    result = cli("-p", str(bad), "profile", "validate")
    assert result.exit_code == 2
    assert f"{bad}:{at + 2}:" in result.stderr
    assert "j1 is a revolute joint" in result.stderr
    lines[at] = "  max_jog_step: 5mm"
    bad.write_text("\n".join(lines).replace("{j1: 5mm}", "{j2: 5mm}") + "\n",
                   encoding="utf-8")
    result = cli("-p", str(bad), "profile", "validate")
    assert result.exit_code == 2
    assert f"{bad}:{at + 1}:" in result.stderr and "max_jog_step" in result.stderr
    assert "j1 is a revolute joint" in result.stderr
    lines[at] = "  home_tolerance: 2deg"  # j2 is prismatic
    bad.write_text("\n".join(lines).replace("{j1: 5mm}", "{j2: 5mm}") + "\n",
                   encoding="utf-8")
    result = cli("-p", str(bad), "profile", "validate")
    assert result.exit_code == 2
    assert f"{bad}:{at + 1}:" in result.stderr and "j2 is a prismatic joint" in result.stderr


def test_replay_tolerances_are_in_the_unit_of_the_replayed_joints(cli, tmp_path):
    out = tmp_path / "jog.mcap"
    assert cli("-p", "dg-3f-m", "--sim", "--yes", "jog", "j_dg_1_2", "10deg", "--record",
               str(out)).exit_code == 0
    for option in ("--tolerance", "--max-deviation"):
        result = cli("replay", str(out), option, "1mm")
        assert result.exit_code == 2, result.output
        assert "j_dg_1_2 is a revolute joint" in result.stderr and option in result.stderr
    result = cli("replay", str(out), "--tolerance", "3deg")
    assert result.exit_code == 0, result.stderr
    assert "°" in result.stdout  # the differences in the unit of --tolerance


def test_the_stream_tables_headers_carry_units(cli):
    from rich.console import Console

    from deltoctl.render.stream import live_tables

    result = cli("--sim", "-p", "bioscara-dg-3f-m", "--json", "stream", "-d", "0.05")
    sample = json.loads(result.stdout.splitlines()[-1])["values"]
    sample["j1/position"], sample["j2/position"] = 0.5, 0.0123
    types = {j.name: j.joint_type for j in load_profile("bioscara-dg-3f-m").joints()}
    console = Console(record=True, width=200)
    console.print(live_tables(sample, "units", types))
    lines = console.export_text().splitlines()
    headers = [(name, unit) for above, below in itertools.pairwise(lines)
               for name, unit in zip(above.split(), below.split()) if unit.startswith("(")]
    assert ("position", "(deg)") in headers and ("position", "(mm)") in headers
    assert ("velocity", "(deg/s)") in headers and ("velocity", "(mm/s)") in headers
    assert ("force.x", "(N)") in headers and ("torque.z", "(N·m)") in headers
    rows = {line.split()[0]: line.split()[1:] for line in lines if line.strip()}
    assert rows["j1"][0] == "28.65"  # 0.5 rad in degrees, two decimals
    assert rows["j2"][0] == "12.30"  # 0.0123 m in millimetres
    assert rows["j3"][0] == "0.00"


def test_a_refused_jog_says_its_values_in_degrees_too(cli):
    result = cli("--sim", "-p", "dg-5f-right", "--yes", "jog", "rj_dg_2_2", "--", "-10deg")
    assert result.exit_code == 5
    assert "rad (-10.00° outside [0.00°, 115.00°])" in result.stderr
    result = cli("--sim", "-p", "dg-5f-right", "--yes", "jog", "rj_dg_2_2", "40deg")
    assert result.exit_code == 5 and "(40.00° > 30.00°)" in result.stderr
