"""Exception family of the :mod:`lsm6ds` drivers (the package knows nothing of imubench)."""

from __future__ import annotations


class LSM6DSError(Exception):
    """Base of every error the lsm6ds drivers raise on purpose."""


class ProbeError(LSM6DSError):
    """WHO_AM_I does not match the configured chip, or the chip does not answer."""


class ConfigurationError(LSM6DSError):
    """An impossible configuration (ODR, full scale, bus budget)."""


class BusBudgetError(ConfigurationError):
    """The configured data rate does not fit the I2C bus."""


class DriverIOError(LSM6DSError):
    """An I2C transfer still failed after the retries."""


class SelfTestError(LSM6DSError):
    """The self-test procedure could not run (not a fail verdict: see SelfTestResult)."""
