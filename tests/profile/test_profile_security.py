"""A profile is untrusted input: nothing in it runs as code (issue 14).

xacro hands ``${…}`` and ``$(eval …)`` to Python's eval; deltoctl evaluates them in its own
sandbox instead. Every known way out of an eval sandbox is tried here, both against the
sandbox itself and through a xacro file, and each must end in a clean ProfileError (exit 2)
with nothing run; the expressions real xacro files use must still work.
"""

from __future__ import annotations

import math
import os
import time
from pathlib import Path
from xml.sax.saxutils import escape

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from deltoctl.errors import ProfileError
from deltoctl.profile.catalog import load_profile
from deltoctl.profile.exporter import to_urdf, to_yaml, xacro_literal
from deltoctl.profile.xacro_sandbox import SandboxError, evaluate

CANARY = "/tmp/deltoctl-sandbox-canary"  # what an escape that ran would create
HEAD = '<?xml version="1.0"?>\n<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">\n'
KINEMATICS = (
    '<link name="base"/><link name="l1"/>\n'
    '<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>'
    '<limit lower="-1" upper="1" velocity="1" effort="1"/></joint>\n')


def robot(value: str, before: str = "") -> str:
    """A one-joint xacro robot whose block has the param ``p`` = ``value`` (raw XML text)."""
    return (HEAD + before + KINEMATICS +
            '<ros2_control name="b" type="system"><hardware>'
            '<plugin>mock_components/GenericSystem</plugin>'
            f'<param name="p">{value}</param></hardware>\n'
            '<joint name="j1"><command_interface name="position"/>'
            '<state_interface name="position"/></joint>\n</ros2_control>\n</robot>\n')


def write(directory: Path, value: str, before: str = "", name: str = "r.urdf.xacro") -> Path:
    path = directory / name
    path.write_text(robot(value, before))
    return path


def param(path: Path, **kwargs) -> str:
    return load_profile(path, **kwargs).hardware[0].params["p"]


@pytest.fixture(autouse=True)
def no_canary():
    Path(CANARY).unlink(missing_ok=True)
    yield
    assert not os.path.exists(CANARY), "an expression from a profile ran code"


# -- the escapes ----------------------------------------------------------------------------------

