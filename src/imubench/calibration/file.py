"""The calibration file (TOML) and its application to batches of samples.

One file per board::

    format = "imubench-calibration"
    version = 1

    [provenance]          # who, when, where, how: serial, date_utc, station, chip,
                          # software, source_uri, run_id (strings)
    [accel]               # and/or [gyro]
    unit = "g"            # "g" (accel) or "dps" (gyro)
    method = "..."        # how offset/matrix/nonlinearity were found
    temp_ref_c = 25.0     # T_ref of the temperature terms, degC (die sensor)
    offset = [bx, by, bz]             # unit
    matrix = [[..], [..], [..]]       # sensitivity matrix M, unitless
    nonlinearity = [qx, qy, qz]       # 1/unit
    temp_method = "..."               # how the temperature terms were found ("" = none)
    temp_coeff1 = [..]                # unit/degC
    temp_coeff2 = [..]                # unit/degC^2
    full_scale = 2.0                  # unit: the full scale it was made at (optional)
    temp_range_c = [lo, hi]           # die temperatures the temperature terms saw
    [accel.residuals]     # free-form: residual tables of the fits (lists of numbers)

Applied to data (:meth:`Calibration.check_data`): a recording or source of another chip
(``provenance.chip``) or another full scale is refused (offset, gains and nonlinearity
belong to the range they were measured at), and data whose die temperature leaves
``temp_range_c`` by more than :data:`TEMP_MARGIN_C` get a warning: the temperature terms
are extrapolated there (a quadratic fitted over +-5 degC made the output at -40 and
85 degC worse than the raw one).

Model and correction (:mod:`imubench.calibration.sensor`,
:mod:`imubench.calibration.temperature`): a sensor reading ``y`` at die temperature ``T``
is ``y = M u + q u^2 + b + c1 dT + c2 dT^2`` (``dT = T - T_ref``); :meth:`Calibration.apply`
returns ``u``. Raw counts are never touched: a batch keeps its ``raw`` and only its
scaled ``values`` change, so a recording keeps what the chip said and states (through
:meth:`Calibration.describe`) which calibration produced its values.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from imubench.batch import CHANNELS, Batch
from imubench.calibration.errors import CalibrationError
from imubench.calibration.sensor import check_invertible, correct
from imubench.tomlread import read_toml

FORMAT = "imubench-calibration"
VERSION = 1
SENSORS: dict[str, tuple[str, slice]] = {"gyro": ("dps", slice(0, 3)), "accel": ("g", slice(3, 6))}
"""Sensor table name -> (unit, columns of Batch.values)."""
PROVENANCE_KEYS = ("serial", "date_utc", "station", "chip", "software", "source_uri", "run_id")
TEMP_MARGIN_C = 5.0
"""Die temperatures this far outside a calibration's ``temp_range_c`` get a warning."""
REQUIRED_PROVENANCE = ("serial", "date_utc", "station")


