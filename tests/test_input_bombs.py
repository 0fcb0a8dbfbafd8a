"""Bounded input measured in memory: a hostile xacro expression, an MCAP chunk that unpacks to
gigabytes or lies about its size, a recording whose summary lies about its commands.

Each bomb runs as a real ``deltoctl`` command in a child of a small wrapper process, which
reports the peak memory (maxrss) of that child alone: the command must exit 2 with one clear
line naming the file and what was refused, and its peak must stay far below what the bomb
would take (a plain `info` or `profile show` peaks at about 30 MB, ``BASELINE`` below).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from xml.sax.saxutils import quoteattr

import pytest

PEAK_MB = 300  # generous: ten times a plain command's peak, far below any bomb's
XACRO = ('<?xml version="1.0"?>\n<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">\n'
         '{body}\n</robot>\n')
_WRAPPER = """\
import json, resource, subprocess, sys
done = subprocess.run(sys.argv[1:], capture_output=True, text=True)
peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
print(json.dumps({"code": done.returncode, "stdout": done.stdout, "stderr": done.stderr,
                  "peak_mb": peak / 1024}))
"""


def deltoctl(*args: str) -> dict:
    """Run ``deltoctl ARGS`` in a fresh process: its exit code, output and peak memory (MB)."""
    wrapper = subprocess.run([sys.executable, "-c", _WRAPPER, sys.executable, "-m", "deltoctl",
                              *args], capture_output=True, text=True, timeout=300, check=True)
    return json.loads(wrapper.stdout)


def refused(result: dict, *words: str) -> str:
    """One line on stderr with ``words``, exit 2, no traceback, a bounded peak."""
    assert result["code"] == 2, result
    assert "Traceback" not in result["stderr"] and "internal error" not in result["stderr"]
    lines = result["stderr"].strip().splitlines()
    assert len(lines) == 1, result["stderr"]
    for word in words:
        assert word in lines[0], lines[0]
    assert result["peak_mb"] < PEAK_MB, result
    return lines[0]


# -- xacro ---------------------------------------------------------------------------------------

def _xacro(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "bomb.xacro"
    path.write_text(XACRO.format(body=body))
    return path


def test_a_profile_command_peaks_at_a_few_tens_of_megabytes(tmp_path):
    """The reference the bounds below are judged against."""
    path = _xacro(tmp_path, '<link name="${len(\'ab\' * 10)}"/>')
    result = deltoctl("-p", str(path), "profile", "validate")
    assert result["code"] == 2 and "no <ros2_control> block" in result["stderr"], result
    assert result["peak_mb"] < 100, result


@pytest.mark.parametrize(("expression", "what"), [
    ("len(('b'*1500).join('a'*1000000))", "str.join() of 1500998500 characters"),
    ("len(('a'*1000).join(['b']*2000))", "str.join()"),
    ("len('x'.ljust(999999999))", "a width of 999999999 characters"),
    ("len('1'.zfill(10**9))", "a width of"),
    ("len('x'.center(10**9))", "a width of"),
    ("len(('\\t'*100000).expandtabs(1000))", "str.expandtabs()"),
    ("len(('ab'*500000).replace('a', 'x'*1000))", "str.replace()"),
    ("len(list('a'*1000000))", "a list of 1000000 characters"),
    ("len(sorted('a'*1000000))", "a list of 1000000 characters"),
    ("len(('a '*500000).split())", "str.split() into 500000 pieces"),
    ("len(xacro.tokenize('a,'*500000))", "xacro.tokenize() into"),
    ("len('a'*10**9)", "repeating a str"),
    ("len([0]*10**9)", "repeating a list"),
    ("len('%0999999999d' % 1)", "'%' formatting"),
    ("3**100000", "an integer larger than 10000 bits"),
    ("(1<<9000)<<9000", "an integer larger than 10000 bits"),
    ("len(['\U0001F600'*1000000, '\U0001F600'*1000000, '\U0001F600'*1000000, "
     "'\U0001F600'*1000000, '\U0001F600'*1000000])", "values take more than 16 MiB"),
    # operands held while the right side is evaluated: each one small, together too large
    ("len(" + "('a'*500000+" * 40 + "'a'" + ")" * 41, "values take more than 16 MiB"),
])
def test_an_expression_that_would_make_a_large_value_is_refused_before_making_it(
        tmp_path, expression, what):
    value = quoteattr("${" + expression + "}")
    path = _xacro(tmp_path, f'<xacro:property name="x" value={value}/><link name="${{x}}"/>')
    line = refused(deltoctl("-p", str(path), "profile", "show"), str(path), what)
    assert "xacro failed" in line


def test_the_join_bomb_peaks_far_below_what_it_would_make(tmp_path):
    """400 bytes that would make a 1.5 GB string: refused from the operands' sizes."""
    path = _xacro(tmp_path, '<link name="${len((\'b\'*1500).join(\'a\'*1000000))}"/>')
    assert path.stat().st_size < 400
    result = deltoctl("-p", str(path), "profile", "show")
    refused(result, "str.join()", "beyond 1048576")
    assert result["peak_mb"] < 100, result


@pytest.mark.parametrize("substitution", ["$(optenv HOME x)", "$(optenv HOME)", "$(env HOME)",
                                          "$(optenv DELTOCTL_NOT_SET a default)"])
def test_an_environment_variable_is_refused_saying_why(tmp_path, substitution):
    path = _xacro(tmp_path, f'<link name="{substitution}"/>')
    line = refused(deltoctl("-p", str(path), "profile", "show"), str(path),
                   f"{substitution} is refused", "does not read environment variables",
                   "--arg")
    assert "TypeError" not in line and "<class" not in line
