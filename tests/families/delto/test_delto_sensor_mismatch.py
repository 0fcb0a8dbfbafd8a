"""A Delto gripper whose fingertip sensors are not the profile's: every verb warns (exit 3),
naming the declared values its replies leave empty — as a model mismatch does."""

from __future__ import annotations

import json

import pytest

from deltoctl.families.delto.emulator import DeltoServer, firmware_for_profile
from deltoctl.families.delto.models import FT_6AXIS, TACTILE_M
from deltoctl.profile.catalog import load_profile
from deltoctl.record.reader import open_recording

VERBS = (("identify",), ("detect",), ("stream", "-d", "0.1"), ("connect", "-n", "2"))


def _run(cli, profile, server, *verb):
    return cli("-p", profile, "-t", server.endpoint, *verb, "--json")


@pytest.mark.parametrize("verb", VERBS, ids=lambda v: v[0])
def test_f_t_from_the_short_version_reply_where_the_profile_declares_grids(cli, verb):
    firmware = firmware_for_profile(load_profile("dg-5f-s-right"), sensor_type=FT_6AXIS,
                                    short_version=True)  # old firmware: F/T fingertips
    with DeltoServer(firmware) as server:
        result = _run(cli, "dg-5f-s-right", server, *verb)
    assert result.exit_code == 3, result.stderr
    assert "fingertip sensor mismatch" in result.stderr
    assert "implied by its short version reply" in result.stderr
    assert "right_tactile_finger_1/*" in result.stderr
    assert "right_tactile_finger_5/*" in result.stderr
    document = result.stderr if verb[0] == "stream" else result.stdout
    envelope = json.loads(document.strip().splitlines()[-1] if verb[0] == "stream"
                          else document)
    assert envelope["exit_code"] == 3
    assert any("right_tactile_finger_3/*" in w for w in envelope["warnings"])


def test_tactile_grids_where_the_profile_declares_f_t_sensors(cli):
    firmware = firmware_for_profile(load_profile("dg-5f-right"), sensor_type=TACTILE_M)
    with DeltoServer(firmware) as server:
        result = _run(cli, "dg-5f-right", server, "identify")
    assert result.exit_code == 3, result.stderr
    warning = json.loads(result.stdout)["warnings"][0]
    assert "the profile declares F/T sensors" in warning
    assert "reports TACTILE_M" in warning
    assert all(f"right_fingertip_finger_{f}/*" in warning for f in range(1, 6))


def test_a_recording_of_the_wrong_sensors_warns_and_says_so(cli, tmp_path):
    firmware = firmware_for_profile(load_profile("dg-5f-s-right"), sensor_type=FT_6AXIS)
    out = tmp_path / "run.mcap"
    with DeltoServer(firmware) as server:
        result = cli("-p", "dg-5f-s-right", "-t", server.endpoint, "record", str(out),
                     "-d", "0.2", "--json")
    assert result.exit_code == 3, result.stderr
    assert "right_tactile_finger_2/*" in result.stderr
    assert json.loads(result.stdout)["exit_code"] == 3
    recording = open_recording(out)  # the file is a valid recording all the same
    assert recording.indexed and recording.messages > 0


def test_the_sensors_the_profile_declares_give_no_warning(cli):
    firmware = firmware_for_profile(load_profile("dg-5f-s-right"))
    with DeltoServer(firmware) as server:
        result = _run(cli, "dg-5f-s-right", server, "identify")
    assert result.exit_code == 0, result.stderr
    assert json.loads(result.stdout)["warnings"] == []
