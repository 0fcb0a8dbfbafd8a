"""Evaluate xacro's ``${…}`` and ``$(eval …)`` expressions without Python's ``eval``.

A profile is untrusted input, and xacro hands every expression to ``eval``. Here an expression
is parsed with :mod:`ast` and only a whitelist of node types is interpreted: literals, names
bound to xacro properties or to a fixed table of math and conversion functions, arithmetic,
comparisons, boolean operators, the ternary, subscripts, and calls of whitelisted functions.
Attribute access is only a name lookup in a namespace (``math.pi``, an included file's
``ns.prop``, a YAML mapping's ``d.key``) or one of a few whitelisted ``str``/``dict`` methods:
no Python object's attributes are ever reached, so ``__class__``, ``__globals__`` and friends
do not exist here. Sizes are bounded too (text, containers, integers), so an expression cannot
exhaust memory or time: an operation that would make a large value (a join, a repeat, a
padding width, a split, a power) is refused from its operands' sizes before it is made, and
the values one expression makes are bounded together.
"""

from __future__ import annotations

import ast
import functools
import math
import operator
import re
import sys
from collections.abc import Callable, Mapping
from typing import Any

MAX_EXPRESSION_CHARS = 4096
MAX_EXPRESSION_NODES = 1000
MAX_EXPRESSION_DEPTH = 64
MAX_TEXT = 1 << 20  # characters in a string, or the printed size of a container
MAX_INT_BITS = 10_000  # str() of such an int stays under Python's 4300-digit limit
MAX_ROUND_DIGITS = 1000
MAX_EXPRESSION_BYTES = 16 << 20  # memory of all the values one expression makes


class SandboxError(Exception):
    """An expression the sandbox refuses or cannot evaluate; ``str()`` is one line."""

    def __init__(self, reason: str, expression: str | None = None) -> None:
        super().__init__(reason)
        self.reason = reason
        self.expression = expression

    def __str__(self) -> str:
        if self.expression is None:
            return self.reason
        shown = " ".join(self.expression.split())
        if len(shown) > 80:
            shown = shown[:77] + "..."
        return f"{self.reason} (in '{shown}')"


class Function:
    """A callable the sandbox allows; its result is checked like any other value."""

    __slots__ = ("func", "guard", "name")

    def __init__(self, name: str, func: Callable[..., Any],
                 guard: Callable[..., None] | None = None) -> None:
        self.name = name
        self.func = func
        self.guard = guard

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        if self.guard is not None:
            self.guard(*args, **kwargs)
        return check_value(self.func(*args, **kwargs))

    def __repr__(self) -> str:
        return f"<function {self.name}>"


class Namespace:
    """A fixed, read-only table of names reached with a dot (``math.pi``)."""

    __slots__ = ("entries", "name")

    def __init__(self, name: str, entries: Mapping[str, Any]) -> None:
        self.name = name
        self.entries = dict(entries)

    def member(self, attr: str) -> Any:
        if attr not in self.entries:
            raise SandboxError(f"{self.name}.{attr} is not available")
        return self.entries[attr]


# -- sizes -------------------------------------------------------------------------------------

_SCALARS = (type(None), bool, int, float, complex, str)
_CONTAINERS = (list, tuple, dict, set, frozenset)
_SIZED = (str, *_CONTAINERS)


def printed_size(value: Any, limit: int = MAX_TEXT) -> int:
    """About len(str(value)), stopping once past ``limit``; shared parts are measured once."""
    memo: dict[int, int] = {}

    def size(v: Any) -> int:
        kind = type(v)
        if kind is str:
            return len(v) + 2
        if kind is int:
            return v.bit_length() // 3 + 2
        if kind not in _CONTAINERS:
            return 24
        key = id(v)
        if key in memo:
            return memo[key]
        memo[key] = limit + 1  # a cycle counts as too big
        total = 2
        items = (x for kv in v.items() for x in kv) if kind is dict else v
        for item in items:
            total += size(item) + 2
            if total > limit:
                break
        memo[key] = total
        return total

    return size(value)


