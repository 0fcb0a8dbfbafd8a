"""Tesollo Delto grippers: developer-mode TCP protocol (codec), driver, model table, emulator."""

from deltoctl.registry import Family, SimOption

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
    serve_options=(
        SimOption("firmware", "text", "Firmware version the device reports, MAJOR.MINOR.",
                  "3.0"),
        SimOption("model_id", "int", "Emulate another model than the profile's (e.g. 0x3F02), "
                  "to rehearse a mismatch.", None, 0, 0xFFFF),
        SimOption("short_version", "flag", "Send the short GET_VERSION reply of old firmware.",
                  False),
        SimOption("input_1", "flag", "Drive gpio/input_1 high.", False),
        SimOption("delay", "number", "Fault: seconds added before every reply.", 0.0, 0, 10),
        SimOption("stall", "joints", "Fault: a joint that cannot move (repeatable)."),
        SimOption("ft_creep", "numbers", "Fault: every fingertip F/T offset creeps, per axis "
                  "Fx,Fy,Fz (N/s),Tx,Ty,Tz (N·m/s); the axes not given stay.", None, -100,
                  100, (1, 6), metavar="FX,FY,FZ,…"),
    ),
    identity_fields=(("reported_model", "{}"), ("firmware", "fw {}")),
)
