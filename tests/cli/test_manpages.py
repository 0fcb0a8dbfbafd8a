"""The manual pages are made from the CLI, shipped current in completions/, and man renders
each one."""

from __future__ import annotations

import os
import re
import shutil
import subprocess

import pytest

from deltoctl import verbs
from deltoctl.cli.completion_cmd import manual_pages as pages
from tests.conftest import REPO

SHIPPED = REPO / "completions"


def test_shipped_manual_pages_are_current():
    made = pages()
    assert {p.name for p in SHIPPED.glob("*.1")} == set(made)
    for name, text in made.items():
        assert (SHIPPED / name).read_text() == text, f"{name}: run deltoctl completion man " \
                                                     "--out completions"


def test_a_page_per_verb_with_its_options_examples_and_exit_codes():
    made = pages()
    assert set(made) == {"deltoctl.1", *(f"deltoctl-{verb}.1" for verb in verbs.TABLE)}
    record = made["deltoctl-record.1"]
    assert r"\-\-force" in record and r"\-\-duration" in record
    assert ".SH EXIT STATUS" in record and "refused for safety" in record
    assert verbs.TABLE["record"].example.replace("-", r"\-") in record
    config = made["deltoctl-config.1"]
    assert ".SS config restore" in config and r"\-\-allow" in config


def test_completion_man_writes_them(cli, tmp_path):
    result = cli("completion", "man", "--out", str(tmp_path))
    assert result.exit_code == 0, result.stderr
    assert {p.name for p in tmp_path.iterdir()} == set(pages())
    assert cli("completion", "man").exit_code == 2  # no --out


@pytest.mark.skipif(shutil.which("man") is None, reason="no man on this machine")
@pytest.mark.parametrize("name", sorted(pages()))
def test_man_renders_each_page(name):
    result = subprocess.run(["man", "-l", str(SHIPPED / name)], capture_output=True, text=True,
                            env={**os.environ, "MANWIDTH": "80", "MAN_KEEP_FORMATTING": "0"},
                            timeout=60)
    assert result.returncode == 0, result.stderr
    text = re.sub(".\b", "", result.stdout)  # bold and underline drawn by overstriking
    assert "NAME" in text and "EXIT STATUS" in text
    assert "warning" not in result.stderr.lower(), result.stderr
