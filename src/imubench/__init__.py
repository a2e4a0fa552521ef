"""imubench: live acquisition and Allan-family noise analysis for ST LSM6DS IMUs."""

__version__ = "0.1.0"
"""The package version: the one source (``pyproject.toml`` reads it, ``--version`` shows it)."""
