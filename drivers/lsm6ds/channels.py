"""The six inertial channels, in the order every array of this project uses."""

from __future__ import annotations

CHANNELS: tuple[str, ...] = ("gx", "gy", "gz", "ax", "ay", "az")
"""Gyro x, y, z (dps) then accelerometer x, y, z (g)."""
