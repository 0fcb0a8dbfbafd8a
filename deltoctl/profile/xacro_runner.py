"""Run xacro with no ROS installed, and with nothing from the profile run as code.

``$(find pkg)`` resolves through package paths. A profile is untrusted input, so while xacro
runs, the places where it would call Python's ``eval`` (``${…}``, ``$(eval …)``, the unit tags
of ``xacro.load_yaml``) go through :mod:`deltoctl.profile.xacro_sandbox` instead;
``$(env)``/``$(optenv)`` are refused; every file xacro reads (the profile, its includes,
``xacro.load_yaml``) must be a regular file under the size limit inside the profile's
directory or a package path, and plain XML (no entities) or bounded YAML; and the expansion
is bounded in nodes, so a macro bomb stops early.
"""

from __future__ import annotations

import contextlib
import io
import itertools
import os
import re
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from deltoctl.errors import ProfileError
from deltoctl.profile.xacro_sandbox import (
    Evaluator,
    Function,
    SandboxError,
    base_globals,
    printed_size,
    xacro_namespace,
)

PACKAGE_PATH_ENV = "DELTOCTL_PACKAGE_PATH"
MAX_XACRO_NODES = 50_000  # XML nodes visited or copied while expanding (the UR arm: 4,600)
MAX_XACRO_CHARS = 64 << 20  # characters copied by macros and blocks, or made by expressions
MAX_EXPRESSION_STEPS = 100_000  # values made by all expressions of one run (UR arm: 1,052)
# xacro's lexer copies the rest of a text at each token: a text's length times its '$' count
MAX_LEXER_WORK = 1 << 26
MAX_INCLUDE_MATCHES = 1000
_GLOB_MAGIC = re.compile(r"[*?[]")  # what makes xacro glob an include's file name


def package_paths(given: Mapping[str, str] | None = None) -> dict[str, Path]:
    """``PKG=DIR`` pairs from DELTOCTL_PACKAGE_PATH (``:``-separated), overridden by ``given``."""
    paths: dict[str, Path] = {}
    for item in os.environ.get(PACKAGE_PATH_ENV, "").split(os.pathsep):
        if "=" in item:
            pkg, _, directory = item.partition("=")
            paths[pkg.strip()] = Path(directory.strip()).expanduser()
    for pkg, directory in (given or {}).items():
        paths[pkg] = Path(directory).expanduser()
    return paths


def _is_table(value: Any) -> bool:
    import xacro

    return isinstance(value, xacro.Table)


def _table_lookup(table: Any, name: str) -> Any:
    """A property from xacro's scopes, never from xacro's own globals (the root), which hold
    Python builtins such as ``type`` and ``vars``."""
    import xacro

    while isinstance(table, xacro.Table):
        if dict.__contains__(table, name):
            return table[name]  # Table.__getitem__ evaluates a lazy property
        table = table.parent
    raise KeyError(name)


def _weight(node: Any) -> int:
    """The characters one DOM node holds: its text, or its attributes' values."""
    data = getattr(node, "data", None)
    if isinstance(data, str):
        return len(data)
    attrs = getattr(node, "_attrs", None) or {}
    return sum(len(attr.value) for attr in attrs.values())


def _plain(data: Any) -> Any:
    """YAML data as dict/list/str/number/bool/None (a date or bytes becomes its text)."""
    memo: dict[int, Any] = {}

    def convert(value: Any) -> Any:
        if isinstance(value, (bool, int, float, str)) or value is None:
            return value
        if id(value) in memo:  # an alias: share, do not copy
            return memo[id(value)]
        if isinstance(value, dict):
            result: Any = {}
            memo[id(value)] = result
            result.update((convert(k), convert(v)) for k, v in value.items())
            return result
        if isinstance(value, list):
            memo[id(value)] = result = []
            result.extend(convert(v) for v in value)
            return result
        return str(value)

    return convert(data)


_UNITS = {"!radians": 1.0, "!degrees": 0.017453292519943295, "!meters": 1.0,
          "!millimeters": 0.001, "!foot": 0.3048, "!inches": 0.0254}