@dataclass(frozen=True)
class SensorCalibration:
    """The correction of one 3-axis sensor (see the module docstring for the model)."""

    unit: str
    method: str
    temp_ref_c: float
    offset: np.ndarray
    matrix: np.ndarray
    nonlinearity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    temp_method: str = ""
    temp_coeff1: np.ndarray = field(default_factory=lambda: np.zeros(3))
    temp_coeff2: np.ndarray = field(default_factory=lambda: np.zeros(3))
    residuals: Mapping[str, Any] = field(default_factory=dict)
    full_scale: float = 0.0
    """The full scale (unit) the calibration was made at; 0 = not stated."""
    temp_range_c: tuple[float, float] | None = None
    """The die temperatures (degC) the temperature terms were fitted over; None = not
    stated."""

    @property
    def has_temperature(self) -> bool:
        return bool(np.any(self.temp_coeff1) or np.any(self.temp_coeff2))

    def outside_sweep(self, temp_c: np.ndarray) -> np.ndarray:
        """Bool mask: die temperatures (degC) beyond ``temp_range_c`` by more than
        :data:`TEMP_MARGIN_C`, where the temperature terms are extrapolated. All False
        without temperature terms or a stated range, and where ``temp_c`` is NaN."""
        t = np.asarray(temp_c, dtype=np.float64)
        if not self.has_temperature or self.temp_range_c is None:
            return np.zeros(t.shape, dtype=bool)
        lo, hi = self.temp_range_c
        with np.errstate(invalid="ignore"):
            return (t < lo - TEMP_MARGIN_C) | (t > hi + TEMP_MARGIN_C)

    def correct(self, y: np.ndarray, temp_c: np.ndarray | None) -> np.ndarray:
        """True input ``u`` (n, 3) from readings ``y`` (n, 3) at die temperatures
        ``temp_c`` (n,) (None or NaN only allowed without temperature terms)."""
        y = np.asarray(y, dtype=np.float64)
        if self.has_temperature:
            if temp_c is None or not np.all(np.isfinite(temp_c)):
                raise CalibrationError(
                    f"{self.unit} calibration has temperature terms ({self.temp_method}) but"
                    " the data carry no die temperature for every sample; record the"
                    " temperature or use a calibration without temperature terms"
                )
            dT = np.asarray(temp_c, dtype=np.float64)[:, None] - self.temp_ref_c
            y = y - dT * (self.temp_coeff1 + dT * self.temp_coeff2)
        return correct(y, self.matrix, self.offset, self.nonlinearity)

    def parameters(self) -> dict[str, Any]:
        """The TOML table of this sensor (lists of floats)."""
        return {
            "unit": self.unit,
            "method": self.method,
            "temp_ref_c": float(self.temp_ref_c),
            "offset": [float(v) for v in self.offset],
            "matrix": [[float(v) for v in row] for row in self.matrix],
            "nonlinearity": [float(v) for v in self.nonlinearity],
            "temp_method": self.temp_method,
            "temp_coeff1": [float(v) for v in self.temp_coeff1],
            "temp_coeff2": [float(v) for v in self.temp_coeff2],
            "residuals": _plain(self.residuals),
            **({"full_scale": float(self.full_scale)} if self.full_scale else {}),
            **({"temp_range_c": [float(v) for v in self.temp_range_c]}
               if self.temp_range_c is not None else {}),
        }


