"""Bounded input (issue 14): a hostile profile fails fast with exit 2 and names the limit.

Each bomb must be refused well within a second on any machine; the tests allow 5 s so that
they never depend on the machine's speed. The property tests feed the loaders any YAML or
XML text: the answer is a profile or a ProfileError, never another exception.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
import time
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from deltoctl.errors import ProfileError
from deltoctl.profile.catalog import catalog_dir, load_profile
from deltoctl.profile.exporter import to_urdf

XACRO = '<?xml version="1.0"?>\n<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">\n'
LAUGHS = ('<?xml version="1.0"?>\n<!DOCTYPE robot [\n<!ENTITY lol "lol">\n' +
          "".join(f'<!ENTITY lol{i} "{f"&lol{i - 1};" * 10 if i else "&lol;" * 10}">\n'
                  for i in range(10)) +
          ']>\n<robot name="r">&lol9;</robot>\n')
XXE = ('<?xml version="1.0"?>\n<!DOCTYPE robot [<!ENTITY x SYSTEM "file:///etc/passwd">]>\n'
       '<robot name="r"><link name="&x;"/></robot>\n')
PARAMETER_ENTITY = ('<?xml version="1.0"?>\n<!DOCTYPE robot [<!ENTITY % p SYSTEM '
                    '"http://example.invalid/x.dtd"> %p;]>\n<robot name="r"/>\n')
YAML_BOMB = 'a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]\n' + "".join(
    f"{chr(98 + i)}: &{chr(98 + i)} [{', '.join([f'*{chr(97 + i)}'] * 9)}]\n" for i in range(8))


def refused(cli, path: Path, *match: str, options: tuple[str, ...] = (),
            named: Path | None = None) -> str:
    """``profile validate`` exits 2 within 5 s with one line naming the file (or ``named``,
    the file at fault) and ``match``."""
    started = time.monotonic()
    result = cli(*options, "profile", "validate", str(path))
    assert time.monotonic() - started < 5
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and str(named or path) in lines[0], result.stderr
    for text in match:
        assert text in lines[0], lines[0]
    return lines[0]


# -- size ----------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def newlines_100mb(tmp_path_factory):
    path = tmp_path_factory.mktemp("big") / "newlines"
    with path.open("wb") as f:
        chunk = b"\n" * (1 << 20)
        for _ in range(100):
            f.write(chunk)
    yield path
    path.unlink()


@pytest.mark.parametrize("name", ["big.yaml", "big.urdf", "big.urdf.xacro", "big.xml"])
def test_a_100_mb_file_is_refused_before_it_is_read(cli, newlines_100mb, tmp_path, name):
    path = tmp_path / name
    path.symlink_to(newlines_100mb)
    refused(cli, path, "larger than 16 MiB")


def test_an_include_over_the_size_limit_is_refused(cli, tmp_path):
    big = tmp_path / "big.xacro"
    with big.open("wb") as f:
        f.truncate(100 << 20)  # sparse: 100 MB that take no disk
    path = tmp_path / "r.urdf.xacro"
    path.write_text(XACRO + '<xacro:include filename="big.xacro"/></robot>\n')
    refused(cli, path, "larger than 16 MiB", named=big)


def test_a_fifo_is_refused_without_blocking(cli, tmp_path):
    path = tmp_path / "pipe.yaml"
    os.mkfifo(path)
    refused(cli, path, "not a regular file", options=("-p", str(path)))


# -- XML -----------------------------------------------------------------------------------------

@pytest.mark.parametrize("text", [LAUGHS, XXE, PARAMETER_ENTITY], ids=["laughs", "xxe", "param"])
@pytest.mark.parametrize("name", ["r.urdf", "r.urdf.xacro"])
def test_xml_entities_are_refused(cli, tmp_path, text, name):
    path = tmp_path / name
    path.write_text(text)
    line = refused(cli, path, "entity declarations are not allowed")
    assert "root:" not in line  # /etc/passwd was not read


def test_an_entity_bomb_in_an_included_file_is_refused(cli, tmp_path):
    (tmp_path / "inc.xacro").write_text(LAUGHS)
    path = tmp_path / "r.urdf.xacro"
    path.write_text(XACRO + '<xacro:include filename="inc.xacro"/></robot>\n')
    refused(cli, path, "entity declarations are not allowed", named=tmp_path / "inc.xacro")


@pytest.mark.parametrize("name", ["r.urdf", "r.urdf.xacro"])
def test_deep_xml_is_refused(cli, tmp_path, name):
    path = tmp_path / name
    path.write_text('<robot name="r">' + "<a>" * 100_000 + "</a>" * 100_000 + "</robot>")
    refused(cli, path, "nested deeper than 256")


# -- YAML ----------------------------------------------------------------------------------------

def test_a_yaml_alias_bomb_is_refused(cli, tmp_path):
    path = tmp_path / "bomb.yaml"
    path.write_text(YAML_BOMB)
    refused(cli, path, "alias")


def test_a_yaml_alias_bomb_through_xacro_load_yaml_is_refused(cli, tmp_path):
    (tmp_path / "bomb.yaml").write_text(YAML_BOMB)
    path = tmp_path / "r.urdf.xacro"
    path.write_text(XACRO + '<link name="${xacro.load_yaml(\'bomb.yaml\')}"/></robot>\n')
    refused(cli, path, "alias", named=tmp_path / "bomb.yaml")


@pytest.mark.parametrize("text", ["a: " + "[" * 100_000 + "]" * 100_000,
                                  "".join(" " * i + "- \n" for i in range(1000)),
                                  "a: " + "{b: " * 50_000 + "}" * 50_000],
                         ids=["flow", "block", "mappings"])
def test_deep_yaml_is_refused(cli, tmp_path, text):
    path = tmp_path / "deep.yaml"
    path.write_text(text)
    refused(cli, path, "nested deeper than 64")


def test_a_self_referencing_alias_is_refused(cli, tmp_path):
    path = tmp_path / "loop.yaml"
    path.write_text("name: &a [*a]\n")
    refused(cli, path, "refers to itself")


@pytest.mark.parametrize("text", ["? [a, b]\n: 1\n", "{[1]: 2}\n", "? {a: 1}\n: 2\n",
                                  "? !!set {a}\n: 1\n", "name: x\nros2_control:\n  - {[1]: 2}\n"])
def test_an_unhashable_key_is_a_profile_error(cli, tmp_path, text):
    path = tmp_path / "keys.yaml"
    path.write_text(text)
    refused(cli, path, "a mapping key must be a single value")


@pytest.mark.parametrize("text", ["name: 2001-02-30\n", "name: " + "9" * 5000 + "\n",
                                  "a: !!python/object/apply:os.system ['echo hi']\n",
                                  "name: !!float abc\n", "a: 1\n---\nb: 2\n"])
def test_other_bad_yaml_is_a_profile_error(cli, tmp_path, text):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    refused(cli, path, "not valid YAML")


# -- xacro expansion -----------------------------------------------------------------------------

def test_a_macro_bomb_is_refused(cli, tmp_path):
    macros = ['<xacro:macro name="m0" params=""><link name="x"/></xacro:macro>'] + [
        f'<xacro:macro name="m{i}" params=""><xacro:m{i - 1}/><xacro:m{i - 1}/></xacro:macro>'
        for i in range(1, 40)]
    path = tmp_path / "bomb.urdf.xacro"
    path.write_text(XACRO + "\n".join(macros) + "\n<xacro:m39/></robot>\n")
    refused(cli, path, "exceeds 50000 XML nodes")


def test_a_macro_with_a_huge_unused_body_is_refused(cli, tmp_path):
    body = "<!--c-->" * 100_000
    path = tmp_path / "wide.urdf.xacro"
    path.write_text(XACRO + f'<xacro:macro name="w" params=""><xacro:if value="false">{body}'
                    "</xacro:if></xacro:macro>" + "<xacro:w/>" * 1000 + "</robot>\n")
    refused(cli, path, "exceeds 50000 XML nodes")


def test_text_made_by_expressions_is_bounded(cli, tmp_path):
    uses = "".join(f'<link name="${{s + \'{i}\'}}"/>' for i in range(100))
    path = tmp_path / "text.urdf.xacro"
    path.write_text(XACRO + "<xacro:property name=\"s\" value=\"${'x'*1000000}\"/>" + uses +
                    "</robot>\n")
    refused(cli, path, "MiB of text")


def test_the_work_of_all_expressions_is_bounded(cli, tmp_path):
    expression = "len((" + ",".join(["1"] * 900) + "))"
    path = tmp_path / "steps.urdf.xacro"
    path.write_text(XACRO + f'<xacro:macro name="m" params=""><link name="${{{expression}}}"/>'
                    "</xacro:macro>" + "<xacro:m/>" * 2000 + "</robot>\n")
    refused(cli, path, "more than 100000 steps")


def test_a_text_that_would_make_xacro_lexer_quadratic_is_refused(cli, tmp_path):
    path = tmp_path / "dollars.urdf.xacro"
    path.write_text(XACRO + '<link name="x">' + "$a" * 500_000 + "</link></robot>\n")
    refused(cli, path, "too costly to expand")


# -- any input: a profile or a ProfileError ------------------------------------------------------

def _load_text(text: str, suffix: str) -> None:
    with tempfile.TemporaryDirectory() as directory:
        path = Path(directory) / f"p{suffix}"
        path.write_text(text, encoding="utf-8", errors="surrogatepass")
        with contextlib.suppress(ProfileError):  # anything else fails the test
            load_profile(path)


SCALARS = st.one_of(
    st.none(), st.booleans(), st.integers(), st.floats(), st.text(max_size=6),
    st.sampled_from(["1deg", "-30deg", "0x11", "nan", "inf", "-inf", "1e999", "", "true",
                     "tcp://1.2.3.4:5", "serial:///dev/null", "position", "velocity", "effort",
                     "mock_components/GenericSystem", "delto", "dynamixel", "system", "j1"]))
VALUES = st.recursive(SCALARS, lambda inner: st.lists(inner, max_size=4) |
                      st.dictionaries(st.text(max_size=6) | st.sampled_from(
                          ["name", "joints", "params", "limits", "min", "max", "bus"]),
                          inner, max_size=4), max_leaves=20)
CATALOG = {p.stem: yaml.safe_load(p.read_text()) for p in sorted(catalog_dir().glob("*.yaml"))}


@st.composite
def mutated_profiles(draw) -> object:
    """A catalog profile with a few parts replaced by anything."""
    data = draw(st.sampled_from(sorted(CATALOG)))
    data = yaml.safe_load(yaml.safe_dump(CATALOG[data]))
    for _ in range(draw(st.integers(1, 4))):
        node = data
        while isinstance(node, (dict, list)) and node and draw(st.booleans()):
            key = draw(st.sampled_from(sorted(node, key=str) if isinstance(node, dict)
                                       else range(len(node))))
            if not isinstance(node[key], (dict, list)) or not draw(st.booleans()):
                node[key] = draw(VALUES)
                break
            node = node[key]
    return data


PROPERTY = settings(max_examples=150, deadline=None, database=None,
                    suppress_health_check=[HealthCheck.too_slow])


@PROPERTY
@given(st.text(max_size=200) | st.text(alphabet=":-[]{},&*!|>'\"#%@`?<= \n\tab01.", max_size=80))
def test_any_yaml_text_gives_a_profile_or_a_profile_error(text):
    _load_text(text, ".yaml")


@settings(PROPERTY, max_examples=50)
@given(mutated_profiles())
def test_any_yaml_profile_gives_a_profile_or_a_profile_error(data):
    _load_text(yaml.safe_dump(data, allow_unicode=True), ".yaml")


FRAGMENTS = ['<joint name="j"/>', '<param name="deltoctl.address">nan</param>',
             '<limit lower="nan" upper="inf" velocity="-1" effort="1e999"/>', "<!DOCTYPE r>",
             '<state_interface name="position"/>', '<ros2_control name="b" type="x">',
             "</ros2_control>", '<joint name="j1" type="prismatic">', "&amp;", "&bogus;",
             '<command_interface name="position"><param name="min">2</param></command_interface>',
             '<mimic joint="j1" multiplier="x"/>', "<robot>", "</robot>", "\x00", "]]>", "<![CDATA["]
URDF = [to_urdf(load_profile(name)) for name in ("rrbot-gpio", "dg-3f-b", "bioscara-arm")]


@st.composite
def mutated_urdf(draw) -> str:
    text = draw(st.sampled_from(URDF))
    for _ in range(draw(st.integers(1, 4))):
        start = draw(st.integers(0, len(text)))
        end = draw(st.integers(start, min(len(text), start + 200)))
        insert = draw(st.sampled_from(FRAGMENTS) | st.text(max_size=5) | st.just(""))
        text = text[:start] + insert + text[end:]
    return text


@PROPERTY
@given(st.text(max_size=200) | st.text(alphabet='<>/="\' \nabrotjinx&;!-?[]', max_size=80))
def test_any_xml_text_gives_a_profile_or_a_profile_error(text):
    _load_text(text, ".urdf")


@PROPERTY
@given(mutated_urdf())
def test_any_urdf_gives_a_profile_or_a_profile_error(text):
    _load_text(text, ".urdf")


def test_the_limits_are_named_in_the_trust_model():
    # `deltoctl help trust-model` and the manual's page print this file
    text = (Path(__file__).resolve().parents[2] / "deltoctl/topics/trust-model.md").read_text()
    assert "16 MiB" in text and "at most 256 deep" in text
