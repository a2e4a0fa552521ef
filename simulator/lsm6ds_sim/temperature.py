"""Temperature profiles of the simulated die: constant, ramp, steps, sine, replayed.

A profile is a pure function of simulated time (``at(t_s) -> temp_c``), so a profile
sampled in chunks equals the profile sampled at once. :func:`parse_profile` reads the
one-line form used by ``imubench sim --temperature``:

=========================================  ============================================
``25`` or ``constant:25``                   25 degC
``ramp:20:0.01[:40]``                       20 degC + 0.01 degC/s, optionally held at 40
``steps:0=20,600=30,1200=25``               piecewise constant, value from each time (s)
``sine:25:5:3600``                          25 + 5 sin(2 pi t / 3600 s)
``replay:PATH[:TIME_COL:TEMP_COL]``         CSV with a header; linear interpolation,
                                            held at the ends; default columns t_s, temp_c
=========================================  ============================================

:class:`ChamberTemperature` (no one-line form) is the die in a climatic chamber whose set
point a test jig changes while the simulation runs.
"""

from __future__ import annotations

import abc
import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lsm6ds_sim.errors import ProfileError


class TemperatureProfile(abc.ABC):
    """Die temperature (degC) as a function of simulated time (s since start)."""

    @abc.abstractmethod
    def at(self, t_s: np.ndarray) -> np.ndarray:
        """Temperature in degC at the times ``t_s`` (float64 array, seconds)."""


@dataclass(frozen=True)
class ConstantTemperature(TemperatureProfile):
    temp_c: float = 25.0

    def at(self, t_s: np.ndarray) -> np.ndarray:
        return np.full(np.shape(t_s), float(self.temp_c))


@dataclass(frozen=True)
class RampTemperature(TemperatureProfile):
    """``start_c + rate_c_per_s * t``, held at ``stop_c`` once reached (if given)."""

    start_c: float
    rate_c_per_s: float
    stop_c: float | None = None

    def at(self, t_s: np.ndarray) -> np.ndarray:
        temp = self.start_c + self.rate_c_per_s * np.asarray(t_s, dtype=np.float64)
        if self.stop_c is not None:
            temp = (
                np.minimum(temp, self.stop_c)
                if self.rate_c_per_s >= 0
                else np.maximum(temp, self.stop_c)
            )
        return temp


@dataclass(frozen=True)
class StepTemperature(TemperatureProfile):
    """Piecewise constant: ``temps_c[i]`` from ``times_s[i]`` on (first value before)."""

    times_s: tuple[float, ...]
    temps_c: tuple[float, ...]

    def __post_init__(self) -> None:
        if len(self.times_s) != len(self.temps_c) or not self.times_s:
            raise ProfileError("steps temperature profile: need as many times as temperatures")
        if any(b <= a for a, b in zip(self.times_s, self.times_s[1:], strict=False)):
            raise ProfileError("steps temperature profile: times must increase strictly")

    def at(self, t_s: np.ndarray) -> np.ndarray:
        idx = np.searchsorted(np.asarray(self.times_s), np.asarray(t_s), side="right") - 1
        return np.asarray(self.temps_c, dtype=np.float64)[np.clip(idx, 0, None)]


@dataclass(frozen=True)
class SineTemperature(TemperatureProfile):
    """``mean_c + amplitude_c sin(2 pi t / period_s + phase_rad)``."""

    mean_c: float
    amplitude_c: float
    period_s: float
    phase_rad: float = 0.0

    def __post_init__(self) -> None:
        if not self.period_s > 0:
            raise ProfileError(
                f"sine temperature profile: period_s must be > 0, got {self.period_s}"
            )

    def at(self, t_s: np.ndarray) -> np.ndarray:
        w = 2.0 * math.pi / self.period_s
        return self.mean_c + self.amplitude_c * np.sin(w * np.asarray(t_s) + self.phase_rad)


class ReplayTemperature(TemperatureProfile):
    """A recorded temperature, linearly interpolated, held at its first/last value."""

    def __init__(self, t_s: np.ndarray, temp_c: np.ndarray, *, name: str = "<array>") -> None:
        t = np.asarray(t_s, dtype=np.float64)
        v = np.asarray(temp_c, dtype=np.float64)
        if t.ndim != 1 or t.shape != v.shape or len(t) == 0:
            raise ProfileError(f"{name}: replayed temperature needs equal-length 1-D arrays")
        ok = np.isfinite(t) & np.isfinite(v)
        t, v = t[ok], v[ok]
        if len(t) == 0:
            raise ProfileError(f"{name}: replayed temperature has no finite sample")
        if np.any(np.diff(t) <= 0):
            raise ProfileError(f"{name}: replayed temperature times must increase strictly")
        self.t_s = t
        self.temp_c = v
        self.name = name

    def at(self, t_s: np.ndarray) -> np.ndarray:
        return np.interp(np.asarray(t_s, dtype=np.float64), self.t_s, self.temp_c)

    @classmethod
    def from_csv(
        cls, path: str | Path, time_col: str = "t_s", temp_col: str = "temp_c"
    ) -> ReplayTemperature:
        """Read two named columns of a CSV file with a header line (``#`` lines skipped)."""
        p = Path(path)
        try:
            with p.open(newline="", encoding="utf-8") as fh:
                rows = csv.DictReader(line for line in fh if not line.lstrip().startswith("#"))
                if rows.fieldnames is None or not {time_col, temp_col} <= set(rows.fieldnames):
                    raise ProfileError(
                        f"{p}: needs columns {time_col!r} and {temp_col!r} in its header,"
                        f" found {rows.fieldnames}"
                    )
                t, v = [], []
                for lineno, row in enumerate(rows, start=2):
                    try:
                        t.append(float(row[time_col]))
                        v.append(float(row[temp_col]))
                    except (TypeError, ValueError):
                        raise ProfileError(
                            f"{p}, data row {lineno}: {time_col}/{temp_col} are not numbers"
                        ) from None
        except OSError as exc:
            raise ProfileError(f"{p}: cannot read temperature file ({exc.strerror})") from exc
        return cls(np.array(t), np.array(v), name=str(p))


