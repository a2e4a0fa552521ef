"""Register-level simulator of LSM6DS3H / LSM6DSM / LSM6DSL and of the SensorTile firmware."""
