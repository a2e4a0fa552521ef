"""Drivers for ST LSM6DS3H / LSM6DSM / LSM6DSL over I2C and the SensorTile serial link."""