TOUCH = f"touch {CANARY}"
ESCAPES = [
    # the classic ways to the builtins or os
    f"__import__('os').system('{TOUCH}')",
    "__import__",
    "__builtins__",
    "__builtins__['eval']('1')",
    "__loader__",
    "__spec__",
    "__name__",
    f"eval(\"__import__('os').system('{TOUCH}')\")",
    "exec('x = 1')",
    "compile('1', 'f', 'eval')",
    "open('/etc/passwd').read()",
    "globals()",
    "locals()",
    "vars()",
    "dir()",
    "input()",
    "breakpoint()",
    "help()",
    "getattr(1, '__class__')",
    "getattr(1, '\\x5f\\x5fclass\\x5f\\x5f')",
    "setattr(math, 'pi', 3)",
    "delattr(math, 'pi')",
    "type(1)",
    "type('x', (), {})",
    "object",
    "super()",
    "isinstance(1, int)",
    "issubclass(int, object)",
    "hash(1)",
    "id(1)",
    "memoryview(b'x')",
    "bytearray(3)",
    "print('x')",
    "range(10)",
    "map(str, [1])",
    "os",
    "sys",
    "subprocess",
    "builtins",
    "importlib",
    # attribute walks to __subclasses__ / __globals__
    "().__class__.__bases__[0].__subclasses__()",
    "''.__class__.__mro__[1].__subclasses__()",
    "[].__class__.__base__.__subclasses__()",
    "(1).__class__",
    "True.__class__",
    "None.__class__",
    "dict(a=1).__class__",
    "max.__self__",
    "max.func",
    "str.mro()",
    "int.from_bytes(b'x', 'big')",
    "dict.fromkeys('a')",
    "(1).real",
    "''.join.__self__",
    "'a'.lower.__call__",
    "{}.keys.__self__",
    "radians.__module__",
    "math.__dict__",
    "math.sys",
    "math.factorial(100000)",
    "math['__dict__']",
    "().__\uff43lass__",  # a fullwidth c: NFKC makes the name '__class__'
    "().__\uff43lass__.__mro__[1].__subclasses__()",
    # xacro's own namespaces and functions
    "xacro.load_yaml.__globals__['os'].system('x')",
    "load_yaml.__globals__",
    "xacro.abs_filename('x')",
    "xacro.print_location()",
    "xacro.os",
    "xacro.NameSpace",
    "xacro.arg.__globals__",
    "python.type(0)",
    "python.vars(python.type)['__subclasses__'](python.type)",
    "python.isinstance(1, 1)",
    "python.getattr",
    "python.__builtins__",
    "python['type']",
    "python.eval",
    # syntax that is refused whatever it contains
    "f'{1}'",
    "f'{().__class__}'",
    "(lambda: 1)()",
    "(lambda f: f.__globals__)(max)",
    "[c for c in ().__class__.__base__.__subclasses__()]",
    "[x for x in [1]]",
    "{x: 1 for x in 'a'}",
    "{x for x in 'a'}",
    "list(x for x in 'ab')",
    "(x := 1)",
    "max(*[1, 2])",
    "dict(**{'a': 1})",
    "{**{'a': 1}}",
    "b'bytes'",
    "...",
    # format strings reach attributes without a dot in the expression
    "'{0.__class__}'.format(1)",
    "'{0.__class__.__base__}'.format('')",
    "'{a.__class__}'.format_map({'a': 1})",
    "'%s' % 1",
    "'%(a)s' % {'a': 1}",
    "'x'.encode()",
    "'x'.translate({})",
    # resources: each would take minutes or gigabytes
    "9**9**9**9",
    "10**10**10",
    "2**100000",
    "'a'*10**10",
    "[0]*10**9",
    "1 << 10**10",
    "round(5, -10**9)",
    "('x'*1000000).replace('x', 'yy')",
    "str([[0]*100000]*100000)",
    "[[0]*100000]*100000",
    "','.join(['x'*100000]*100)",
    "'x'*4097 + 'x'*(2**20)",
]


@pytest.mark.parametrize("expression", ESCAPES)
def test_the_sandbox_refuses_each_escape(expression):
    started = time.monotonic()
    with pytest.raises(SandboxError) as caught:
        evaluate(expression, {"x": 1.0}.__getitem__)
    assert time.monotonic() - started < 5
    assert "\n" not in str(caught.value)


@pytest.mark.parametrize("expression", ESCAPES)
def test_a_xacro_file_with_an_escape_is_a_profile_error(cli, tmp_path, expression):
    path = write(tmp_path, "${" + escape(expression) + "}")
    started = time.monotonic()
    with pytest.raises(ProfileError) as caught:
        load_profile(path)
    assert time.monotonic() - started < 5
    assert caught.value.source == str(path)
    result = cli("profile", "validate", str(path))
    assert result.exit_code == 2
    assert "Traceback" not in result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and str(path) in lines[0], result.stderr


EVAL_ESCAPES = [  # what fits in $( … ): xacro's lexer ends it at the first ')'
    "__import__", "__builtins__", "open", "eval", "exec", "globals", "compile", "env",
    "optenv", "true.__class__", "arg.__globals__", "find.__globals__", "dirname.__code__",
    "[c for c in 'ab']", "lambda: 1", "f'{1}'", "'{0.__class__}'.format", "python.type",
    "xacro.load_yaml", "9**9**9**9", "'a'*10**10",
]


@pytest.mark.parametrize("expression", EVAL_ESCAPES)
def test_eval_substitution_goes_through_the_sandbox(tmp_path, expression):
    path = write(tmp_path, "$(eval " + escape(expression) + ")")
    with pytest.raises(ProfileError):
        load_profile(path)