def _yaml_loader_class(evaluator: Callable[[], Evaluator]) -> type:
    """A safe YAML loader with xacro's unit tags, their values evaluated in the sandbox."""
    import yaml

    base = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
    loader = type("XacroYamlLoader", (base,), {})

    def unit(factor: float) -> Callable[[Any, Any], float]:
        def construct(yaml_loader: Any, node: Any) -> float:
            text = yaml_loader.construct_scalar(node)
            value = evaluator().evaluate(str(text))
            try:
                return float(value) * factor
            except (TypeError, ValueError):
                raise SandboxError(f"{node.tag} needs a number, got {value!r}") from None
        return construct

    for tag, factor in _UNITS.items():
        loader.add_constructor(tag, unit(factor))
    return loader


def _no_properties(name: str) -> Any:
    raise KeyError(name)


class _Run:
    """One xacro run: the directories files may come from, the node budget, the sandbox."""

    def __init__(self, top: Path, paths: dict[str, Path]) -> None:
        self.top = top
        self.paths = paths
        self.roots = [top.resolve().parent, *(p.resolve() for p in paths.values())]
        self.missing: list[str] = []
        self.nodes = 0
        self.chars = 0
        self.steps = 0
        self.names = base_globals(xacro_namespace(self.load_yaml, self.arg))
        self.yaml_loader: type | None = None

    # -- files --------------------------------------------------------------------------------

    def inside(self, filename: str, what: str) -> Path:
        """The real path of ``filename``, if it is inside the allowed directories."""
        real = Path(filename).resolve()
        if not any(real == root or real.is_relative_to(root) for root in self.roots):
            raise ProfileError(
                f"{what} {filename} is outside the profile's directory and the --package-path "
                "directories; deltoctl reads no other files", str(self.top))
        return real

    def read(self, filename: str, what: str) -> str:
        """The text of a file xacro wants, if it is inside the allowed directories."""
        from deltoctl.profile.files import check_profile_file

        real = self.inside(filename, what)
        if not real.exists():
            raise FileNotFoundError(2, "No such file or directory", filename)
        check_profile_file(real)
        try:
            return real.read_bytes().decode("utf-8")
        except UnicodeDecodeError:
            raise ProfileError("not a text file (expected UTF-8)", filename) from None

    def parse(self, original: Callable[..., Any]) -> Callable[..., Any]:
        """xacro.parse, reading files through ``read`` and checking them as plain XML."""
        import xacro

        from deltoctl.profile.xmltree import XMLSyntaxError, parse_xml

        def parse(inp: Any, filename: str | None = None) -> Any:
            if inp is None:
                path = os.path.join(xacro.root_dir, filename or "")
                try:
                    inp = self.read(path, "the xacro file")
                except OSError as exc:  # as xacro does, so that optional includes work
                    xacro.filestack.pop()
                    raise xacro.XacroException(f"{exc.strerror}: {path}", exc=exc) from None
                try:
                    parse_xml(inp)  # no entities, bounded depth, before minidom sees it
                except XMLSyntaxError as exc:
                    raise ProfileError(f"not well-formed XML: {exc}", path, exc.line) from None
            return original(inp)

        return parse

    def glob(self, pattern: str) -> list[str]:
        """The files an include pattern names: walked from inside the allowed directories
        only, and at most MAX_INCLUDE_MATCHES of them (a pattern like /*/*/*/* would walk
        the whole disk)."""
        import glob as globbing

        parts = Path(pattern).parts
        first = next(i for i, part in enumerate(parts) if _GLOB_MAGIC.search(part))
        if ".." in parts[first:]:
            raise ProfileError(f"xacro:include pattern {pattern}: '..' after a wildcard",
                               str(self.top))
        self.inside(str(Path(*parts[:first])) if first else ".", "xacro:include pattern")
        matches = list(itertools.islice(globbing.iglob(pattern), MAX_INCLUDE_MATCHES + 1))
        if len(matches) > MAX_INCLUDE_MATCHES:
            raise ProfileError(f"xacro:include pattern {pattern} matches more than "
                               f"{MAX_INCLUDE_MATCHES} files", str(self.top))
        return matches

    def load_yaml(self, filename: Any) -> Any:
        import xacro

        from deltoctl.profile.yaml_loader import load_data

        if not isinstance(filename, str):
            raise SandboxError("xacro.load_yaml() takes a file name")
        path = xacro.abs_filename_spec(filename)
        try:
            text = self.read(path, "xacro.load_yaml of")
        except OSError as exc:
            raise SandboxError(f"xacro.load_yaml: {exc.strerror}: {path}") from None
        if self.yaml_loader is None:  # unit tags see math, as in xacro, and no properties
            self.yaml_loader = _yaml_loader_class(
                lambda: Evaluator(_no_properties, base_globals(), spend=self.step))
        data = load_data(text, path, self.yaml_loader)
        xacro.all_includes.append(path)
        return _plain(data)

    # -- expressions --------------------------------------------------------------------------

    def arg(self, name: Any) -> Any:
        import xacro

        args = xacro.substitution_args_context.get("arg", {})
        if name not in args:
            raise SandboxError(f"xacro argument {name!r} has no value: pass --arg {name}:=VALUE")
        return args[name]

    def safe_eval(self, expr: str, globals: Any, locals: Any = None) -> Any:
        """Replaces xacro.safe_eval: ``${expr}`` with the properties in scope."""
        evaluator = Evaluator(lambda name: _table_lookup(globals, name), self.names,
                              member=_table_lookup, is_namespace=_is_table, spend=self.step)
        return self.spent(evaluator.evaluate(expr))

    def eval_substitution(self, text: str, context: dict[str, Any]) -> str:
        """Replaces substitution_args._eval: ``$(eval expr)`` with the xacro args as names."""
        from xacro import substitution_args as sa

        args = context.setdefault("arg", {})
        functions: dict[str, Any] = {
            "arg": Function("arg", lambda name: sa.convert_value(sa._eval_arg(name, args),
                                                                 "auto")),
            "dirname": Function("dirname", lambda: sa._eval_dirname(context.get("filename"))),
            "find": Function("find", lambda pkg: sa._eval_find(pkg)),
            "true": True, "false": False, "True": True, "False": False,
        }

        def lookup(name: str) -> Any:
            if name in functions:
                return functions[name]
            if name in args:
                return sa.convert_value(args[name], "auto")
            raise KeyError(name)

        evaluator = Evaluator(lookup, base_globals(), spend=self.step)
        return str(self.spent(evaluator.evaluate(text)))

    def find(self, pkg: str) -> str:
        if pkg in self.paths:
            return str(self.paths[pkg].resolve())
        self.missing.append(pkg)
        raise LookupError(pkg)

    # -- budget -------------------------------------------------------------------------------

    def spend(self, nodes: int = 0, chars: int = 0) -> None:
        self.nodes += nodes
        self.chars += chars
        if self.nodes > MAX_XACRO_NODES:
            raise ProfileError(f"the xacro expansion exceeds {MAX_XACRO_NODES} XML nodes "
                               "(a macro that multiplies itself?)", str(self.top))
        if self.chars > MAX_XACRO_CHARS:
            raise ProfileError(f"the xacro expansion exceeds {MAX_XACRO_CHARS >> 20} MiB of text",
                               str(self.top))

    def step(self, cost: int) -> None:
        """One value made by an expression: all expressions of a run make a bounded number."""
        self.steps += 1
        if self.steps > MAX_EXPRESSION_STEPS:
            raise ProfileError(f"the xacro expressions take more than {MAX_EXPRESSION_STEPS} "
                               "steps to evaluate", str(self.top))
        self.spend(chars=cost)

    def spent(self, result: Any) -> Any:
        self.spend(chars=printed_size(result))
        return result

    def counting_eval_all(self, original: Callable[..., Any]) -> Callable[..., Any]:
        def eval_all(node: Any, macros: Any, symbols: Any) -> Any:
            self.spend(nodes=len(node.childNodes) + 1)
            return original(node, macros, symbols)

        return eval_all

    def counting_clone(self, original: Callable[..., Any]) -> Callable[..., Any]:
        """minidom's node copy, which every macro call and inserted block goes through."""
        def clone_node(node: Any, deep: bool, owner: Any) -> Any:
            self.spend(nodes=1, chars=_weight(node))
            return original(node, deep, owner)

        return clone_node


