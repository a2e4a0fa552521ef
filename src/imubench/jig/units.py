"""The units a limits file may state, and conversion between them.

Each unit has a dimension and a factor to that dimension's base unit (rate: dps;
acceleration: g; rate noise density: dps/sqrt(Hz) = deg/sqrt(s), so ARW's deg/sqrt(h) is
1/60 of it; acceleration density: g/sqrt(Hz); temperature coefficients: dps/degC and
g/degC; ratios: 1). A measurement is reported in the unit of its limit: the suite's value
is converted into it, and a limit whose unit is of another dimension, or unknown, is
refused when the limits file is loaded (``zero_g_offset.ax`` with ``unit = "g"`` was
judged in mg against +-0.09, and a noise density in ``dps/sqrt(Hz)`` was read 1000x off,
both without a word).
"""

from __future__ import annotations

import math

from imubench.jig.errors import JigError
from imubench.recording.options import ACCEL_UNITS_G, GYRO_UNITS_DPS, STANDARD_GRAVITY_M_S2

DEG_PER_RAD = 180.0 / math.pi

UNITS: dict[str, tuple[str, float]] = {
    # angular rate in dps and acceleration in g: the recordings' own tables
    **{u: ("rate", f) for u, f in GYRO_UNITS_DPS.items()},
    **{u: ("accel", f) for u, f in ACCEL_UNITS_G.items()}, "µg": ("accel", 1e-6),
    # rate noise density (angle random walk), in dps/sqrt(Hz)
    "dps/sqrt(Hz)": ("rate_density", 1.0), "mdps/sqrt(Hz)": ("rate_density", 1e-3),
    "deg/sqrt(s)": ("rate_density", 1.0), "deg/sqrt(h)": ("rate_density", 1.0 / 60.0),
    "deg/h/sqrt(Hz)": ("rate_density", 1.0 / 3600.0),
    "rad/s/sqrt(Hz)": ("rate_density", DEG_PER_RAD),
    # acceleration noise density (velocity random walk), in g/sqrt(Hz)
    "g/sqrt(Hz)": ("accel_density", 1.0), "mg/sqrt(Hz)": ("accel_density", 1e-3),
    "ug/sqrt(Hz)": ("accel_density", 1e-6), "µg/sqrt(Hz)": ("accel_density", 1e-6),
    "m/s2/sqrt(Hz)": ("accel_density", 1.0 / STANDARD_GRAVITY_M_S2),
    # temperature coefficients
    "dps/degC": ("rate_per_degC", 1.0), "mdps/degC": ("rate_per_degC", 1e-3),
    "deg/h/degC": ("rate_per_degC", 1.0 / 3600.0),
    "g/degC": ("accel_per_degC", 1.0), "mg/degC": ("accel_per_degC", 1e-3),
    "ug/degC": ("accel_per_degC", 1e-6), "µg/degC": ("accel_per_degC", 1e-6),
    # ratios
    "%": ("ratio", 1e-2), "ppm": ("ratio", 1e-6), "1": ("ratio", 1.0),
    # temperature, counts, register values
    "degC": ("temperature", 1.0), "samples": ("samples", 1.0), "-": ("register", 1.0),
}


def convertible(from_unit: str, to_unit: str) -> bool:
    """Whether a value in ``from_unit`` can be stated in ``to_unit``."""
    return from_unit == to_unit or (from_unit in UNITS and to_unit in UNITS
                                    and UNITS[from_unit][0] == UNITS[to_unit][0])


def conversion_hint(unit: str) -> str:
    """``"units of its kind: dps, deg/s, ..."`` for a message."""
    if unit not in UNITS:
        return f"state it in {unit!r}"
    kind = UNITS[unit][0]
    return "units of its kind: " + ", ".join(u for u, (d, _) in UNITS.items() if d == kind)


def conversion_factor(from_unit: str, to_unit: str) -> float:
    """The factor that takes a value in ``from_unit`` to ``to_unit``; JigError when the
    two are not of one dimension."""
    if from_unit == to_unit:
        return 1.0
    if not convertible(from_unit, to_unit):
        raise JigError(f"unit {to_unit!r} is not a unit of what is measured in "
                       f"{from_unit!r} ({conversion_hint(from_unit)})")
    return UNITS[from_unit][1] / UNITS[to_unit][1]


__all__ = ["UNITS", "conversion_factor", "conversion_hint", "convertible"]