@pytest.mark.parametrize("where", [
    # places where xacro evaluates other than a text
    '<xacro:property name="bad" value="${{{e}}}"/><link name="${{bad}}"/>',
    '<xacro:property name="bad" value="${{{e}}}" lazy_eval="false"/>',
    '<xacro:property name="${{{e}}}" value="1"/>',
    '<xacro:macro name="m" params="a:=${{{e}}}"><link name="${{a}}"/></xacro:macro><xacro:m/>',
    '<xacro:if value="${{{e}}}"><link name="z"/></xacro:if>',
    '<xacro:element xacro:name="${{{e}}}"/>',
    '<link name="z"><xacro:attribute name="a" value="${{{e}}}"/></link>',
    '<xacro:call macro="${{{e}}}"/>',
    '<!-- xacro:eval-comments --><!-- ${{{e}}} --><link name="z"/>',
    '<xacro:include filename="${{{e}}}"/>',
    '<xacro:arg name="a" default="${{{e}}}"/>',
])
def test_every_place_xacro_evaluates_is_sandboxed(tmp_path, where):
    before = where.format(e=escape(f"__import__('os').system('{TOUCH}')"))
    with pytest.raises(ProfileError, match="not allowed"):
        load_profile(write(tmp_path, "x", before))


@pytest.mark.parametrize("expression", [
    "inc.type", "inc.vars", "inc.python", "inc.xacro", "inc.parent", "inc.root", "inc['type']",
    "inc.__dict__", "inc.prop.__class__", "inc", "str(inc)", "[inc]", "inc == inc",
])
def test_an_included_namespace_leads_nowhere_else(tmp_path, expression):
    """xacro's namespaces chain up to its globals, which hold Python's type and vars."""
    (tmp_path / "inc.xacro").write_text(
        '<robot xmlns:xacro="http://www.ros.org/wiki/xacro">'
        '<xacro:property name="prop" value="1"/></robot>')
    before = '<xacro:include filename="inc.xacro" ns="inc"/>'
    with pytest.raises(ProfileError):
        load_profile(write(tmp_path, "${" + escape(expression) + "}", before))


def test_the_environment_is_not_read(tmp_path, monkeypatch):
    monkeypatch.setenv("DELTOCTL_SECRET", "hunter2")
    for text in ("$(env DELTOCTL_SECRET)", "$(optenv DELTOCTL_SECRET x)"):
        with pytest.raises(ProfileError, match="environment") as caught:
            load_profile(write(tmp_path, text))
        assert "hunter2" not in str(caught.value)


# -- files xacro reads ---------------------------------------------------------------------------

@pytest.fixture
def outside(tmp_path):
    """A directory beside the profile's: files a profile must not read."""
    directory = tmp_path / "outside"
    directory.mkdir()
    (directory / "secret.yaml").write_text("token: hunter2\n")
    (directory / "secret.xacro").write_text(
        '<robot xmlns:xacro="http://www.ros.org/wiki/xacro"><link name="hunter2"/></robot>')
    profile_dir = tmp_path / "profile"
    profile_dir.mkdir()
    return profile_dir, directory


@pytest.mark.parametrize("spec", ["{out}/secret.yaml", "../outside/secret.yaml", "/etc/passwd",
                                  "/proc/self/environ", "/dev/zero", "link.yaml"])
def test_load_yaml_reads_no_file_outside_the_profile(outside, spec):
    profile_dir, out = outside
    (profile_dir / "link.yaml").symlink_to(out / "secret.yaml")
    name = spec.format(out=out)
    for expression in (f"xacro.load_yaml('{name}')", f"load_yaml('{name}')['token']"):
        with pytest.raises(ProfileError, match="outside the profile's directory") as caught:
            load_profile(write(profile_dir, "${" + expression + "}"))
        assert "hunter2" not in str(caught.value)


@pytest.mark.parametrize("spec", ["{out}/secret.xacro", "../outside/secret.xacro",
                                  "/etc/fonts/fonts.conf", "link.xacro", "/dev/zero"])
