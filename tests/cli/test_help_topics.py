"""What a wheel user has: `deltoctl help TOPIC` prints the texts shipped in deltoctl/topics/
(the manual includes the same files), `help examples` lists the shipped examples and copies
them out, and no hint in the code sends a user to a README they do not have."""

from __future__ import annotations

import json
import re
import stat

import pytest

from deltoctl.topics_lookup import TOPICS, examples_dir, topic_names
from tests.conftest import REPO

EXAMPLES = sorted(p.name for p in (REPO / "examples").iterdir() if p.is_file())


def test_the_topics_a_hint_names_are_shipped():
    assert {"trust-model", "security", "shell-completion", "targets", "pytest",
            "global-options", "diagnostics"} <= set(topic_names())


@pytest.mark.parametrize("topic", topic_names())
def test_help_prints_each_topic(cli, topic):
    result = cli("help", topic)
    assert result.exit_code == 0, result.output
    assert result.stdout == (TOPICS / f"{topic}.md").read_text()
    document = json.loads(cli("help", topic, "--json").stdout)
    assert document["result"]["topic"] == topic
    assert document["result"]["text"].startswith("# ")


def test_the_exit_codes_and_the_trust_models_limits_stay_topics(cli):
    assert "refused for safety" in cli("help", "exit-codes").stdout
    assert "16 MiB" in cli("help", "trust-model").stdout


def test_an_unknown_topic_names_the_nearest(cli):
    result = cli("help", "trust-modle")
    assert result.exit_code == 2
    assert "trust-model" in result.stderr


def test_help_examples_lists_every_shipped_example(cli):
    result = cli("help", "examples")
    assert result.exit_code == 0
    for name in EXAMPLES:
        assert name in result.stdout
    document = json.loads(cli("help", "examples", "--json").stdout)["result"]
    assert [e["file"] for e in document["examples"]] == EXAMPLES
    assert all(e["what"] for e in document["examples"])
    assert document["copied"] == []


def test_help_examples_copy_writes_them_and_refuses_to_overwrite(cli, tmp_path):
    dest = tmp_path / "ex"
    result = cli("help", "examples", "--copy", str(dest))
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in dest.iterdir()) == EXAMPLES
    for name in EXAMPLES:
        assert (dest / name).read_bytes() == (REPO / "examples" / name).read_bytes()
    assert (dest / "bringup.sh").stat().st_mode & stat.S_IXUSR  # still runnable
    (dest / "bringup.sh").write_text("edited")
    again = cli("help", "examples", "--copy", str(dest))
    assert again.exit_code == 2 and "--force" in again.stderr
    assert (dest / "bringup.sh").read_text() == "edited"  # nothing written
    forced = cli("help", "examples", "--copy", str(dest), "--force")
    assert forced.exit_code == 0
    assert (dest / "bringup.sh").read_bytes() == (REPO / "examples" / "bringup.sh").read_bytes()


def test_copy_goes_with_examples_only(cli, tmp_path):
    assert cli("help", "jog", "--copy", str(tmp_path)).exit_code == 2
    afile = tmp_path / "f"
    afile.write_text("")
    assert cli("help", "examples", "--copy", str(afile)).exit_code == 2


def test_the_wheel_ships_the_examples():
    tomllib = pytest.importorskip("tomllib")
    wheel = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["hatch"]["build"]
    assert wheel["targets"]["wheel"]["force-include"]["examples"] == "deltoctl/_data/examples"
    assert examples_dir() == REPO / "examples"  # a source checkout: the folder itself


def test_no_hint_in_the_code_sends_a_user_to_the_readme():
    own = re.compile(r"(\bthe|\bsee|\()\s*README")
    found = [f"{path.relative_to(REPO)}:{n}" for path in (REPO / "deltoctl").rglob("*.py")
             for n, line in enumerate(path.read_text().splitlines(), 1) if own.search(line)]
    assert not found