def check_value(value: Any) -> Any:
    """``value`` if it is plain data of a bounded size (or an allowed function)."""
    kind = type(value)
    if kind is int and value.bit_length() > MAX_INT_BITS:
        raise SandboxError(f"an integer larger than {MAX_INT_BITS} bits")
    if kind is str and len(value) > MAX_TEXT:
        raise SandboxError(f"a string longer than {MAX_TEXT} characters")
    if kind in _CONTAINERS:
        if printed_size(value) > MAX_TEXT:
            raise SandboxError(f"a {kind.__name__} larger than {MAX_TEXT} characters")
        return value
    if kind in _SCALARS or kind in (Function, _Method):
        return value
    raise SandboxError(f"a value of type {kind.__name__} cannot be used here")


def _length(value: Any) -> int:
    return len(value) if type(value) in (str, list, tuple) else 0


def _check_repeat(seq: Any, times: Any) -> None:
    if type(seq) not in (str, list, tuple) or type(times) not in (int, bool):
        return
    unit = len(seq) if type(seq) is str else printed_size(seq)
    if unit * max(times, 0) > MAX_TEXT:
        raise SandboxError(f"repeating a {type(seq).__name__} beyond {MAX_TEXT} characters")


def _check_mult(a: Any, b: Any) -> None:
    _check_repeat(a, b)
    _check_repeat(b, a)
    if type(a) is int and type(b) is int and a.bit_length() + b.bit_length() > MAX_INT_BITS:
        raise SandboxError(f"an integer larger than {MAX_INT_BITS} bits")


def _check_pow(base: Any, exp: Any) -> None:
    if type(base) in (int, bool) and type(exp) in (int, bool) and exp > 0 \
            and abs(base) > 1 and exp * math.log2(abs(base)) > MAX_INT_BITS:
        raise SandboxError(f"an integer larger than {MAX_INT_BITS} bits")


def _check_add(a: Any, b: Any) -> None:
    if _length(a) + _length(b) > MAX_TEXT:
        raise SandboxError(f"joining beyond {MAX_TEXT} characters")


def _check_mod(a: Any, b: Any) -> None:
    if isinstance(a, str):  # printf-style widths ('%999999999d') allocate before any check
        raise SandboxError("'%' formatting of strings is not allowed")


def _check_shift(a: Any, b: Any) -> None:
    if type(a) in (int, bool) and type(b) in (int, bool) and a.bit_length() + b > MAX_INT_BITS:
        raise SandboxError(f"an integer larger than {MAX_INT_BITS} bits")


_BINARY: dict[type, tuple[Callable[[Any, Any], Any], Callable[[Any, Any], None] | None]] = {
    ast.Add: (operator.add, _check_add),
    ast.Sub: (operator.sub, None),
    ast.Mult: (operator.mul, _check_mult),
    ast.Div: (operator.truediv, None),
    ast.FloorDiv: (operator.floordiv, None),
    ast.Mod: (operator.mod, _check_mod),
    ast.Pow: (operator.pow, _check_pow),
    ast.LShift: (operator.lshift, _check_shift),
    ast.RShift: (operator.rshift, None),
    ast.BitAnd: (operator.and_, None),
    ast.BitOr: (operator.or_, None),
    ast.BitXor: (operator.xor, None),
}
_UNARY: dict[type, Callable[[Any], Any]] = {
    ast.UAdd: operator.pos, ast.USub: operator.neg, ast.Not: operator.not_,
    ast.Invert: operator.invert,
}
_COMPARE: dict[type, Callable[[Any, Any], Any]] = {
    ast.Eq: operator.eq, ast.NotEq: operator.ne, ast.Lt: operator.lt, ast.LtE: operator.le,
    ast.Gt: operator.gt, ast.GtE: operator.ge, ast.Is: operator.is_, ast.IsNot: operator.is_not,
    ast.In: lambda a, b: a in b, ast.NotIn: lambda a, b: a not in b,
}


# -- the functions an expression may call ------------------------------------------------------

def _guard_text(*args: Any, **kwargs: Any) -> None:
    if any(printed_size(value) > MAX_TEXT for value in (*args, *kwargs.values())):
        raise SandboxError(f"text longer than {MAX_TEXT} characters")


def _guard_items(items: Any = (), *args: Any, **kwargs: Any) -> None:
    """list(), tuple(), sorted() of a string make a string of each character: counted first."""
    if type(items) is str and 2 + 5 * len(items) > MAX_TEXT:
        raise SandboxError(f"a list of {len(items)} characters, beyond {MAX_TEXT} characters "
                           "printed")