@dataclass(frozen=True)
class Calibration:
    """A board's calibration: provenance plus a :class:`SensorCalibration` per sensor.

    Build it from fits (the jig does), or :meth:`load` a file; :meth:`apply` corrects a
    :class:`~imubench.batch.Batch`; :meth:`describe` is what a recording header states.
    """

    provenance: Mapping[str, str]
    gyro: SensorCalibration | None = None
    accel: SensorCalibration | None = None
    path: Path | None = None
    sha256: str | None = None

    def __post_init__(self) -> None:
        if self.gyro is None and self.accel is None:
            raise CalibrationError(f"{self._where()}: a calibration needs [gyro] or [accel]")
        missing = [k for k in REQUIRED_PROVENANCE if not self.provenance.get(k)]
        if missing:
            raise CalibrationError(
                f"{self._where()}: [provenance] lacks {missing}; a calibration must say which"
                " board it belongs to, when and where it was made"
            )
        for name in SENSORS:
            sc = getattr(self, name)
            if sc is not None:
                check_invertible(sc.matrix, f"{self._where()}: [{name}] matrix")

    def _where(self) -> str:
        return str(self.path) if self.path is not None else "calibration"

    # -- application ------------------------------------------------------------------
    def apply(self, batch: Batch) -> Batch:
        """``batch`` with corrected ``values`` (dps, g); ``raw``, indices, times and gaps
        unchanged. A sensor whose three channels are all NaN (absent) is left as is."""
        if not len(batch):
            return batch
        values = batch.values.copy()
        for name, (_, cols) in SENSORS.items():
            sc = getattr(self, name)
            if sc is None or np.all(np.isnan(values[:, cols])):
                continue
            absent = [ch for ch, col in zip(CHANNELS[cols], values[:, cols].T, strict=True)
                      if np.all(np.isnan(col))]
            if absent:  # the matrix mixes the three axes: none can be corrected alone
                raise CalibrationError(
                    f"{self._where()}: [{name}] corrects {', '.join(CHANNELS[cols])} together "
                    f"(its matrix mixes the axes) and the data lack {', '.join(absent)}; "
                    "calibrate a recording that holds all three, then export the channel")
            values[:, cols] = sc.correct(values[:, cols], batch.temp_c)
        return dataclasses.replace(batch, values=values)

    def check_data(self, chip: str | None, fs_dps: float | None, fs_g: float | None,
                   temp_c: np.ndarray | None, where: str) -> list[str]:
        """Refuse data this calibration does not belong to (CalibrationError naming both):
        another chip than ``provenance.chip``, another full scale (``fs_dps``, ``fs_g``
        of the data, None where unknown). Returns warnings
        for die temperatures ``temp_c`` outside ``temp_range_c`` by more than
        :data:`TEMP_MARGIN_C` (the temperature terms extrapolate there)."""
        own = self.provenance.get("chip")
        if own and chip and own.lower() != chip.lower():
            raise CalibrationError(f"{self._where()} was made for an {own}; {where} is from "
                                   f"an {chip}")
        warnings: list[str] = []
        for name in SENSORS:
            sc = getattr(self, name)
            if sc is None:
                continue
            fs = fs_dps if name == "gyro" else fs_g
            if sc.full_scale and fs and not math.isclose(fs, sc.full_scale, rel_tol=1e-6):
                raise CalibrationError(
                    f"{self._where()}: [{name}] was made at full scale {sc.full_scale:g} "
                    f"{sc.unit}; {where} is at {fs:g} {sc.unit} (offset and gains belong "
                    "to the range they were measured at)")
            if temp_c is not None and np.any(sc.outside_sweep(temp_c)):
                t = np.asarray(temp_c, dtype=np.float64)
                warnings.append(self.extrapolation_warning(
                    name, float(np.nanmin(t)), float(np.nanmax(t)), where))
        return warnings

    def extrapolation_warning(self, name: str, lo_c: float, hi_c: float, where: str) -> str:
        """The words for die temperatures ``lo_c`` to ``hi_c`` (degC) outside the sweep of
        sensor ``name``'s temperature terms (see :meth:`SensorCalibration.outside_sweep`)."""
        sc = getattr(self, name)
        assert sc is not None and sc.temp_range_c is not None
        span = f"{lo_c:.1f}" if f"{lo_c:.1f}" == f"{hi_c:.1f}" else f"{lo_c:.1f} to {hi_c:.1f}"
        return (f"{where}: die temperature {span} degC, outside the "
                f"{sc.temp_range_c[0]:.1f} to {sc.temp_range_c[1]:.1f} degC the "
                f"[{name}] temperature terms of {self._where()} were fitted over: "
                "they are extrapolated there and may make the values worse")

    def describe(self) -> dict[str, Any]:
        """JSON-ready statement for a recording header: ``applied`` (True), ``path``,
        ``sha256`` of the file, ``provenance`` and every parameter (enough for
        :meth:`from_description` to rebuild the same correction)."""
        out: dict[str, Any] = {
            "applied": True,
            "format": FORMAT,
            "version": VERSION,
            "path": None if self.path is None else str(self.path),
            "sha256": self.sha256,
            "provenance": dict(self.provenance),
        }
        for name in SENSORS:
            sc = getattr(self, name)
            if sc is not None:
                out[name] = sc.parameters()
        return out

    @classmethod
    def from_description(cls, d: Mapping[str, Any]) -> Calibration:
        """Rebuild from :meth:`describe` (e.g. a recording header's ``calibration``)."""
        return cls._from_table(d, "recording header calibration", None, d.get("sha256"))

    # -- file I/O ---------------------------------------------------------------------
    def to_toml(self) -> str:
        table: dict[str, Any] = {"format": FORMAT, "version": VERSION,
                                 "provenance": dict(self.provenance)}
        for name in SENSORS:
            sc = getattr(self, name)
            if sc is not None:
                table[name] = sc.parameters()
        return tomli_w.dumps(table)

    def save(self, path: str | Path) -> Calibration:
        """Write the file; returns the calibration with its ``path`` and ``sha256``."""
        p = Path(path)
        text = self.to_toml()
        p.write_text(text, encoding="utf-8")
        return dataclasses.replace(self, path=p, sha256=_sha256(text))

    @classmethod
    def load(cls, path: str | Path) -> Calibration:
        """Read a calibration file; errors name the file and the key."""
        p = Path(path)
        data, text = read_toml(p, "calibration file", CalibrationError)
        return cls._from_table(data, str(p), p, _sha256(text))

    @classmethod
    def _from_table(cls, d: Mapping[str, Any], where: str, path: Path | None,
                    sha: str | None) -> Calibration:
        if d.get("format") != FORMAT:
            raise CalibrationError(f"{where}: key 'format' must be {FORMAT!r}, got"
                                   f" {d.get('format')!r}")
        if d.get("version") != VERSION:
            raise CalibrationError(f"{where}: key 'version' must be {VERSION}, got"
                                   f" {d.get('version')!r}")
        known = {"format", "version", "provenance", "applied", "path", "sha256", *SENSORS}
        extra = sorted(set(d) - known)
        if extra:
            raise CalibrationError(f"{where}: unknown keys {extra}; allowed: {sorted(known)}")
        prov = d.get("provenance", {})
        if not isinstance(prov, Mapping) or not all(isinstance(v, str) for v in prov.values()):
            raise CalibrationError(f"{where}: [provenance] must be a table of strings")
        sensors = {name: _sensor(d[name], f"{where}: [{name}]", unit)
                   for name, (unit, _) in SENSORS.items() if name in d}
        return cls(dict(prov), sensors.get("gyro"), sensors.get("accel"), path, sha)


