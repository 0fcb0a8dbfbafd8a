"""The shape deltoctl's code keeps: typed above the device layers (a ``type: ignore`` only
where a library leaves no other way, with its reason), and a command line of short functions
(parse, confirm, call the library, render, exit code)."""

from __future__ import annotations

import ast
import re

from tests.conftest import REPO

PACKAGE = REPO / "deltoctl"
DEVICE_LAYERS = ("core", "families", "transport")
IGNORE = re.compile(r"#\s*type:\s*ignore(\[[\w,-]+\])?(?P<why>.*)$")
MAX_IGNORES = 5
MAX_CLI_FUNCTION_LINES = 60


def _ignores() -> list[tuple[str, str]]:
    """(file:line, the reason given after it) of each type: ignore above the device layers."""
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.relative_to(PACKAGE).parts[0] in DEVICE_LAYERS:
            continue
        for number, line in enumerate(path.read_text().splitlines(), 1):
            match = IGNORE.search(line)
            if match:
                found.append((f"{path.relative_to(REPO)}:{number}", match["why"].strip(" #")))
    return found


def test_few_type_ignores_above_the_device_layers_each_with_its_reason():
    ignores = _ignores()
    assert len(ignores) <= MAX_IGNORES, ignores
    assert [where for where, why in ignores if not why] == []


def test_the_pattern_finds_an_ignore_and_its_reason():
    assert IGNORE.search("x = f()  # type: ignore[attr-defined]  # untyped C module")["why"]
    assert not IGNORE.search("x = f()  # type: ignore")["why"]


def _long_functions(limit: int) -> list[str]:
    long = []
    for path in sorted((PACKAGE / "cli").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = node.end_lineno - node.lineno + 1
                if lines > limit:
                    long.append(f"{path.name}:{node.name} ({lines} lines)")
    return long


def test_no_function_of_the_command_line_is_over_60_lines():
    assert _long_functions(MAX_CLI_FUNCTION_LINES) == []
    assert _long_functions(20)  # the walk sees the functions (and their signatures)


MAX_CLI_LINES = 3000


def test_the_command_line_stays_a_thin_layer():
    """cli/ parses, confirms, calls the library and renders: at most MAX_CLI_LINES lines."""
    lines = sum(len(p.read_text().splitlines()) for p in (PACKAGE / "cli").glob("*.py"))
    assert 500 < lines <= MAX_CLI_LINES


def test_no_block_above_cyclomatic_grade_c_in_the_front_layers():
    """radon's grade of each function and class of cli/, app/ and render/: C at worst."""
    from radon.complexity import cc_rank, cc_visit

    def graded(layer: str) -> list[tuple[str, str]]:
        return [(f"{path.relative_to(PACKAGE)}:{block.fullname}", cc_rank(block.complexity))
                for path in (PACKAGE / layer).rglob("*.py")
                for top in cc_visit(path.read_text())
                for block in [top, *getattr(top, "methods", [])]]

    front = [g for layer in ("cli", "app", "render") for g in graded(layer)]
    assert len(front) > 100
    assert [(where, rank) for where, rank in front if rank > "C"] == []
    tangled = "def f(x):\n" + "".join(f"    if x == {i}:\n        return {i}\n" for i in range(25))
    assert cc_rank(cc_visit(tangled)[0].complexity) == "D"  # what the walk would catch


def test_no_verb_of_the_command_line_reaches_past_the_robot():
    """cli/ drives the robot through the library's Robot, never its System: what a verb does,
    a script or the fleet agent can do through the same methods."""
    found = [f"{p.name}:{n}" for p in sorted((PACKAGE / "cli").glob("*.py"))
             for n, line in enumerate(p.read_text().splitlines(), 1) if "robot.system" in line]
    assert found == []
