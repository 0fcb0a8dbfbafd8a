"""The LSM6DS3 / LSM6DS3TR-C IMU on I2C (the MH5's chest IMU): registers, driver, emulator."""

from deltoctl.registry import Family, SimOption

FAMILY = Family(
    name="lsm6ds3",
    summary="LSM6DS3 IMU on I2C",
    driver="deltoctl.families.lsm6ds3.driver:Lsm6ds3Driver",
    frame_names="deltoctl.families.lsm6ds3.codec:frame_name",
    emulator="deltoctl.families.lsm6ds3.emulator:serve",
    plugins=("mh5_hardware/MH5I2CInterface",),
    schemes=("i2c", "i2c+tcp"),
    address_range=(0x08, 0x77),
    address_kind="I2C address",
    address_format="#04x",
    capabilities=frozenset({"identify", "detect", "config", "calibrate_imu"}),
    serve_options=(
        SimOption("who_am_i", "int", "WHO_AM_I of a simulated LSM6DS3: 0x69 (LSM6DS3), 0x6A "
                  "(LSM6DS3TR-C), or another value to rehearse a wrong part.", 0x6A, 0, 0xFF),
        SimOption("orientation", "numbers", "The IMU's roll,pitch[,yaw] in degrees (gravity "
                  "follows).", (0.0, 0.0), count=(2, 3), metavar="ROLL,PITCH"),
    ),
    identity_fields=(("chip", "{}"), ("output_rate_hz", "at {} Hz")),
)
