"""The exchange policy every family configures: tries, what is tried again, what is an answer,
and when a lost link is reopened."""

import pytest

from deltoctl.core.exchange import ExchangePolicy, Reopener
from deltoctl.errors import DeviceError, DeviceFault, LinkLost, NoAnswer, ProtocolError


def attempts(*outcomes):
    """An attempt that raises or returns each outcome in turn, and the calls it saw."""
    calls = []

    def attempt():
        outcome = outcomes[len(calls)]
        calls.append(outcome)
        if isinstance(outcome, Exception):
            raise outcome
        return outcome

    return attempt, calls


def test_no_answer_and_bad_bytes_are_tried_again_and_counted():
    attempt, calls = attempts(NoAnswer("quiet"), ProtocolError("bad crc"), "status")
    stats = {"packets": 0, "errors": 0}
    assert ExchangePolicy(tries=3).run(attempt, "read servo 1", stats) == "status"
    assert len(calls) == 3
    assert stats == {"packets": 3, "errors": 2}


def test_after_the_last_try_no_answer_names_what_and_the_tries():
    attempt, calls = attempts(*[ProtocolError("bad crc")] * 5)
    with pytest.raises(NoAnswer, match=r"read servo 7 \(5 tries\): bad crc"):
        ExchangePolicy(tries=5).run(attempt, "read servo 7")
    assert len(calls) == 5


@pytest.mark.parametrize("answer", [DeviceFault("overload", code=0x20), LinkLost("unplugged")])
def test_a_device_error_or_a_lost_link_is_an_answer_not_tried_again(answer):
    attempt, calls = attempts(answer, "never")
    with pytest.raises(type(answer)):
        ExchangePolicy(tries=3).run(attempt, "write")
    assert len(calls) == 1


def test_causes_are_told_apart_under_the_exit_code_classes():
    assert issubclass(NoAnswer, DeviceError) and issubclass(DeviceFault, DeviceError)
    assert DeviceFault("angle limit", code=0x02).code == 0x02
    assert not issubclass(NoAnswer, DeviceFault)


@pytest.mark.parametrize("bad", [dict(tries=0), dict(timeout=0), dict(pause=-1),
                                 dict(reopen_period=0)])
def test_a_policy_without_tries_or_time_is_refused(bad):
    with pytest.raises(ValueError):
        ExchangePolicy(**bad)


def test_a_lost_link_is_reopened_one_period_apart_in_rounds():
    now = [100.0]
    link = Reopener(ExchangePolicy(reopen_period=1.0, reopen_tries=2), clock=lambda: now[0])
    assert not link.due()  # up: nothing to reopen
    link.lost()
    assert not link.due()
    now[0] += 1.0
    assert link.due()
    assert not link.failed()  # the first of two
    assert not link.due()
    now[0] += 1.0
    assert link.failed()  # the round is over
    now[0] += 1.0
    assert link.due()
    link.reopened()
    assert not link.due() and link.reconnects == 1 and not link.is_lost
