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

from imubench.jig.errors import JigError
from imubench.tomlread import read_toml

LIMIT_KEYS = frozenset({"low", "high", "unit", "typ", "basis"})


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
            raise JigError(
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
    return Limits(chip, p, out)


__all__ = ["Limit", "Limits", "load_limits"]
