"""Calibration of LSM6DS boards: accelerometer (one point, +-1 g flip, six-position least
squares), gyroscope (bias at rest, rate table), offset over temperature (the tilt note's
three-point procedure and a least-squares polynomial), and the calibration file that
``imubench run``, ``acquire`` and ``convert`` apply (docs/calibration.md).
"""

from __future__ import annotations

from imubench.calibration.errors import CalibrationError
from imubench.calibration.file import Calibration, SensorCalibration, recording_header

__all__ = ["Calibration", "CalibrationError", "SensorCalibration", "recording_header"]