def _guard_round(number: Any = 0, ndigits: Any = None) -> None:
    if type(ndigits) is int and abs(ndigits) > MAX_ROUND_DIGITS:
        raise SandboxError(f"round() to more than {MAX_ROUND_DIGITS} digits")


_MATH_NAMES = (
    "acos", "acosh", "asin", "asinh", "atan", "atan2", "atanh", "ceil", "copysign", "cos",
    "cosh", "degrees", "dist", "erf", "erfc", "exp", "expm1", "fabs", "floor", "fmod", "frexp",
    "gamma", "hypot", "isclose", "isfinite", "isinf", "isnan", "ldexp", "lgamma", "log",
    "log10", "log1p", "log2", "modf", "pow", "radians", "remainder", "sin", "sinh", "sqrt",
    "tan", "tanh", "trunc",
)
MATH: dict[str, Any] = {name: Function(name, getattr(math, name)) for name in _MATH_NAMES}
MATH.update(pi=math.pi, e=math.e, tau=math.tau, inf=math.inf, nan=math.nan)

BUILTINS: dict[str, Any] = {
    "abs": Function("abs", abs),
    "all": Function("all", all),
    "any": Function("any", any),
    "bool": Function("bool", bool),
    "dict": Function("dict", dict),
    "float": Function("float", float),
    "int": Function("int", int),
    "len": Function("len", len),
    "list": Function("list", list, _guard_items),
    "max": Function("max", max),
    "min": Function("min", min),
    "repr": Function("repr", repr, _guard_text),
    "round": Function("round", round, _guard_round),
    "sorted": Function("sorted", sorted, _guard_items),
    "str": Function("str", str, _guard_text),
    "tuple": Function("tuple", tuple, _guard_items),
}


def _tokenize(text: Any, sep: Any = ",; ", skip_empty: bool = True) -> list[str]:
    if not isinstance(text, str) or not isinstance(sep, str):
        raise SandboxError("xacro.tokenize() takes text")
    pieces = sum(text.count(c) for c in set(sep)) + 1
    if len(text) + 4 * pieces > MAX_TEXT:
        raise SandboxError(f"xacro.tokenize() into {pieces} pieces, beyond {MAX_TEXT} "
                           "characters")
    # xacro builds this regex from sep unescaped; escaping it keeps sep a set of characters
    items = re.split(f"[{re.escape(sep)}]", text) if sep else [text]
    return [i for i in items if i] if skip_empty else items


def _fatal(*message: Any) -> None:
    raise SandboxError("xacro.fatal: " + " ".join(str(m) for m in message))


def _dotify(value: Any) -> Any:
    if type(value) is not dict:
        raise SandboxError("xacro.dotify() takes a mapping")
    return value  # a mapping's keys are reachable with a dot already


def _quiet(*message: Any, **kwargs: Any) -> str:
    return ""


def xacro_namespace(load_yaml: Callable[[Any], Any], arg: Callable[[Any], Any]) -> Namespace:
    """xacro's own functions, with ``load_yaml`` and ``arg`` given by the runner."""
    return Namespace("xacro", {
        "load_yaml": Function("xacro.load_yaml", load_yaml),
        "arg": Function("xacro.arg", arg),
        "tokenize": Function("xacro.tokenize", _tokenize),
        "fatal": Function("xacro.fatal", _fatal),
        "dotify": Function("xacro.dotify", _dotify),
        "message": Function("xacro.message", _quiet),
        "warning": Function("xacro.warning", _quiet),
        "error": Function("xacro.error", _quiet),
    })


def base_globals(xacro: Namespace | None = None) -> dict[str, Any]:
    """The names every expression sees (after the properties): math, a few builtins."""
    names: dict[str, Any] = {**MATH, **BUILTINS}
    names["math"] = Namespace("math", MATH)
    names["python"] = Namespace("python", BUILTINS)
    if xacro is not None:
        names["xacro"] = xacro
        names["load_yaml"] = xacro.entries["load_yaml"]  # xacro's deprecated spelling
    return names


# -- methods of plain values ---------------------------------------------------------------------

def _guard_replace(text: str, old: Any = "", new: Any = "", count: Any = -1) -> None:
    if not (isinstance(old, str) and isinstance(new, str)):
        return  # str.replace raises TypeError itself
    hits = text.count(old) if old else len(text) + 1
    if type(count) is int and count >= 0:
        hits = min(hits, count)
    if len(text) + hits * (len(new) - len(old)) > MAX_TEXT:
        raise SandboxError(f"str.replace() beyond {MAX_TEXT} characters")