def _bounded_eval_text(original: Callable[..., Any]) -> Callable[..., Any]:
    def eval_text(text: Any, symbols: Any) -> Any:
        if isinstance(text, str) and len(text) * text.count("$") > MAX_LEXER_WORK:
            raise SandboxError(f"a text of {len(text)} characters with {text.count('$')} '$' "
                               "is too costly to expand")
        return original(text, symbols)

    return eval_text


def _refused_environment(substitution: str, name: Any, default: str = "") -> SandboxError:
    """A profile reads no environment variable: the same file must describe the same robot on
    every computer and for every user, and the environment may hold secrets."""
    given = f"{name} {default}".strip()
    return SandboxError(f"$({substitution} {given}) is refused: a profile does not read "
                        f"environment variables (they differ from one computer or user to the "
                        f"next, and may hold secrets); pass --arg {name}:=VALUE and write "
                        f"$(arg {name}) instead")


def _refuse_env(name: Any) -> str:
    raise _refused_environment("env", name)


def _refuse_optenv(name: Any, default: str = "") -> str:
    raise _refused_environment("optenv", name, default)


@contextlib.contextmanager
def _sandboxed(run: _Run) -> Iterator[None]:
    """Point xacro's evaluation and file reading at ``run`` for the time of one expansion."""
    from xml.dom import minidom

    import xacro
    from xacro import substitution_args as sa

    patches: list[tuple[Any, str, Any]] = [
        (xacro, "safe_eval", run.safe_eval),
        (xacro, "parse", run.parse(xacro.parse)),
        (xacro, "glob", SimpleNamespace(glob=run.glob)),
        (xacro, "eval_text", _bounded_eval_text(xacro.eval_text)),
        (xacro, "eval_all", run.counting_eval_all(xacro.eval_all)),
        (minidom, "_clone_node", run.counting_clone(minidom._clone_node)),
        (xacro, "all_includes", []),
        (sa, "_eval", run.eval_substitution),
        (sa, "_eval_env", _refuse_env),
        (sa, "_eval_optenv", _refuse_optenv),
        (sa, "_eval_find", run.find),
    ]
    saved = [(target, name, getattr(target, name)) for target, name, _ in patches]
    try:
        for target, name, value in patches:
            setattr(target, name, value)
        yield
    finally:
        for target, name, value in saved:
            if name != "all_includes":  # kept for included_files() after the run
                setattr(target, name, value)


