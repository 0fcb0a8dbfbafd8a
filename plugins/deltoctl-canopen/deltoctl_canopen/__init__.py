"""CANopen CiA 402 servo drives for deltoctl: a family in a package of its own.

Installed, it adds the ``canopen`` family (ros2_control plugin ``canopen_ros2_control/
Cia402System``) through the ``deltoctl.families`` entry point, and the ``localhub`` python-can
interface through ``can.interface``. This module is what deltoctl reads at start-up: data and
strings only; the driver, the emulator, python-can and canopen load when a block is opened.
"""

from deltoctl.registry import Family, Permission, SimOption

__version__ = "0.1.0"

FAMILY = Family(
    name="canopen",
    summary="CANopen CiA 402 servo drives (python-can bus, plugin deltoctl-canopen)",
    driver="deltoctl_canopen.driver:CanopenDriver",
    frame_names="deltoctl_canopen.codec:frame_name",
    emulator="deltoctl_canopen.emulator:serve",
    link_scan="deltoctl_canopen.scan:scan_link",
    link_setup="deltoctl_canopen.addressing:addressing",
    plugins=("canopen_ros2_control/Cia402System",),
    schemes=("can",),
    address_range=(1, 127),
    address_param="node_id",
    address_kind="node ID",
    capabilities=frozenset({"identify", "detect", "home", "jog", "registers", "config"}),
    import_block="deltoctl_canopen.nodes:import_block",
    homing_joints="deltoctl_canopen.nodes:homing_joints",
    serve_options=(
        SimOption("missing", "joints", "Fault: a joint's node that never answers (repeatable)."),
        SimOption("wrong_identity", "int", "Fault: every node reports this product code "
                  "(0x1018:2) instead of its EDS's.", None, 0, 0xFFFFFFFF),
        SimOption("drive_fault", "joints", "Fault: a joint's drive starts in Fault (EMCY "
                  "0x2310, over-current), cleared by a fault reset (repeatable)."),
        SimOption("stall", "joints", "Fault: a joint that cannot move: its following error "
                  "faults the drive (EMCY 0x8611) (repeatable)."),
        SimOption("heartbeat_stops", "joints", "Fault: a joint's node falls silent (no "
                  "heartbeat, no reply) --heartbeat-stops-after seconds after start."),
        SimOption("heartbeat_stops_after", "number", "When the nodes --heartbeat-stops names "
                  "fall silent, seconds after start.", 2.0, 0, 3600),
        SimOption("factory_new", "flag", "Drives as they leave the factory: no node ID (LSS, "
                  "CiA 305, gives them one), each with a serial of its own.", False),
    ),
    permissions=(Permission(
        "limits", why="software position limits (0x607D) bound every move of the drive"),
        Permission("homing", why="the home offset and method (0x607C, 0x6098) move the "
                   "drive's zero"),
        Permission("save", why="0x1010 stores the drive's parameters for good",
                   given="the parameters are stored in the drive's non-volatile memory")),
    identity_fields=(("nodes", "{} CANopen nodes"),),
    register_items="deltoctl_canopen.objects:item_names",
    config_rules="deltoctl_canopen.objects:config_rules",
)
