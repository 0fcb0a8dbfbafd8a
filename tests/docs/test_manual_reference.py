"""The manual's reference is generated from deltoctl itself (docs/hooks/reference.py, run by
`mkdocs build`): every verb and sub-command, every JSON Schema and every help topic is in it."""

from __future__ import annotations

import importlib.util
import re

import pytest

from deltoctl import verbs
from deltoctl.errors import EXIT_CODES
from deltoctl.schemas_lookup import SCHEMAS
from deltoctl.topics_lookup import topic_names, topic_text
from tests.conftest import REPO

spec = importlib.util.spec_from_file_location("docs_reference", REPO / "docs/hooks/reference.py")
reference = importlib.util.module_from_spec(spec)
spec.loader.exec_module(reference)


def test_every_verb_is_in_the_command_reference():
    text = reference.cli_reference()
    for path, entry in verbs.walk():
        assert f"deltoctl {path}\n" in text, path
        if entry.example:
            assert entry.example in text
    assert "`--profile`, `-p`" in text  # the global options


def test_every_schema_and_exit_code_is_in_the_reference():
    text = reference.schemas_reference()
    for path in SCHEMAS.glob("*.json"):
        assert f"## {path.stem.replace('-', ' ')}\n" in text
    codes = reference.exit_codes()
    assert all(f"| {code} | {meaning} |" in codes for code, meaning in EXIT_CODES)


def test_each_help_topic_is_a_page_of_the_manual():
    marked = {m for page in (REPO / "docs").rglob("*.md")
              for m in re.findall(r"<!-- deltoctl: topic ([a-z-]+) -->", page.read_text())}
    assert marked == set(topic_names())
    assert reference.generate("topic", "targets") == topic_text("targets")


def test_an_unknown_marker_stops_the_build():
    with pytest.raises(ValueError):
        reference.generate("nothing")