def test_include_reads_no_file_outside_the_profile(outside, spec):
    profile_dir, out = outside
    (profile_dir / "link.xacro").symlink_to(out / "secret.xacro")
    before = f'<xacro:include filename="{spec.format(out=out)}"/>'
    with pytest.raises(ProfileError, match="outside the profile's directory"):
        load_profile(write(profile_dir, "x", before))


@pytest.mark.parametrize("pattern,problem", [
    ("/*/*/*/*/*/*/*", "outside the profile's directory"),
    ("../*/*.xacro", "outside the profile's directory"),
    ("inc/*/../../../*/*", "'..' after a wildcard"),
    ("many/*.xacro", "matches more than 1000 files"),
])
def test_include_wildcards_walk_only_inside_the_profile(outside, pattern, problem):
    profile_dir, _ = outside
    if pattern.startswith("many/"):
        (profile_dir / "many").mkdir()
        for i in range(1001):
            (profile_dir / "many" / f"{i}.xacro").touch()
    started = time.monotonic()
    with pytest.raises(ProfileError, match=problem):
        load_profile(write(profile_dir, "x", f'<xacro:include filename="{pattern}"/>'))
    assert time.monotonic() - started < 5


def test_include_wildcards_inside_the_profile_work(tmp_path):
    (tmp_path / "inc").mkdir()
    for name, value in (("a", "1"), ("b", "2")):
        (tmp_path / "inc" / f"{name}.xacro").write_text(
            '<robot xmlns:xacro="http://www.ros.org/wiki/xacro">'
            f'<xacro:property name="{name}" value="{value}"/></robot>')
    path = write(tmp_path, "${a + b}", '<xacro:include filename="inc/*.xacro"/>')
    assert param(path) == "3"


def test_a_fifo_inside_the_profile_directory_does_not_block(tmp_path):
    os.mkfifo(tmp_path / "pipe.yaml")
    started = time.monotonic()
    with pytest.raises(ProfileError, match="not a regular file"):
        load_profile(write(tmp_path, "${xacro.load_yaml('pipe.yaml')}"))
    assert time.monotonic() - started < 5


def test_yaml_unit_tags_are_evaluated_in_the_sandbox(tmp_path):
    (tmp_path / "c.yaml").write_text(f"a: !degrees __import__('os').system('{TOUCH}')\n")
    with pytest.raises(ProfileError, match="not allowed"):
        load_profile(write(tmp_path, "${xacro.load_yaml('c.yaml')['a']}"))


def test_tokenize_separators_are_characters_not_a_regex(tmp_path):
    started = time.monotonic()
    path = write(tmp_path, "${xacro.tokenize('" + "a" * 40 + "X', 'a](a+)+[')}")
    assert param(path) == "['X']"
    assert time.monotonic() - started < 5


def test_plain_xacro_would_have_run_code():
    """The hole this suite closes: xacro's own safe_eval reaches any class."""
    import xacro

    symbols = dict(xacro._global_symbols)
    classes = xacro.safe_eval("python.vars(python.type)['__subclasses__'](python.type)", symbols)
    assert classes and all(isinstance(c, type) for c in classes)


# -- what still works ----------------------------------------------------------------------------