def _guard_join(sep: str, items: Any = ()) -> None:
    """The joined length, from the items' lengths: a string's items are its characters."""
    if type(items) is str:
        total = len(items) + len(sep) * max(len(items) - 1, 0)
    elif type(items) in _CONTAINERS:
        total = sum(len(i) for i in items if type(i) is str) + len(sep) * max(len(items) - 1, 0)
    else:
        return  # str.join raises TypeError itself
    if total > MAX_TEXT:
        raise SandboxError(f"str.join() of {total} characters, beyond {MAX_TEXT}")


def _guard_width(text: str, width: Any = 0, *args: Any) -> None:
    """ljust, rjust, center, zfill: the result is ``width`` characters long."""
    if type(width) in (int, bool) and width > MAX_TEXT:
        raise SandboxError(f"a width of {width} characters, beyond {MAX_TEXT}")


def _guard_expandtabs(text: str, tabsize: Any = 8) -> None:
    if type(tabsize) in (int, bool) and len(text) + text.count("\t") * tabsize > MAX_TEXT:
        raise SandboxError(f"str.expandtabs() beyond {MAX_TEXT} characters")


def _guard_split(text: str, sep: Any = None, maxsplit: Any = -1) -> None:
    """The pieces of a split, counted before they are made: each costs a string."""
    if sep is None:
        pieces = sum(1 for _ in re.finditer(r"\S+", text))
    elif isinstance(sep, str) and sep:
        pieces = text.count(sep) + 1
    else:
        return  # str.split raises itself
    if type(maxsplit) is int and maxsplit >= 0:
        pieces = min(pieces, maxsplit + 1)
    if len(text) + 4 * pieces > MAX_TEXT:
        raise SandboxError(f"str.split() into {pieces} pieces, beyond {MAX_TEXT} characters")


_STR_METHODS: dict[str, Callable[..., None] | None] = {
    name: None for name in (
        "lower", "upper", "strip", "lstrip", "rstrip", "startswith", "endswith", "split",
        "rsplit", "find", "rfind", "count", "title", "capitalize", "isdigit", "isalpha",
        "isalnum", "isnumeric", "isspace", "islower", "isupper", "removeprefix",
        "removesuffix", "partition", "rpartition")
}
_STR_METHODS.update(replace=_guard_replace, join=_guard_join, split=_guard_split,
                    rsplit=_guard_split, expandtabs=_guard_expandtabs,
                    **dict.fromkeys(("ljust", "rjust", "center", "zfill"), _guard_width))
_DICT_METHODS = {
    "get": lambda d, *a: d.get(*a),
    "keys": lambda d: list(d.keys()),
    "values": lambda d: list(d.values()),
    "items": lambda d: [tuple(kv) for kv in d.items()],
}


class _Method:
    """A whitelisted method bound to a plain str or dict value."""

    __slots__ = ("name", "target")

    def __init__(self, target: Any, name: str) -> None:
        self.target = target
        self.name = name

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        if type(self.target) is dict:
            return check_value(_DICT_METHODS[self.name](self.target, *args, **kwargs))
        guard = _STR_METHODS[self.name]
        if guard is not None:
            guard(self.target, *args, **kwargs)
        return check_value(getattr(self.target, self.name)(*args, **kwargs))

    def __repr__(self) -> str:
        return f"<method {type(self.target).__name__}.{self.name}>"


# -- parsing: only whitelisted syntax ------------------------------------------------------------

_ALLOWED_NODES = (
    ast.Expression, ast.Constant, ast.Name, ast.Load, ast.Attribute, ast.Subscript, ast.Slice,
    ast.BinOp, ast.UnaryOp, ast.BoolOp, ast.Compare, ast.IfExp, ast.Call, ast.keyword,
    ast.List, ast.Tuple, ast.Dict, ast.Set, ast.And, ast.Or,
    *_BINARY, *_UNARY, *_COMPARE,
)
_REFUSED_NAMES = {
    ast.Lambda: "lambda", ast.ListComp: "comprehensions", ast.SetComp: "comprehensions",
    ast.DictComp: "comprehensions", ast.GeneratorExp: "generator expressions",
    ast.JoinedStr: "f-strings", ast.FormattedValue: "f-strings",
    ast.NamedExpr: "assignment expressions (:=)", ast.Starred: "* unpacking",
    ast.Await: "await", ast.Yield: "yield", ast.YieldFrom: "yield",
}