def _cause(exc: BaseException) -> BaseException | None:
    """The ProfileError or SandboxError that xacro wrapped on its way out, if any."""
    seen: set[int] = set()
    stack: list[BaseException | None] = [exc]
    while stack:
        current = stack.pop(0)
        if current is None or id(current) in seen:
            continue
        seen.add(id(current))
        if isinstance(current, (ProfileError, SandboxError)):
            return current
        stack += [getattr(current, "exc", None), current.__cause__, current.__context__]
    return None


def run_xacro(path: Path, args: Mapping[str, str], packages: Mapping[str, str] | None) -> str:
    """Expand a xacro file; returns the URDF text. Errors name the file."""
    import xacro

    source = str(path)
    run = _Run(path, package_paths(packages))
    try:
        with _sandboxed(run), contextlib.redirect_stderr(io.StringIO()):
            doc = xacro.process_file(str(path), mappings=dict(args), verbosity=0)
    except Exception as exc:  # xacro raises many kinds; each becomes one clear line
        cause = _cause(exc)
        if isinstance(cause, ProfileError):
            raise cause from None
        if run.missing:
            pkg = run.missing[0]
            raise ProfileError(
                f"$(find {pkg}): package {pkg!r} is unknown; pass --package-path {pkg}=DIR "
                f"or add {pkg}=DIR to {PACKAGE_PATH_ENV}", source) from None
        where = ""
        stack = [f for f in (getattr(xacro, "filestack", None) or []) if f]
        if stack and stack[-1] != source:
            where = f" (in {stack[-1]})"
        message = str(cause if cause is not None else exc).strip() or type(exc).__name__
        undefined = re.match(r"Undefined substitution argument (\S+)", message)
        if undefined:
            name = undefined.group(1)
            message = f"xacro argument {name!r} has no value: pass --arg {name}:=VALUE"
        raise ProfileError(f"xacro failed{where}: {' '.join(message.split())}", source) from None
    return doc.toxml()


def included_files() -> list[str]:
    import xacro

    return [str(f) for f in getattr(xacro, "all_includes", [])]
