"""The manual's command examples run as documented: every ```console block marked
``<!-- runnable -->`` in docs/ is run, command by command, against the simulators (`--sim`) in
a folder of its own per page, and each command's exit code is the one the page gives (0, or
the ``# exit N`` / ``# exit N|M`` at the end of its line)."""

from __future__ import annotations

import importlib.util
import os
import re
import shlex
import subprocess
import sys

import pytest

from tests.conftest import REPO

DOCS = REPO / "docs"
RUNNABLE = re.compile(r"^<!-- runnable -->\n```(?:console|shell)\n(.*?)^```", re.S | re.M)
EXIT = re.compile(r"#.*\bexit (\d+(?:\|\d+)*)\s*$")


def commands(block: str) -> list[tuple[str, list[str], set[int]]]:
    """Each ``$ `` line of a block (with its ``\\`` continuations): the line, its argv and
    the exit codes the page gives it."""
    out = []
    for line in re.sub(r"\s*\\\n\s*", " ", block).splitlines():
        if not line.startswith("$ "):
            continue  # the output a page shows
        found = EXIT.search(line)
        codes = {int(c) for c in found.group(1).split("|")} if found else {0}
        out.append((line[2:], shlex.split(line[2:], comments=True), codes))
    return out


def pages() -> dict[str, list[tuple[str, list[str], set[int]]]]:
    found = {}
    for page in sorted(DOCS.rglob("*.md")):
        runs = [c for block in RUNNABLE.findall(page.read_text()) for c in commands(block)]
        if runs:
            found[str(page.relative_to(DOCS))] = runs
    return found


PAGES = pages()


def test_the_parser_reads_commands_continuations_and_exit_codes():
    block = "$ deltoctl -p x --sim \\\n    jog j 5deg -y   # refused: exit 5\noutput line\n" \
            "$ deltoctl report -o r.html     # exit 0|1\n$ deltoctl profile list\n"
    assert commands(block) == [
        ("deltoctl -p x --sim jog j 5deg -y   # refused: exit 5",
         ["deltoctl", "-p", "x", "--sim", "jog", "j", "5deg", "-y"], {5}),
        ("deltoctl report -o r.html     # exit 0|1", ["deltoctl", "report", "-o", "r.html"],
         {0, 1}),
        ("deltoctl profile list", ["deltoctl", "profile", "list"], {0})]


def test_the_first_steps_and_every_robot_page_have_runnable_examples():
    assert {"quickstart.md", "robots/1-delto-hand.md", "robots/2-dynamixel-arm.md",
            "robots/3-mh5.md", "robots/4-bioscara-arm.md",
            "robots/5-canopen-axis.md"} <= set(PAGES)


@pytest.mark.slow
@pytest.mark.parametrize("page", sorted(PAGES))
def test_the_commands_of_a_page_run_as_documented(page, tmp_path):
    if "canopen" in page and importlib.util.find_spec("deltoctl_canopen") is None:
        pytest.skip("the CANopen plugin is not installed")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(REPO), str(REPO / "plugins" / "deltoctl-canopen"),
         os.environ.get("PYTHONPATH", "")]),
        # what a page's calibrations save stays in its folder
        "XDG_DATA_HOME": str(tmp_path / "data"),
        "HF_LEROBOT_CALIBRATION": str(tmp_path / "lerobot")}
    for line, argv, codes in PAGES[page]:
        assert argv[0] == "deltoctl", f"{page}: a runnable block runs deltoctl only: {line}"
        assert "--sim" in argv or argv[1:2] in (["profile"], ["info"], ["help"]), \
            f"{page}: a runnable command runs on the simulators: {line}"
        result = subprocess.run([sys.executable, "-m", "deltoctl", *argv[1:]], cwd=tmp_path,
                                env=env, capture_output=True, text=True, timeout=180)
        assert result.returncode in codes, \
            f"{page}: `{line}` exited {result.returncode}: {result.stderr[-1500:]}"
