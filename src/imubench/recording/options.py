"""How a recording from elsewhere is to be read: rate, time unit, column map, units, topic.

Every command that reads a recording takes the same options (:func:`add_input_arguments`,
:func:`input_options`) and hands them to :func:`imubench.recording.load_recording`:

``--rate HZ``
    the sample rate, overriding the file's (``# odr_hz``, the sample index, ``t``).
``--time-unit s|ms|us|ns``
    the unit of the time column, when the header does not say and the spacing cannot
    tell (see :func:`imubench.recording.timebase.time_unit_from_spacing`).
``--columns gx=gyro_x,ax=acc_x,t=stamp``
    which file column holds each channel (``t``, ``index``, ``gx``..``az``, ``temp``);
    a column is named by its header text or by its 1-based number (``gx=2``).
``--units rad/s,m/s2``
    the units of the gyro and accelerometer columns (converted to dps and g).
``--topic /imu``
    the ``sensor_msgs/msg/Imu`` topic of a ROS 2 bag or MCAP file.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Mapping
from dataclasses import dataclass, field

from imubench.batch import CHANNELS
from imubench.errors import RecordingError

STANDARD_GRAVITY_M_S2 = 9.80665
"""g in m/s^2 (CGPM 1901; the value ST's datasheets use for 1 g)."""

TIME_UNITS_S: dict[str, float] = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
"""Seconds per unit of the time column."""
GYRO_UNITS_DPS: dict[str, float] = {
    "dps": 1.0, "deg/s": 1.0, "mdps": 1e-3, "rad/s": 180.0 / math.pi, "deg/h": 1.0 / 3600.0,
    "mrad/s": 0.18 / math.pi, "rpm": 6.0,
}
"""dps per unit of a gyro column."""
ACCEL_UNITS_G: dict[str, float] = {
    "g": 1.0, "mg": 1e-3, "ug": 1e-6, "m/s2": 1.0 / STANDARD_GRAVITY_M_S2,
    "m/s^2": 1.0 / STANDARD_GRAVITY_M_S2, "cm/s2": 0.01 / STANDARD_GRAVITY_M_S2,
    "mm/s2": 0.001 / STANDARD_GRAVITY_M_S2,
}
"""g per unit of an accelerometer column."""
TARGETS: tuple[str, ...] = ("t", "index", *CHANNELS, "temp")
"""What ``--columns`` may map."""


@dataclass(frozen=True)
class InputOptions:
    """Overrides for reading one recording; None = from the file."""

    rate_hz: float | None = None
    time_unit: str | None = None
    columns: Mapping[str, str] = field(default_factory=dict)
    """channel (:data:`TARGETS`) -> file column (header text or 1-based number)."""
    gyro_unit: str | None = None
    accel_unit: str | None = None
    topic: str | None = None
    default_rate_hz: float | None = None
    """Rate of a file that states none and has no time column (a one-column Stable32 or
    allantools file): ``imubench allan`` uses 1 Hz (tau in samples, as those tools);
    None = such a file is refused without ``--rate``."""


NO_TIME_COLUMN = "-"
"""``--columns t=-``: read no time column (rows in order at ``--rate``), for stamps that
cannot index the rows (rounded as coarse as the sample period)."""


def parse_columns(text: str) -> dict[str, str]:
    """``gx=gyro_x,ax=3`` -> ``{"gx": "gyro_x", "ax": "3"}``; RecordingError if malformed."""
    out: dict[str, str] = {}
    for part in (p.strip() for p in text.split(",")):
        if not part:
            continue
        target, eq, column = part.partition("=")
        target, column = target.strip(), column.strip()
        if not eq or not column:
            raise RecordingError(f"--columns {text!r}: {part!r} is not CHANNEL=COLUMN")
        if target not in TARGETS:
            raise RecordingError(f"--columns {text!r}: {target!r} is not one of "
                                 f"{', '.join(TARGETS)}")
        if target in out:
            raise RecordingError(f"--columns {text!r}: {target} is mapped twice")
        out[target] = column
    return out


def parse_units(text: str) -> tuple[str, str]:
    """``rad/s,m/s2`` -> (gyro unit, accel unit); RecordingError if unknown."""
    parts = [p.strip().lower() for p in text.split(",")]
    if len(parts) != 2:
        raise RecordingError(f"--units {text!r}: give GYRO,ACCEL, e.g. rad/s,m/s2 or dps,g")
    gyro, accel = parts
    if gyro not in GYRO_UNITS_DPS:
        raise RecordingError(f"--units {text!r}: gyro unit {gyro!r} is not one of "
                             f"{', '.join(GYRO_UNITS_DPS)}")
    if accel not in ACCEL_UNITS_G:
        raise RecordingError(f"--units {text!r}: accelerometer unit {accel!r} is not one of "
                             f"{', '.join(ACCEL_UNITS_G)}")
    return gyro, accel


def add_input_arguments(p: argparse.ArgumentParser, *, rate: bool = True) -> None:
    """The input options of every command that reads recordings (``rate=False`` when the
    command already defines its own ``--rate``)."""
    g = p.add_argument_group("reading recordings from elsewhere (docs/recordings.md)")
    if rate:
        g.add_argument("--rate", type=float, default=None, metavar="HZ",
                       help="sample rate in Hz, overriding the file's (# odr_hz, sample "
                       "index, time column)")
    g.add_argument("--time-unit", choices=tuple(TIME_UNITS_S), default=None,
                   help="unit of the time column when the header does not say it")
    g.add_argument("--columns", default=None, metavar="CH=COL,...",
                   help="file column of each channel, by header text or 1-based number: "
                   "t=timestamp,gx=gyro_x,...,az=acc_z (channels: t index gx gy gz ax ay "
                   "az temp)")
    g.add_argument("--units", default=None, metavar="GYRO,ACCEL",
                   help=f"units of the gyro and accelerometer columns: gyro "
                   f"{'|'.join(GYRO_UNITS_DPS)}, accel {'|'.join(ACCEL_UNITS_G)} "
                   "(e.g. rad/s,m/s2)")
    g.add_argument("--topic", default=None,
                   help="sensor_msgs/msg/Imu topic of a ROS 2 bag or MCAP file")


def input_options(args: argparse.Namespace) -> InputOptions:
    """The :class:`InputOptions` of parsed arguments (RecordingError if malformed)."""
    rate = args.rate
    if rate is not None and not (math.isfinite(rate) and rate > 0):
        raise RecordingError(f"--rate {rate}: must be a positive number of Hz")
    gyro = accel = None
    if args.units:
        gyro, accel = parse_units(args.units)
    return InputOptions(rate_hz=rate, time_unit=args.time_unit,
                        columns=parse_columns(args.columns) if args.columns else {},
                        gyro_unit=gyro, accel_unit=accel, topic=args.topic)