def _describe(node: ast.AST) -> str:
    for kind, name in _REFUSED_NAMES.items():
        if isinstance(node, kind):
            return name
    return type(node).__name__


def _check_node(node: ast.AST) -> None:
    if not isinstance(node, _ALLOWED_NODES):
        raise SandboxError(f"{_describe(node)} not allowed")
    if isinstance(node, ast.Constant) and type(node.value) not in _SCALARS:
        raise SandboxError(f"the literal {node.value!r} is not allowed")
    if isinstance(node, ast.Name) and node.id.startswith("__"):
        raise SandboxError(f"the name {node.id!r} is not allowed")
    if isinstance(node, ast.Attribute) and node.attr.startswith("_"):
        raise SandboxError(f"the attribute .{node.attr} is not allowed")
    if isinstance(node, ast.keyword) and node.arg is None:
        raise SandboxError("** unpacking not allowed")
    if isinstance(node, ast.Dict) and any(k is None for k in node.keys):
        raise SandboxError("** unpacking not allowed")


@functools.lru_cache(maxsize=512)  # a macro's expressions come back at every call
def parse_expression(text: str) -> ast.Expression:
    """The syntax tree of ``text``, if every node of it is one the sandbox interprets."""
    if len(text) > MAX_EXPRESSION_CHARS:
        raise SandboxError(f"an expression longer than {MAX_EXPRESSION_CHARS} characters")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as exc:
        raise SandboxError(f"not a valid expression: {exc.msg}") from None
    except (RecursionError, MemoryError, ValueError):
        raise SandboxError("not a valid expression: too complex") from None
    stack: list[tuple[ast.AST, int]] = [(tree, 0)]
    count = 0
    while stack:
        node, depth = stack.pop()
        count += 1
        if count > MAX_EXPRESSION_NODES or depth > MAX_EXPRESSION_DEPTH:
            raise SandboxError("an expression too large or too deeply nested")
        _check_node(node)
        stack.extend((child, depth + 1) for child in ast.iter_child_nodes(node))
    return tree


# -- evaluation ----------------------------------------------------------------------------------

Lookup = Callable[[str], Any]
AttributeHook = Callable[[Any, str], Any]


