"""Profiles with no hardware protocol: ros2_control's mock_components/GenericSystem, in-process."""

from deltoctl.registry import Family

FAMILY = Family(
    name="generic",
    summary="ros2_control mock_components/GenericSystem (in-process, no transport)",
    driver="deltoctl.families.generic.driver:GenericDriver",
    plugins=("mock_components/GenericSystem",),
    capabilities=frozenset({"identify", "detect", "home", "jog", "gpio", "config"}),
)