WORKING = [
    ("-2*pi", -2 * math.pi),
    ("pi/2", math.pi / 2),
    ("radians(30)", math.radians(30)),
    ("sin(x)", math.sin(0.5)),
    ("math.cos(x) + math.pi", math.cos(0.5) + math.pi),
    ("x * 4 + y / 2 - 1", 0.5 * 4 + 3 / 2 - 1),
    ("2**10 // 3 % 7", 2**10 // 3 % 7),
    ("-x if y > 2 else x", -0.5),
    ("'a' + 'b'", "ab"),
    ("name + '_joint'", "left_joint"),
    ("x < y <= 3 and not (x == y)", True),
    ("y != 3 or x", 0.5),
    ("name == 'left'", True),
    ("str(flag).lower() == 'true'", True),
    ("'type1' if str(flag).lower() == 'true' else 'default'", "type1"),
    ("[1, 2, 3][1]", 2),
    ("(1, 2)[-1]", 2),
    ("'a,b'.split(',')[1]", "b"),
    ("name.upper()", "LEFT"),
    ("dict(a=1, b=2)['b']", 2),
    ("len(name)", 4),
    ("max(1, x, y)", 3),
    ("round(2.567, 2)", 2.57),
    ("abs(-3) + int('4') + float('0.5')", 7.5),
    ("python.len('abc')", 3),
    ("xacro.tokenize('a b,c')", ["a", "b", "c"]),
    ("'$' + '{x'", "${x"),
    ("255/255", 1.0),
    ("inf > 1e308", True),
]


@pytest.mark.parametrize("expression,expected", WORKING)
def test_real_expressions_still_work(tmp_path, expression, expected):
    before = ('<xacro:property name="x" value="0.5"/><xacro:property name="y" value="3"/>'
              '<xacro:property name="name" value="left"/><xacro:property name="flag" '
              'value="true"/>')
    assert param(write(tmp_path, "${" + escape(expression) + "}", before)) == str(expected)


def test_args_find_eval_include_namespaces_and_yaml(tmp_path):
    package = tmp_path / "pkg"
    (package / "config").mkdir(parents=True)
    (package / "config" / "limits.yaml").write_text(
        "j1: {max: !degrees 90, min: -1.5}\nbase: &b {v: 1}\nmerged: {<<: *b, w: 2}\n")
    (package / "inc.xacro").write_text(
        '<robot xmlns:xacro="http://www.ros.org/wiki/xacro">'
        '<xacro:property name="prop" value="${2*3}"/></robot>')
    before = ('<xacro:arg name="side" default="left"/>'
              '<xacro:property name="cfg" value="${xacro.load_yaml(\'$(find pkg)/config/'
              'limits.yaml\')}"/>'
              '<xacro:include filename="$(find pkg)/inc.xacro" ns="inc"/>')
    value = ("$(arg side)|$(find pkg)|$(eval 1 + 2)|$(eval n * 2)|${cfg['j1']['max']}|"
             "${cfg.j1.min}|${cfg.merged.v + cfg.merged.w}|${inc.prop}|$${literal}|$(arg n)")
    got = param(write(tmp_path, value, before), xacro_args={"n": "21"},
                packages={"pkg": str(package)})
    assert got.split("|") == ["left", str(package.resolve()), "3", "42", str(math.pi / 2),
                              "-1.5", "3", "6", "${literal}", "21"]


def test_the_cli_refuses_an_escape_with_exit_2(cli, tmp_path):
    path = write(tmp_path, "${" + escape(f"__import__('os').system('{TOUCH}')") + "}")
    for verb in (["profile", "validate", str(path)], ["profile", "show", str(path)],
                 ["-p", str(path), "profile", "show"]):
        result = cli(*verb)
        assert result.exit_code == 2, result.output
        assert "Traceback" not in result.output
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and str(path) in lines[0] and "not allowed" in lines[0]


# -- only .xacro files, or --xacro, run xacro -----------------------------------------------------

def test_a_urdf_is_plain_xml_even_with_xacro_syntax(tmp_path):
    path = write(tmp_path, "${" + escape("__import__('os')") + "}$(eval 1)", name="r.urdf")
    assert param(path) == "${__import__('os')}$(eval 1)"
    with pytest.raises(ProfileError, match="not allowed"):
        param(path, xacro=True)


# -- completion and profile list evaluate nothing ------------------------------------------------

@pytest.fixture
def xacro_forbidden(monkeypatch):
    """Any xacro run fails the test."""
    import xacro

    def forbidden(*args, **kwargs):
        raise AssertionError("xacro ran")

    monkeypatch.setattr(xacro, "process_file", forbidden)


def _complete(cli, words: str) -> list[str]:
    cword = len(words.split()) - (0 if words.endswith(" ") else 1)
    result = cli(env={"_DELTOCTL_COMPLETE": "complete_bash", "COMP_WORDS": words,
                      "COMP_CWORD": str(cword)}, prog_name="deltoctl")
    assert "xacro ran" not in result.output
    return result.stdout.split()


def test_completion_never_runs_xacro(cli, tmp_path, xacro_forbidden):
    xacro_file = write(tmp_path, "1")
    urdf = write(tmp_path, "${" + escape("__import__('os')") + "}", name="r.urdf")
    assert _complete(cli, f"deltoctl profile show {xacro_file} j") == []
    assert _complete(cli, f"deltoctl -p {xacro_file} profile show j") == []
    assert _complete(cli, f"deltoctl --xacro profile show {urdf} j") == []
    assert _complete(cli, f"deltoctl profile show {urdf} j") == ["j1"]  # plain XML: read
    assert _complete(cli, f"deltoctl -p {urdf} --hardware ") == ["b"]


def test_profile_list_runs_no_xacro(cli, xacro_forbidden):
    result = cli("profile", "list", "--json")
    assert result.exit_code == 0, result.output


# -- the exporter escapes what xacro would evaluate ----------------------------------------------

NASTY = [
    "${__import__('os').system('" + TOUCH + "')}",
    "$(eval __import__)",
    "$(env HOME)",
    "$${already}",
    "$$${x}",
    "a$$b",
    "$",
    "$$",
    "x$",
    "100$ ${",
    "$(",
    "}{)(${'$'*2}",
]


def _robot_around(macro: Path, profile, directory: Path) -> Path:
    """A robot xacro that includes the exported macro of ``profile`` and calls it."""
    kinematics = to_urdf(profile).split("<ros2_control")[0].split("\n", 2)[2].split(">", 1)[1]
    name = profile.name.replace("-", "_") + "_ros2_control"
    robot_file = directory / "robot.urdf.xacro"
    robot_file.write_text(HEAD + f'<xacro:include filename="{macro}"/>\n' + kinematics +
                          f"<xacro:{name}/>\n</robot>\n")
    return robot_file


def _through_xacro(profile, directory: Path):
    """Export ``profile`` as a xacro macro and load it back through xacro."""
    macro = directory / "m.ros2_control.xacro"
    macro.write_text(to_urdf(profile, macro=True))
    return load_profile(_robot_around(macro, profile, directory))


def test_yaml_to_xacro_to_profile_gives_back_the_literal_text(cli, tmp_path):
    profile = load_profile("rrbot-gpio")
    hw = profile.hardware[0]
    hw.params.update({f"nasty_{i}": text for i, text in enumerate(NASTY)})
    joint = hw.joints[0]
    joint.params["cmd"] = NASTY[0]
    joint.command_interfaces[0].params["p"] = "$(eval 1 + 2)"
    profile.description = "costs 5$ ${per_unit}"
    yaml_file = tmp_path / "nasty.yaml"
    yaml_file.write_text(to_yaml(profile))
    assert load_profile(yaml_file) == profile  # YAML evaluates nothing
    macro = tmp_path / "m.ros2_control.xacro"
    result = cli("profile", "export", str(yaml_file), "--format", "xacro", "-o", str(macro))
    assert result.exit_code == 0, result.output
    back = load_profile(_robot_around(macro, profile, tmp_path))
    assert back == profile
    assert back.hardware[0].params["nasty_0"] == NASTY[0]


@settings(max_examples=40, deadline=None, database=None)
@given(st.text(alphabet="$${}()' \"x\\<&-", min_size=1, max_size=12).map(str.strip)
       .filter(bool))
def test_any_param_text_survives_the_xacro_export(text):
    import tempfile

    profile = load_profile("rrbot-gpio")
    profile.hardware[0].params["p"] = text
    with tempfile.TemporaryDirectory() as directory:
        assert _through_xacro(profile, Path(directory)).hardware[0].params["p"] == text


def test_xacro_literal_leaves_plain_text_alone():
    assert xacro_literal("mock_components/GenericSystem") == "mock_components/GenericSystem"
    assert xacro_literal("${x}") == "$${x}"
    assert xacro_literal("$(arg y)") == "$$(arg y)"