class ChamberTemperature(TemperatureProfile):
    """Die temperature of a board in a climatic chamber whose set point a jig changes.

    The chamber air follows each set point at once; the die follows the air as a
    first-order lag of time constant ``time_constant_s`` (thermal mass behind a thermal
    resistance): from a set-point change at ``t_k`` to ``S_k``,
    ``T(t) = S_k + (T(t_k) - S_k) exp(-(t - t_k) / time_constant_s)`` until the next
    change. :meth:`set_point` appends a change (times must not go back), so the profile
    stays a pure function of time for every time before the last change and a sampled
    profile equals the profile sampled at once.
    """

    def __init__(self, start_c: float = 25.0, time_constant_s: float = 120.0) -> None:
        if not time_constant_s > 0:
            raise ProfileError(
                f"chamber temperature: time_constant_s must be > 0, got {time_constant_s}"
            )
        self.time_constant_s = float(time_constant_s)
        self._times: list[float] = [0.0]
        self._starts: list[float] = [float(start_c)]
        self._targets: list[float] = [float(start_c)]

    @property
    def set_point_c(self) -> float:
        """The latest set point, degC."""
        return self._targets[-1]

    def set_point(self, t_s: float, temp_c: float) -> None:
        """From time ``t_s`` (s) on, the chamber air is at ``temp_c`` (degC)."""
        if t_s < self._times[-1]:
            raise ProfileError(
                f"chamber temperature: set point at t={t_s} s is before the previous change"
                f" at t={self._times[-1]} s"
            )
        here = float(self.at(np.array([t_s]))[0])
        self._times.append(float(t_s))
        self._starts.append(here)
        self._targets.append(float(temp_c))

    def at(self, t_s: np.ndarray) -> np.ndarray:
        t = np.asarray(t_s, dtype=np.float64)
        k = np.clip(np.searchsorted(np.asarray(self._times), t, side="right") - 1, 0, None)
        t0 = np.asarray(self._times)[k]
        start = np.asarray(self._starts)[k]
        target = np.asarray(self._targets)[k]
        decay = np.exp(-np.maximum(t - t0, 0.0) / self.time_constant_s)
        return target + (start - target) * decay


def as_profile(value: TemperatureProfile | float | str | None) -> TemperatureProfile:
    """A profile from a profile, a constant degC, a spec string, or None (25 degC)."""
    if value is None:
        return ConstantTemperature(25.0)
    if isinstance(value, TemperatureProfile):
        return value
    if isinstance(value, int | float):
        return ConstantTemperature(float(value))
    if isinstance(value, str):
        return parse_profile(value)
    raise ProfileError(f"cannot use {value!r} as a temperature profile")


def parse_profile(spec: str) -> TemperatureProfile:
    """Parse the one-line profile form (see the module docstring)."""
    s = spec.strip()
    kind, _, rest = s.partition(":")
    try:
        if not rest:
            return ConstantTemperature(float(kind))
        if kind == "constant":
            return ConstantTemperature(float(rest))
        if kind == "ramp":
            parts = [float(x) for x in rest.split(":")]
            if len(parts) not in (2, 3):
                raise ValueError
            return RampTemperature(parts[0], parts[1], parts[2] if len(parts) == 3 else None)
        if kind == "steps":
            pairs = [p.split("=") for p in rest.split(",")]
            return StepTemperature(
                tuple(float(a) for a, _ in pairs), tuple(float(b) for _, b in pairs)
            )
        if kind == "sine":
            parts = [float(x) for x in rest.split(":")]
            if len(parts) not in (3, 4):
                raise ValueError
            return SineTemperature(*parts)
        if kind == "replay":
            path, *cols = rest.split(":")
            if len(cols) not in (0, 2):
                raise ValueError
            return ReplayTemperature.from_csv(path, *cols)
    except ProfileError:  # already precise (it is a ValueError too)
        raise
    except ValueError:
        raise ProfileError(
            f"temperature profile {spec!r}: malformed; use e.g. 25, ramp:20:0.01[:40],"
            " steps:0=20,600=30, sine:25:5:3600 or replay:FILE.csv[:t_s:temp_c]"
        ) from None
    raise ProfileError(
        f"temperature profile {spec!r}: unknown kind {kind!r}; kinds are constant, ramp,"
        " steps, sine, replay"
    )


__all__ = [
    "ChamberTemperature",
    "ConstantTemperature",
    "RampTemperature",
    "ReplayTemperature",
    "SineTemperature",
    "StepTemperature",
    "TemperatureProfile",
    "as_profile",
    "parse_profile",
]