def _sha256(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _plain(value: Any) -> Any:
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _vector(t: Mapping[str, Any], key: str, where: str, shape: tuple[int, ...],
            default: float | None = None) -> np.ndarray:
    if key not in t:
        if default is None:
            raise CalibrationError(f"{where} key {key!r} is missing")
        return np.full(shape, default)
    try:
        arr = np.asarray(t[key], dtype=np.float64)
    except (TypeError, ValueError):
        raise CalibrationError(f"{where} key {key!r} must be numbers, got {t[key]!r}") from None
    if arr.shape != shape or not np.all(np.isfinite(arr)):
        raise CalibrationError(
            f"{where} key {key!r} must be {'x'.join(map(str, shape))} finite numbers,"
            f" got {t[key]!r}"
        )
    return arr


def _sensor(t: Any, where: str, unit: str) -> SensorCalibration:
    if not isinstance(t, Mapping):
        raise CalibrationError(f"{where} must be a table")
    span = None
    if "temp_range_c" in t:
        lo, hi = _vector(t, "temp_range_c", where, (2,))
        span = (float(lo), float(hi))
    allowed = {"unit", "method", "temp_ref_c", "offset", "matrix", "nonlinearity",
               "temp_method", "temp_coeff1", "temp_coeff2", "residuals", "full_scale",
               "temp_range_c"}
    extra = sorted(set(t) - allowed)
    if extra:
        raise CalibrationError(f"{where}: unknown keys {extra}; allowed: {sorted(allowed)}")
    if t.get("unit") != unit:
        raise CalibrationError(f"{where} key 'unit' must be {unit!r}, got {t.get('unit')!r}")
    ref = t.get("temp_ref_c", 25.0)
    if isinstance(ref, bool) or not isinstance(ref, int | float) or not math.isfinite(ref):
        raise CalibrationError(f"{where} key 'temp_ref_c' must be a number (degC), got {ref!r}")
    return SensorCalibration(
        unit=unit,
        method=str(t.get("method", "")),
        temp_ref_c=float(ref),
        offset=_vector(t, "offset", where, (3,)),
        matrix=_vector(t, "matrix", where, (3, 3)),
        nonlinearity=_vector(t, "nonlinearity", where, (3,), 0.0),
        temp_method=str(t.get("temp_method", "")),
        temp_coeff1=_vector(t, "temp_coeff1", where, (3,), 0.0),
        temp_coeff2=_vector(t, "temp_coeff2", where, (3,), 0.0),
        residuals=dict(t.get("residuals", {})),
        full_scale=float(_vector(t, "full_scale", where, (), 0.0)),
        temp_range_c=span,
    )


__all__ = ["FORMAT", "PROVENANCE_KEYS", "REQUIRED_PROVENANCE", "SENSORS", "VERSION",
           "Calibration", "SensorCalibration"]


def recording_header(calibration: Calibration | None) -> dict[str, Any]:
    """A recording header's ``calibration`` field: :meth:`Calibration.describe`, or
    ``{"applied": False}``."""
    return {"applied": False} if calibration is None else calibration.describe()
