"""Tesollo Delto grippers: developer-mode TCP protocol (codec), driver, model table, emulator."""

from deltoctl.registry import Family

FAMILY = Family(
    name="delto",
    summary="Tesollo Delto grippers (TCP, developer mode)",
    driver="deltoctl.families.delto.driver:DeltoDriver",
    frame_names="deltoctl.families.delto.codec:frame_name",
    emulator="deltoctl.families.delto.emulator:serve",
    plugins=("delto_hardware/SystemInterface",),
    schemes=("tcp",),
    address_range=(1, 20),
    address_kind="motor index",
    address_by_position=True,
    endpoint_params=("delto_ip", "delto_port", 502),
    refused_hint="switch the gripper to developer mode (DIP switches 2 and 4: in operator mode "
                 "it speaks Modbus TCP) and check the port",
    capabilities=frozenset({"identify", "detect", "home", "jog", "calibrate_ft", "gpio",
                            "config"}),
    serve_options=("firmware", "model_id", "short_version", "input_1", "delay", "stall"),
)
