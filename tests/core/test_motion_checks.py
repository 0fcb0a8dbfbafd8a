"""The checks before any move: hard limits (one bound or two), soft limits, the jog step."""

from __future__ import annotations

import pytest

from deltoctl.core.envelope import check_target
from deltoctl.errors import Refused
from deltoctl.profile.model import Component, Limits, Profile, Safety, SoftLimits


def _joint(**kw) -> Component:
    return Component("joint", "j", **kw)


@pytest.mark.parametrize(("target", "refused"), [(2.0, "limits [-inf, 1.0000]"),
                                                  (0.7, "soft limits"), (0.2, None)])
def test_limits_and_soft_limits(target, refused):
    joint = _joint(limits=Limits(upper=1.0), soft_limits=SoftLimits(-0.5, 0.5))
    if refused is None:
        check_target(Profile("p"), joint, target, None)
        return
    with pytest.raises(Refused, match=refused.replace("[", r"\[")):
        check_target(Profile("p"), joint, target, None)


def test_the_jog_step():
    profile = Profile("p", safety=Safety(max_jog_step=0.1))
    check_target(profile, _joint(), 0.3, 0.25)
    with pytest.raises(Refused, match="max_jog_step"):
        check_target(profile, _joint(), 0.3, 0.1)
