"""Limits files (TOML, one per chip: ``config/limits-<chip>.toml``).

Every leaf table with a ``unit`` key is one limit; its dotted path is the measurement
name, e.g.::

    chip = "lsm6dsl"
    [noise_density]
    gx = { low = 1.0, high = 6.0, unit = "mdps/sqrt(Hz)", typ = 4.0, basis = "..." }

gives the limit ``noise_density.gx``. Keys of a limit: ``low`` and/or ``high`` (at least
one), ``unit`` (the unit the measurement must be reported in), ``typ`` (the datasheet
typical, for reports and self-test intervals) and ``basis`` (where the numbers come
from). Unknown keys, a low above its high, or a limit with neither are errors naming
the file and the limit.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from imubench.jig.errors import JigError, StationError
from imubench.jig.units import conversion_hint, convertible
from imubench.tomlread import read_toml

LIMIT_KEYS = frozenset({"low", "high", "unit", "typ", "basis"})

_GYRO, _ACCEL = ("gx", "gy", "gz"), ("ax", "ay", "az")
SUITE_UNITS: dict[str, str] = {
    "identity.who_am_i": "-",
    **{f"self_test.gyro_{a}": "dps" for a in "xyz"},
    **{f"self_test.accel_{a}": "g" for a in "xyz"},
    **{f"zero_rate_level.{c}": "dps" for c in _GYRO},
    **{f"zero_g_offset.{c}": "mg" for c in _ACCEL},
    **{f"noise_density.{c}": "mdps/sqrt(Hz)" for c in _GYRO},
    **{f"noise_density.{c}": "ug/sqrt(Hz)" for c in _ACCEL},
    **{f"angle_random_walk.{c}": "deg/sqrt(h)" for c in _GYRO},
    **{f"bias_instability.{c}": "deg/h" for c in _GYRO},
    **{f"bias_instability.{c}": "ug" for c in _ACCEL},
    "temperature_sensor.offset": "degC",
    "fifo.lost_samples": "samples",
    "fifo.session_lost_samples": "samples",
    "fifo.odr_error": "%",
    **{f"accel_calibration.gain_error.{c}": "%" for c in _ACCEL},
    "accel_calibration.residual_max": "mg",
    "accel_calibration.chi2_per_dof": "1",
    **{f"gyro_sensitivity.{c}": "%" for c in _GYRO},
    **{f"gyro_cross_axis.{c}": "%" for c in _GYRO},
    **{f"temperature_coefficient.{c}": "dps/degC" for c in _GYRO},
    **{f"temperature_coefficient.{c}": "mg/degC" for c in _ACCEL},
    "temperature_calibration.residual_max.gyro": "dps",
    "temperature_calibration.residual_max.accel": "mg",
}
"""Every measurement the shipped suite makes, with the unit it computes it in: a limit of
that name may state any unit of the same dimension (:mod:`imubench.jig.units`; the value
is converted into it), and a limit under one of these groups that the suite does not
measure (a typo: ``zero_rate_level.gzz``) is refused when the file is loaded."""
SUITE_GROUPS = frozenset(name.split(".")[0] for name in SUITE_UNITS)


@dataclass(frozen=True)
class Limit:
    name: str
    unit: str
    low: float | None = None
    high: float | None = None
    typ: float | None = None
    basis: str = ""


@dataclass(frozen=True)
class Limits:
    """The limits of one chip, by measurement name."""

    chip: str
    path: Path | None
    limits: Mapping[str, Limit]

    def __getitem__(self, name: str) -> Limit:
        try:
            return self.limits[name]
        except KeyError:
            where = self.path if self.path is not None else "limits"
            raise StationError(
                f"{where}: no limit for measurement {name!r}; add it (known: "
                f"{', '.join(sorted(self.limits)[:8])}, ...)"
            ) from None

    def __contains__(self, name: str) -> bool:
        return name in self.limits


def _number(v: Any, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise JigError(f"{where}: must be a finite number, got {v!r}")
    return float(v)


def _walk(table: Mapping[str, Any], prefix: str, where: str, out: dict[str, Limit]) -> None:
    for key, value in table.items():
        name = f"{prefix}.{key}" if prefix else key
        if not isinstance(value, Mapping):
            if prefix:
                raise JigError(f"{where}: {name} must be a table with a 'unit' (a limit)")
            continue  # top-level scalars: chip, source
        if "unit" not in value:
            _walk(value, name, where, out)
            continue
        bad = sorted(set(value) - LIMIT_KEYS)
        if bad:
            raise JigError(f"{where}: limit {name!r} has unknown keys {bad}; use"
                           f" {sorted(LIMIT_KEYS)}")
        low = None if "low" not in value else _number(value["low"], f"{where}: {name}.low")
        high = None if "high" not in value else _number(value["high"], f"{where}: {name}.high")
        if low is None and high is None:
            raise JigError(f"{where}: limit {name!r} needs 'low' and/or 'high'")
        if low is not None and high is not None and low > high:
            raise JigError(f"{where}: limit {name!r} has low {low} above high {high}")
        typ = None if "typ" not in value else _number(value["typ"], f"{where}: {name}.typ")
        out[name] = Limit(name, str(value["unit"]), low, high, typ, str(value.get("basis", "")))


def load_limits(path: str | Path) -> Limits:
    p = Path(path)
    data, _ = read_toml(p, "limits file", JigError)
    chip = data.get("chip")
    if not isinstance(chip, str):
        raise JigError(f"{p}: key 'chip' (lsm6dsl, lsm6dsm or lsm6ds3h) is missing")
    out: dict[str, Limit] = {}
    _walk(data, "", str(p), out)
    if not out:
        raise JigError(f"{p}: no limits (tables with a 'unit' key)")
    _check_suite_names(out, str(p))
    return Limits(chip, p, out)


def _check_suite_names(limits: Mapping[str, Limit], where: str) -> None:
    """JigError for a limit under a suite group that the suite does not measure, or in a
    unit that is not of the measurement's dimension (:data:`SUITE_UNITS`)."""
    for name, lim in limits.items():
        own = SUITE_UNITS.get(name)
        if own is None:
            if name.split(".")[0] in SUITE_GROUPS:
                group = name.split(".")[0]
                known = sorted(n for n in SUITE_UNITS if n.startswith(group + "."))
                raise JigError(f"{where}: limit {name!r}: the suite measures no such "
                               f"quantity (in [{group}]: {', '.join(known)})")
            continue
        if not convertible(own, lim.unit):
            raise JigError(f"{where}: limit {name!r} is in {lim.unit!r}, which is not a "
                           f"unit of {name} (measured in {own!r}; "
                           f"{conversion_hint(own)})")


__all__ = ["SUITE_UNITS", "Limit", "Limits", "load_limits"]
