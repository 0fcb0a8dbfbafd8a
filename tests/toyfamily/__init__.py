"""A family that exists only in the tests: "toy" pendulums, one float per joint over a link of
its own (``toy://``).

Its whole definition is this folder — descriptor, transport, driver, emulator — registered
with ``deltoctl.registry.register(FAMILY)`` and ``register_transport("toy", TRANSPORT)``, or
as a third-party package is, through the ``deltoctl.families`` and ``deltoctl.transports``
entry points (``ENTRY_POINTS``).
"""

from deltoctl.registry import Family, Permission, SimOption

TRANSPORT = "tests.toyfamily.transport:TRANSPORT"
# what the package's pyproject.toml would declare
ENTRY_POINTS = {"deltoctl.families": {"toy": "tests.toyfamily:FAMILY"},
                "deltoctl.transports": {"toy": TRANSPORT}}

FAMILY = Family(
    name="toy",
    summary="toy pendulums (tests only)",
    driver="tests.toyfamily.driver:ToyDriver",
    emulator="tests.toyfamily.emulator:serve",
    plugins=("toy_hardware/ToySystem",),
    schemes=("toy",),
    capabilities=frozenset({"identify", "detect", "config"}),
    refused_hint="start the pendulums: deltoctl sim serve PROFILE",
    serve_options=(SimOption("frozen", "flag", "Fault: the pendulums stand still.", False),),
    permissions=(Permission("toy-rewind", why="a new period restarts every swing",
                            given="the pendulums restart their swing",
                            hint="pass --allow toy-rewind once the pendulums may restart"),),
    identity_fields=(("version", "{}"), ("joints", "({} pendulums)")),
)
