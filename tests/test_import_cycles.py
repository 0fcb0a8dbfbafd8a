"""No two modules of deltoctl (or of the CANopen plugin) import each other, directly or round a
longer loop: each module sits below the ones that use it. Imports inside functions count (they
run all the same, only later); imports under ``if TYPE_CHECKING:`` do not (they never run)."""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

from tests.conftest import REPO

PACKAGES = (REPO / "deltoctl", REPO / "plugins" / "deltoctl-canopen" / "deltoctl_canopen")


def _modules(roots: tuple[Path, ...]) -> dict[str, Path]:
    """Dotted name → file of every module under the package directories ``roots``."""
    found = {}
    for root in roots:
        for path in sorted(root.rglob("*.py")):
            parts = path.relative_to(root.parent).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            found[".".join(parts)] = path
    return found


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _nodes(tree: ast.AST) -> Iterator[ast.AST]:
    """Every node of ``tree`` except the bodies of ``if TYPE_CHECKING:`` (their else runs)."""
    stack = [tree]
    while stack:
        node = stack.pop()
        yield node
        if isinstance(node, ast.If) and _is_type_checking(node.test):
            stack.extend(node.orelse)
            continue
        stack.extend(ast.iter_child_nodes(node))


def _imported(name: str, path: Path, node: ast.AST, known: dict[str, Path]) -> Iterator[str]:
    """The dotted names one node of module ``name`` (file ``path``) imports, if it imports."""
    if isinstance(node, ast.Import):
        for alias in node.names:
            yield alias.name
    elif isinstance(node, ast.ImportFrom):
        if node.level:
            package = name if path.name == "__init__.py" else name.rpartition(".")[0]
            for _ in range(node.level - 1):
                package = package.rpartition(".")[0]
            base = ".".join(part for part in (package, node.module) if part)
        else:
            base = node.module or ""
        for alias in node.names:
            submodule = f"{base}.{alias.name}"
            yield submodule if submodule in known else base
    elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
          and node.func.attr == "import_module" and node.args
          and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)):
        yield node.args[0].value  # importlib.import_module("a.b"): an import all the same


def import_graph(roots: tuple[Path, ...]) -> dict[str, set[str]]:
    """Module → the modules of ``roots`` it imports (a name resolved to its nearest module)."""
    known = _modules(roots)
    graph: dict[str, set[str]] = {}
    for name, path in known.items():
        targets = graph.setdefault(name, set())
        for node in _nodes(ast.parse(path.read_text(), str(path))):
            for target in _imported(name, path, node, known):
                while target and target not in known:
                    target = target.rpartition(".")[0]
                if target and target != name:
                    targets.add(target)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, targets = work[-1]
            for target in targets:
                if target not in index:
                    index[target] = low[target] = len(index)
                    stack.append(target)
                    on_stack.add(target)
                    work.append((target, iter(sorted(graph[target]))))
                    break
                if target in on_stack:
                    low[node] = min(low[node], index[target])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    if len(component) > 1:
                        found.append(sorted(component))
    return sorted(found)


def mutual_pairs(graph: dict[str, set[str]]) -> list[tuple[str, str]]:
    return sorted((a, b) for a, targets in graph.items() for b in targets
                  if a < b and a in graph.get(b, ()))


def test_no_two_modules_import_each_other():
    assert mutual_pairs(import_graph(PACKAGES)) == []


def test_no_longer_loop_of_imports_either():
    assert cycles(import_graph(PACKAGES)) == []


def test_the_graph_sees_the_packages():
    graph = import_graph(PACKAGES)
    assert "deltoctl.errors" in graph["deltoctl.core.envelope"]
    assert "deltoctl.registry" in graph["deltoctl_canopen"]


def _write(root: Path, files: dict[str, str]) -> None:
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


def test_deferred_imports_count_and_type_checking_ones_do_not(tmp_path):
    _write(tmp_path, {
        "pkg/__init__.py": "",
        "pkg/a.py": "def f():\n    from pkg import b\n",
        "pkg/b.py": "from . import a\n",
        "pkg/c.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg.d import X\n"
                    "else:\n    import pkg.e\n",
        "pkg/d.py": "from pkg.c import Y\n",
        "pkg/e.py": "import importlib\nimportlib.import_module('pkg.sub.f')\n",
        "pkg/sub/__init__.py": "from ..e import Z\n",
        "pkg/sub/f.py": "from pkg.c import W\n",
    })
    graph = import_graph((tmp_path / "pkg",))
    assert graph["pkg.a"] == {"pkg.b"}
    assert graph["pkg.c"] == {"pkg.e"}
    assert graph["pkg.sub"] == {"pkg.e"}
    assert graph["pkg.e"] == {"pkg.sub.f"}
    assert mutual_pairs(graph) == [("pkg.a", "pkg.b")]
    assert cycles(graph) == [["pkg.a", "pkg.b"], ["pkg.c", "pkg.e", "pkg.sub.f"]]
