"""The live table of a stream fits the terminal it is drawn on: long tables side by side when
the width allows, else cut with a line saying how many rows are left out and how to pick fewer;
sensors and GPIOs always in view; a line saying how to stop."""

import json
import os

import pytest
from rich.console import Console

from deltoctl.render.stream import fit_rows, live_tables


@pytest.fixture(scope="module")
def samples():
    from typer.testing import CliRunner

    from deltoctl.cli.main import app

    out = {}
    for profile in ("mh5", "dg-5f-right"):
        result = CliRunner().invoke(app, ["-p", profile, "--sim", "stream", "-d", "0.05"])
        out[profile] = json.loads(result.stdout.splitlines()[-1])["values"]
    return out


def _drawn(sample: dict, width: int, height: int) -> list[str]:
    with open(os.devnull, "w") as devnull:
        console = Console(record=True, width=width, height=height, file=devnull)
        console.print(live_tables(sample, "9 samples at 50 Hz", live=True))
    return console.export_text().splitlines()


def test_mh5_at_80x24_shows_the_imu_and_says_what_it_leaves_out(samples):
    lines = _drawn(samples["mh5"], 80, 24)
    assert len(lines) <= 24 and max(len(line) for line in lines) <= 80
    text = "\n".join(lines)
    assert "9 samples at 50 Hz · links up" in lines[0]
    for shown in ("head_p", "orientation.w", "angular_velocity.z", "linear_acceleration.z"):
        assert shown in text
    hidden = [line for line in lines if "more rows" in line]
    assert len(hidden) == 1 and "narrow with -i 'PATTERN'" in hidden[0]
    count = int(hidden[0].split()[0])
    joints = [line.split()[0] for line in lines if line.startswith((" l_", " r_", " head"))]
    assert count + len(joints) == 22 and "r_ank_r" in hidden[0]  # the last one left out
    assert lines[-1] == "Ctrl-C to stop"


def test_mh5_at_120x40_shows_every_row(samples):
    lines = _drawn(samples["mh5"], 120, 40)
    assert len(lines) <= 40 and max(len(line) for line in lines) <= 120
    text = "\n".join(lines)
    assert "more rows" not in text and "r_ank_r" in text and "linear_acceleration.z" in text


def test_dg_5f_at_80x24_keeps_every_fingertip_and_the_gpio(samples):
    lines = _drawn(samples["dg-5f-right"], 80, 24)
    assert len(lines) <= 24 and max(len(line) for line in lines) <= 80
    text = "\n".join(lines)
    for shown in [f"right_fingertip_finger_{i}" for i in range(1, 6)] + ["input_1", "gpio"]:
        assert shown in text
    assert "torque.z" in text and "more rows" not in text  # every fingertip row in view
    assert any(line.endswith("rj_dg_5_4): narrow with -i 'PATTERN'") for line in lines)


def test_a_wide_terminal_puts_the_joints_side_by_side(samples):
    lines = _drawn(samples["dg-5f-right"], 140, 28)
    assert len(lines) <= 28 and "more rows" not in "\n".join(lines)
    beside = [line for line in lines if line.count("rj_dg_") == 2]
    assert len(beside) == 10 and beside[0].split()[0] == "rj_dg_1_1"
    assert beside[0].split()[5] == "rj_dg_3_3"  # the second half of the rows, to its right


def test_printed_for_a_file_nothing_is_left_out(samples):
    with open(os.devnull, "w") as devnull:
        console = Console(record=True, width=80, height=24, file=devnull)
        console.print(live_tables(samples["mh5"], "all"))
    text = console.export_text()
    assert "r_ank_r" in text and "more rows" not in text and "Ctrl-C" not in text


@pytest.mark.parametrize(("spans", "height", "plan"), [
    ([(22, 1, 1, 2), (1, 3, 1, 2)], 40, [(1, 22), (1, 1)]),  # fits: as it is
    ([(22, 1, 2, 2), (1, 1, 1, 2)], 20, [(2, 22), (1, 1)]),  # side by side: 2 + 11, 3
    ([(22, 1, 1, 2), (5, 2, 1, 2), (1, 1, 1, 2)], 22, [(1, 2), (1, 5), (1, 1)]),  # joints cut
    ([(20, 1, 3, 2), (5, 1, 3, 2)], 9, [(3, 6), (3, 5)]),  # cut a line per group: 6 of 20
    ([(3, 1, 1, 2), (2, 1, 1, 2)], 2, [(1, 0), (1, 1)]),  # the most rows all cut, a row kept
    ([(20, 1, 1, 3), (5, 2, 1, 3), (1, 1, 1, 2)], 20, [(1, 0), (1, 5), (1, 1)]),  # F/T stay
    ([(20, 1, 1, 3), (1, 1, 1, 2)], 12, [(1, 5), (1, 1)]),  # units below names: 3 + 5 + 1, 3
])
def test_fit_rows(spans, height, plan):
    assert fit_rows(spans, height) == plan
