"""The LSM6DS3 / LSM6DS3TR-C IMU on I2C (the MH5\x27s chest IMU)."""
