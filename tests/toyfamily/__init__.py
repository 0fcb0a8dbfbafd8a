"""A family that exists only in the tests: "toy" pendulums, one float per joint over TCP.

Its whole definition is this folder — descriptor, driver, emulator — registered with
``deltoctl.registry.register(FAMILY)``, as a third-party package would be through the
``deltoctl.families`` entry point.
"""

from deltoctl.registry import Family

FAMILY = Family(
    name="toy",
    summary="toy pendulums (tests only)",
    driver="tests.toyfamily.driver:ToyDriver",
    emulator="tests.toyfamily.emulator:serve",
    plugins=("toy_hardware/ToySystem",),
    schemes=("toy",),
    capabilities=frozenset({"identify", "detect"}),
)
