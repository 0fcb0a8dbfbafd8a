"""Every verb's --json in one envelope (verb, profile, blocks or result, warnings, exit_code),
valid against the JSON Schema shipped for it, on every catalog profile's simulator; an error
is one JSON object on stderr with stdout empty."""

from __future__ import annotations

import json

import pytest

from deltoctl.profile.catalog import catalog_names
from deltoctl.schemas_lookup import SCHEMAS, schema_file

jsonschema = pytest.importorskip("jsonschema")

DEVICE_VERBS = (("connect", "-n", "2"), ("identify",), ("detect",), ("gpio", "get"),
                ("config", "snapshot", "-o", "-"), ("doctor",))
KEYS = {"verb", "profile", "warnings", "exit_code"}
DATA = {"blocks", "result"}  # where a verb's data goes: nothing else beside the envelope's keys


def _valid(verb: str, document: dict) -> None:
    schema = json.loads(schema_file(verb).read_text())
    jsonschema.validate(document, schema)


def _check(result, verb: str) -> None:
    """The envelope on stdout, valid; or one error object on stderr and nothing on stdout."""
    if not result.stdout.strip():
        assert result.exit_code not in (0, 3), result.stderr
        _valid("error", json.loads(result.stderr.strip().splitlines()[-1]))
        return
    document = json.loads(result.stdout)
    assert set(document) - DATA == KEYS and set(document) & DATA, sorted(document)
    assert document["exit_code"] == result.exit_code
    _valid(verb, document)


@pytest.mark.parametrize("profile", catalog_names())
def test_every_device_verb_on_every_catalog_profile(cli, profile):
    for verb in DEVICE_VERBS:
        words = [w for w in verb if not w.startswith("-")]
        name = " ".join(words[:2] if words[0] in ("gpio", "config") else words[:1])
        _check(cli("-p", profile, "--sim", *verb, "--json"), name)


@pytest.mark.parametrize("profile", catalog_names())
def test_stream_frames_and_its_document(cli, profile):
    result = cli("-p", profile, "--sim", "stream", "-d", "0.1", "--rate", "50", "--json")
    assert result.exit_code in (0, 3), result.stderr
    frame_schema = json.loads(schema_file("stream frame").read_text())
    frames = [json.loads(line) for line in result.stdout.splitlines()]
    assert frames
    for frame in frames:
        jsonschema.validate(frame, frame_schema)
    document = json.loads(result.stderr.strip().splitlines()[-1])
    _valid("stream", document)
    assert document["result"]["samples"] == len(frames)


@pytest.mark.parametrize("profile", ["dg-5f-right", "mh5", "bioscara-dg-3f-m", "rrbot-gpio"])
def test_record_home_and_jog(cli, tmp_path, profile):
    _check(cli("-p", profile, "--sim", "record", str(tmp_path / "r.mcap"), "-d", "0.2",
               "--json"), "record")
    _check(cli("-p", profile, "--sim", "-y", "home", "--json"), "home")


def test_home_and_jog_have_one_shape_for_every_family(cli):
    """The envelope's keys, the blocks, and the move's outcome in ``result``."""
    shapes = set()
    for profile in ("bioscara-arm", "dg-5f-right", "rrbot-gpio"):
        result = cli("-p", profile, "--sim", "-y", "home", "--json")
        assert result.exit_code == 0, result.stderr
        _check(result, "home")
        document = json.loads(result.stdout)
        shapes.add((tuple(sorted(document)), tuple(sorted(document["result"]))))
    assert shapes == {(("blocks", "exit_code", "profile", "result", "verb", "warnings"),
                       ("cannot_home", "seconds", "settled", "unsettled"))}, shapes
    jogs = set()
    for profile, joint in (("rrbot-gpio", "joint1"), ("dg-5f-right", "rj_dg_2_2")):
        jog = cli("-p", profile, "--sim", "-y", "jog", joint, "0.05", "--json")
        assert jog.exit_code == 0, jog.stderr
        _check(jog, "jog")
        document = json.loads(jog.stdout)
        assert document["result"]["settled"] is True
        jogs.add((tuple(sorted(document)), tuple(sorted(document["result"]))))
    assert jogs == {(("blocks", "exit_code", "profile", "result", "verb", "warnings"),
                     ("seconds", "settled", "unsettled"))}, jogs


def test_every_schema_allows_the_envelope_keys_only():
    """A key a verb adds beside the envelope's fails its schema."""
    for path in SCHEMAS.glob("*.json"):
        schema = json.loads(path.read_text())
        if path.stem in ("error", "stream-frame"):
            continue
        assert schema["additionalProperties"] is False, path.name
        assert set(schema["properties"]) - DATA == KEYS, path.name
        assert set(schema["properties"]) & DATA, path.name


def test_a_calibration_says_whether_it_passed_in_its_result(cli):
    result = cli("-p", "dg-4f", "--sim", "--yes", "calibrate", "ft", "--json")
    assert result.exit_code == 0, result.stderr
    _check(result, "calibrate ft")
    assert json.loads(result.stdout)["result"] == {"pass": True}


@pytest.mark.parametrize("args,verb", [(("profile", "list"), "profile list"),
                                       (("profile", "show", "mh5"), "profile show"),
                                       (("help", "exit-codes"), "help")])
def test_verbs_without_a_device(cli, args, verb):
    _check(cli(*args, "--json"), verb)


def test_an_error_is_one_object_on_stderr_and_nothing_on_stdout(cli):
    result = cli("-p", "no-such-profile", "identify", "--json")
    assert result.exit_code == 2 and result.stdout == ""
    _valid("error", json.loads(result.stderr))


def test_help_schema_prints_the_shipped_schema(cli):
    result = cli("help", "schema", "gpio", "get")
    assert result.exit_code == 0
    assert json.loads(result.stdout) == json.loads((SCHEMAS / "gpio-get.json").read_text())
    assert cli("help", "schema", "gpio", "gett").exit_code == 2
    for path in SCHEMAS.glob("*.json"):  # each a valid JSON Schema
        jsonschema.Draft202012Validator.check_schema(json.loads(path.read_text()))
