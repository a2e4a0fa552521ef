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

STANDARD_GRAVITY = 9.80665
"""m/s^2 per g (CGPM 1901)."""
DEG_PER_RAD = 180.0 / math.pi

UNITS: dict[str, tuple[str, float]] = {
    # angular rate, in dps
    "dps": ("rate", 1.0), "deg/s": ("rate", 1.0), "mdps": ("rate", 1e-3),
    "deg/h": ("rate", 1.0 / 3600.0), "rad/s": ("rate", DEG_PER_RAD),
    "mrad/s": ("rate", DEG_PER_RAD * 1e-3),
    # acceleration, in g
    "g": ("accel", 1.0), "mg": ("accel", 1e-3), "ug": ("accel", 1e-6),
    "µg": ("accel", 1e-6), "m/s2": ("accel", 1.0 / STANDARD_GRAVITY),
    "m/s^2": ("accel", 1.0 / STANDARD_GRAVITY),
    # rate noise density (angle random walk), in dps/sqrt(Hz)
    "dps/sqrt(Hz)": ("rate_density", 1.0), "mdps/sqrt(Hz)": ("rate_density", 1e-3),
    "deg/sqrt(s)": ("rate_density", 1.0), "deg/sqrt(h)": ("rate_density", 1.0 / 60.0),
    "deg/h/sqrt(Hz)": ("rate_density", 1.0 / 3600.0),
    "rad/s/sqrt(Hz)": ("rate_density", DEG_PER_RAD),
    # acceleration noise density (velocity random walk), in g/sqrt(Hz)
    "g/sqrt(Hz)": ("accel_density", 1.0), "mg/sqrt(Hz)": ("accel_density", 1e-3),
    "ug/sqrt(Hz)": ("accel_density", 1e-6), "µg/sqrt(Hz)": ("accel_density", 1e-6),
    "m/s2/sqrt(Hz)": ("accel_density", 1.0 / STANDARD_GRAVITY),
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
