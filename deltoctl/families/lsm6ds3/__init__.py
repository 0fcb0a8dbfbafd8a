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
        SimOption("faces", "steps", "Turn the IMU through these faces, each axis up for its "
                  "seconds, over and over (a rehearsal of calibrate imu --tumble).", (),
                  0.5, 600.0, count=(1, 36), choices=("+x", "-x", "+y", "-y", "+z", "-z"),
                  metavar="AXIS:SECONDS,..."),
        SimOption("accel_bias", "numbers", "The IMU accelerometer's bias, m/s² per axis.",
                  (0.0, 0.0, 0.0), -5.0, 5.0, count=(3, 3), metavar="X,Y,Z"),
        SimOption("accel_scale", "numbers", "The IMU accelerometer's scale factor per axis.",
                  (1.0, 1.0, 1.0), 0.5, 1.5, count=(3, 3), metavar="X,Y,Z"),
        SimOption("gyro_bias", "numbers", "The IMU gyroscope's bias, rad/s per axis.",
                  (0.0, 0.0, 0.0), -0.5, 0.5, count=(3, 3), metavar="X,Y,Z"),
        SimOption("gyro_scale", "numbers", "The IMU gyroscope's scale factor per axis.",
                  (1.0, 1.0, 1.0), 0.5, 1.5, count=(3, 3), metavar="X,Y,Z"),
    ),
    identity_fields=(("chip", "{}"), ("output_rate_hz", "at {} Hz")),
)