class Evaluator:
    """Interprets a checked syntax tree.

    ``lookup(name)`` gives a property's value or raises KeyError; then ``names`` is tried.
    ``member(obj, attr)`` resolves a dot on objects the caller knows (xacro's namespaces) and
    raises KeyError for anything else; ``is_namespace(obj)`` tells such objects apart.
    ``spend(cost)`` is told of each value made (1 + its length), so that a caller evaluating
    many expressions can bound their total work.
    """

    def __init__(self, lookup: Lookup, names: Mapping[str, Any],
                 member: AttributeHook | None = None,
                 is_namespace: Callable[[Any], bool] | None = None,
                 spend: Callable[[int], None] | None = None) -> None:
        self.lookup = lookup
        self.names = names
        self.member = member
        self.is_namespace = is_namespace or (lambda value: False)
        self.spend = spend
        self.made = 0  # bytes of the values made so far by the expression being evaluated

    def evaluate(self, text: str) -> Any:
        self.made = 0
        try:
            tree = parse_expression(text)
            return self.value(tree.body)
        except SandboxError as exc:
            if exc.expression is None:
                exc.expression = text
            raise
        except RecursionError:
            raise SandboxError("expressions nested too deeply", text) from None
        except (ArithmeticError, AttributeError, LookupError, MemoryError, TypeError,
                ValueError) as exc:
            raise SandboxError(f"{type(exc).__name__}: {exc}", text) from None

    # values: plain data only
    def value(self, node: ast.AST) -> Any:
        result = self.reference(node)
        if isinstance(result, Namespace) or self.is_namespace(result):
            raise SandboxError("a namespace is not a value")
        check_value(result)
        # each value is bounded on its own; together, held in a list or beside each other
        # while the rest is evaluated, they are bounded too
        self.made += sys.getsizeof(result)
        if self.made > MAX_EXPRESSION_BYTES:
            raise SandboxError(f"an expression whose values take more than "
                               f"{MAX_EXPRESSION_BYTES >> 20} MiB")
        if self.spend is not None:
            self.spend(1 + (len(result) if type(result) in _SIZED else 0))
        return result

    # references: may be a namespace, as the left side of a dot or a subscript
    def reference(self, node: ast.AST) -> Any:
        method = getattr(self, f"_{type(node).__name__}")
        return method(node)

    def _Constant(self, node: ast.Constant) -> Any:
        return node.value

    def _Name(self, node: ast.Name) -> Any:
        try:
            return self.lookup(node.id)
        except KeyError:
            pass
        if node.id in self.names:
            return self.names[node.id]
        raise SandboxError(f"name {node.id!r} is not defined")

    def _Attribute(self, node: ast.Attribute) -> Any:
        return self.attribute(self.reference(node.value), node.attr)

    def attribute(self, target: Any, attr: str) -> Any:
        if attr.startswith("_"):
            raise SandboxError(f"the attribute .{attr} is not allowed")
        if isinstance(target, Namespace):
            return target.member(attr)
        if self.member is not None and self.is_namespace(target):
            try:
                return self.member(target, attr)
            except KeyError:
                raise SandboxError(f"the namespace has no property {attr!r}") from None
        if type(target) is dict:
            if attr in target:
                return target[attr]
            if attr in _DICT_METHODS:
                return _Method(target, attr)
        if type(target) is str and attr in _STR_METHODS:
            return _Method(target, attr)
        raise SandboxError(f"the attribute .{attr} is not allowed on {type(target).__name__}")

    def _Subscript(self, node: ast.Subscript) -> Any:
        target = self.reference(node.value)
        key = self.value(node.slice) if not isinstance(node.slice, ast.Slice) \
            else self._Slice(node.slice)
        if isinstance(target, Namespace) or self.is_namespace(target):
            if not isinstance(key, str):
                raise SandboxError("a namespace is indexed by a name")
            return self.attribute(target, key)
        if type(target) not in (dict, list, tuple, str):
            raise SandboxError(f"a {type(target).__name__} cannot be indexed")
        return target[key]

    def _Slice(self, node: ast.Slice) -> slice:
        parts = [None if n is None else self.value(n) for n in (node.lower, node.upper, node.step)]
        return slice(*parts)

    def _BinOp(self, node: ast.BinOp) -> Any:
        left, right = self.value(node.left), self.value(node.right)
        func, guard = _BINARY[type(node.op)]
        if guard is not None:
            guard(left, right)
        return func(left, right)

    def _UnaryOp(self, node: ast.UnaryOp) -> Any:
        return _UNARY[type(node.op)](self.value(node.operand))

    def _BoolOp(self, node: ast.BoolOp) -> Any:
        result: Any = None
        for operand in node.values:
            result = self.value(operand)
            if bool(result) == isinstance(node.op, ast.Or):
                return result
        return result

    def _Compare(self, node: ast.Compare) -> Any:
        left = self.value(node.left)
        for op, comparator in zip(node.ops, node.comparators):
            right = self.value(comparator)
            if not _COMPARE[type(op)](left, right):
                return False
            left = right
        return True

    def _IfExp(self, node: ast.IfExp) -> Any:
        return self.value(node.body if self.value(node.test) else node.orelse)

    def _Call(self, node: ast.Call) -> Any:
        func = self.value(node.func)
        if not isinstance(func, (Function, _Method)):
            raise SandboxError(f"a {type(func).__name__} cannot be called")
        args = [self.value(a) for a in node.args]
        kwargs = {k.arg: self.value(k.value) for k in node.keywords if k.arg is not None}
        return func(*args, **kwargs)

    def _List(self, node: ast.List) -> Any:
        return [self.value(e) for e in node.elts]

    def _Tuple(self, node: ast.Tuple) -> Any:
        return tuple(self.value(e) for e in node.elts)

    def _Set(self, node: ast.Set) -> Any:
        return {self.value(e) for e in node.elts}

    def _Dict(self, node: ast.Dict) -> Any:
        return {self.value(k): self.value(v) for k, v in zip(node.keys, node.values)
                if k is not None}


def evaluate(text: str, lookup: Lookup, names: Mapping[str, Any] | None = None) -> Any:
    """Evaluate ``text`` with properties from ``lookup`` and the sandbox's own names."""
    return Evaluator(lookup, base_globals() if names is None else names).evaluate(text)
