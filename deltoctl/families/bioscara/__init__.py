"""The Bioscara SCARA arm: uStepper joints on I2C (codec, driver with stall-detection homing,
and the joints' firmware emulated on a simulated bus)."""

from deltoctl.registry import Family, Permission, SimOption

FAMILY = Family(
    name="bioscara",
    summary="Bioscara SCARA arm: uStepper joints on I2C",
    driver="deltoctl.families.bioscara.driver:BioscaraDriver",
    frame_names="deltoctl.families.bioscara.codec:frame_name",
    emulator="deltoctl.families.bioscara.emulator:serve",
    plugins=("bioscara_hardware_interfaces/BioscaraArmHardwareInterface",),
    schemes=("i2c", "i2c+tcp"),
    address_range=(0x08, 0x77),
    address_param="i2c_address",
    address_kind="I2C address",
    address_format="#04x",
    capabilities=frozenset({"identify", "detect", "home", "jog", "config"}),
    serve_options=(
        SimOption("missing", "joints", "Fault: a joint that never answers (repeatable)."),
        SimOption("stall", "joints", "Fault: a joint that cannot move (repeatable)."),
    ),
    # the home offset moves where a joint believes it is: written only when asked
    permissions=(Permission("home-offset"),),
    identity_fields=(("joints", "{} uStepper joints"),),
    mock_param="use_mock_hardware",  # the plugin's MockJoint mode: "true" or "True"
)
