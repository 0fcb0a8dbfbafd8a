"""record and jog --record never overwrite a file unasked (exit 2 unless --force), and fill
{time} (UTC) and {serial} (each block's serial, else its target's address) in the name."""

from __future__ import annotations

import json
import re

from deltoctl.families.delto.emulator import DeltoServer, firmware_for_profile
from deltoctl.profile.catalog import load_profile


def test_record_onto_an_existing_file_is_refused_and_leaves_it(cli, tmp_path):
    out = tmp_path / "run.mcap"
    out.write_bytes(b"precious")
    result = cli("-p", "rrbot-gpio", "record", str(out), "-d", "0.1")
    assert result.exit_code == 2
    assert "exists" in result.stderr and "--force" in result.stderr
    assert out.read_bytes() == b"precious"
    forced = cli("-p", "rrbot-gpio", "record", str(out), "-d", "0.1", "--force")
    assert forced.exit_code == 0, forced.stderr
    assert out.read_bytes()[:8] != b"precious"


def test_jog_record_onto_an_existing_file_is_refused_unless_forced(cli, tmp_path):
    out = tmp_path / "jog.mcap"
    out.write_bytes(b"precious")
    args = ("-p", "rrbot-gpio", "-y", "jog", "joint1", "0.05", "--record", str(out))
    result = cli(*args)
    assert result.exit_code == 2
    assert out.read_bytes() == b"precious"
    assert cli(*args, "--force").exit_code == 0
    assert out.read_bytes()[:8] != b"precious"


def test_time_and_serial_fill_the_name(cli, tmp_path):
    firmware = firmware_for_profile(load_profile("dg-5f-right"))
    with DeltoServer(firmware) as server:
        result = cli("-p", "dg-5f-right", "-t", server.endpoint, "record",
                     str(tmp_path / "hand-{serial}-{time}.mcap"), "-d", "0.1", "--json")
    assert result.exit_code == 0, result.stderr
    written = json.loads(result.stdout)["result"]["output"]
    port = server.endpoint.rsplit(":", 1)[1]
    assert re.fullmatch(rf".*/hand-127\.0\.0\.1-{port}-\d{{8}}T\d{{6}}Z\.mcap", written), written
    assert [p.name for p in tmp_path.iterdir()] == [written.rsplit("/", 1)[1]]


def test_a_serial_name_that_exists_is_refused_once_the_blocks_answer(cli, tmp_path):
    first = cli("-p", "rrbot-gpio", "record", str(tmp_path / "r-{serial}.mcap"), "-d", "0.1")
    assert first.exit_code == 0, first.stderr
    again = cli("-p", "rrbot-gpio", "record", str(tmp_path / "r-{serial}.mcap"), "-d", "0.1")
    assert again.exit_code == 2
    assert "exists" in again.stderr
    assert len(list(tmp_path.iterdir())) == 1
