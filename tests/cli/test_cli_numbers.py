"""Every numeric option of the verbs, fed anything: a result or a clear usage/safety error
(exit 0, 2 or 5), never an internal error or a traceback (issue 14's CLI part)."""

from __future__ import annotations

import math

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

PROFILE = ("-p", "rrbot-gpio", "--sim")  # an in-process mock: no transport to wait for
NUMBERS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(min_value=-10**30, max_value=10**30).map(str),
    st.sampled_from(["nan", "inf", "-inf", "1e309", "-0", "0x10", "5deg", "1,5", "", " "]),
    st.text(max_size=12),
)
RUNS = settings(max_examples=60, deadline=None, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture])


def _clean(result) -> None:  # type: ignore[no-untyped-def]
    assert result.exit_code in (0, 2, 5), (result.exit_code, result.stderr)
    assert "internal error" not in result.stderr and "Traceback" not in result.stderr


def _bad_or_short(text: str) -> bool:
    """Values that either fail to parse or would make the loop short (the test must end)."""
    try:
        value = float(text)
    except ValueError:
        return True
    return not math.isfinite(value) or value <= 0.2


@RUNS
@given(NUMBERS)
def test_stream_rate(cli, text):
    _clean(cli(*PROFILE, "--json", "stream", "--duration", "0.05", "--rate", text))


@RUNS
@given(NUMBERS.filter(_bad_or_short))
def test_stream_duration(cli, text):
    _clean(cli(*PROFILE, "--json", "stream", "--rate", "100", "--duration", text))


@RUNS
@given(NUMBERS)
def test_jog_delta_and_velocity(cli, text):
    _clean(cli(*PROFILE, "--yes", "--json", "jog", "joint1", "--", text))
    _clean(cli(*PROFILE, "--yes", "--json", "jog", "joint1", "0.1", "--velocity", text))


@RUNS
@given(NUMBERS.filter(lambda t: not t.strip().isdigit() or int(t) > 10**5 or int(t) < 1))
def test_connect_count(cli, text):
    _clean(cli(*PROFILE, "connect", "--count", text))
