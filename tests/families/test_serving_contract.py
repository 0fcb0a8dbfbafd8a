"""An emulator depends on the emulator contract (deltoctl.core.emulator_contract), never on the
simulators' server that builds the context it receives: a family in a package of its own
serves its devices without importing deltoctl.sim."""

from __future__ import annotations

import ast
import inspect
from pathlib import Path

import pytest

from deltoctl import registry
from deltoctl.core import emulator_contract
from tests.conftest import REPO

EMULATORS = sorted([*REPO.glob("deltoctl/families/*/*.py"),
                    *REPO.glob("plugins/*/*/emulator.py")])


def _imported(path: Path) -> list[str]:
    """Every module a file imports, those under ``if TYPE_CHECKING:`` included."""
    names: list[str] = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module:
            names.append(node.module)
        elif isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
    return names


def test_no_family_imports_the_simulators_server_even_for_its_types():
    assert len(EMULATORS) > 5
    found = {str(p.relative_to(REPO)): m for p in EMULATORS for m in _imported(p)
             if m == "deltoctl.sim" or m.startswith("deltoctl.sim.")}
    assert found == {}


@pytest.mark.parametrize("name", sorted(n for n, f in registry.families().items()
                                         if (f.emulator or "").startswith("deltoctl.")))
def test_each_emulator_takes_the_core_context(name):
    serve = registry.families()[name].emulator_function()
    assert serve is not None
    annotation = inspect.signature(serve).parameters["ctx"].annotation
    assert annotation == "ServeContext"
    assert serve.__globals__[annotation] is emulator_contract.ServeContext  # resolvable at run time


def test_the_context_offers_what_an_emulator_reads():
    """What the four emulators read of their context is declared in the contract."""
    declared = {n for n in dir(emulator_contract.ServeContext) if not n.startswith("_")}
    declared |= set(emulator_contract.ServeContext.__annotations__)
    read = set()
    for path in REPO.glob("deltoctl/families/*/emulator.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                    and node.value.id == "ctx"):
                read.add(node.attr)
    assert read and read <= declared
