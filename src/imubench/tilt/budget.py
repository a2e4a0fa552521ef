"""Tilt error budget: the error terms of an accelerometer axis used for tilt, their
worst-case sum and root-sum-square, and the angle they cost; the noise multiplier from
a mission profile.

Rows (the tilt note's, A. Fan, "How to Improve the Accuracy of Inclination Measurement
Using an Accelerometer", Analog Dialogue, Analog Devices): sensitivity error over the
range actually used, offset, nonlinearity over the range used, total offset change over
temperature, and noise times a multiplier ``k``. Each column is a state of the board
(before calibration, after each calibration step). Per column the worst-case error is
``E_wc = sum |e_i|`` and the statistical one ``E_rss = sqrt(sum e_i^2)``; near level an
axis reads ``1 g sin(theta)``, so an error ``E`` (in g) costs ``arcsin(E)`` of tilt
(129 mg -> 7.41 deg, 22.4 mg -> 1.28 deg).

Noise multiplier. A tilt reading exceeds ``k sigma`` of Gaussian noise with probability
``r = P(|Z| > k) = erfc(k / sqrt 2)`` (two-sided). Over a mission of ``M`` independent
readings the expected number of exceedances is ``E = M r``; for a budget allowing ``E``
of them, ``k = Phi^-1(1 - E / (2 M))`` (:func:`multiplier_for`): ``M`` = 146 000 uses
(20 a day for 20 years) and ``E`` = 1 give ``k`` = 4.50. The note states 0.00034 % for
6 sigma: that is the "Six Sigma" quality convention, one-sided with the mean shifted by
1.5 sigma (``P(Z > 4.5)`` = 3.4e-6, :func:`exceedance_six_sigma_convention`); the true
two-sided Gaussian tail at 6 sigma is 1.97e-9, and the coverage of +-6 sigma is
99.9999998 %, far above the "over 97 %" the note states.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from scipy.special import erfc
from scipy.stats import norm

from imubench.tilt.errors import TiltError
from imubench.tomlread import read_toml

SIX_SIGMA_SHIFT = 1.5
"""Mean shift of the Six Sigma convention (Motorola), sigma."""


def exceedance_two_sided(k: float) -> float:
    """``P(|Z| > k)`` for a standard normal ``Z``."""
    return float(erfc(k / math.sqrt(2.0)))


def exceedance_six_sigma_convention(k: float) -> float:
    """``P(Z > k - 1.5)``: the one-sided tail after the 1.5 sigma shift of the Six Sigma
    convention (3.4e-6 at k = 6)."""
    return float(norm.sf(k - SIX_SIGMA_SHIFT))


def multiplier_for(uses: float, expected_exceedances: float) -> float:
    """``k`` such that ``uses`` readings exceed ``k sigma`` ``expected_exceedances`` times
    on average (two-sided Gaussian): ``Phi^-1(1 - E / (2 M))``."""
    if not uses > 0 or not 0 < expected_exceedances < uses:
        raise TiltError(
            f"noise multiplier: need uses > 0 and 0 < expected exceedances < uses, got"
            f" M={uses}, E={expected_exceedances}"
        )
    return float(norm.isf(expected_exceedances / (2.0 * uses)))


def tilt_error_deg(error_g: float) -> float:
    """Tilt error of an axis error ``error_g`` near level: ``arcsin(E)`` in degrees (90
    once the error reaches 1 g)."""
    return math.degrees(math.asin(min(abs(error_g), 1.0)))


@dataclass(frozen=True)
class BudgetRow:
    """One error term across the columns.

    ``values_g`` per column (g); for the noise row ``noise_sigma_g`` holds the 1-sigma
    noise per column and the value is ``multiplier x sigma``.
    """

    name: str
    values_g: tuple[float, ...]
    basis: tuple[str, ...] = ()
    noise_sigma_g: tuple[float, ...] | None = None
    multiplier: float | None = None

    @property
    def is_noise(self) -> bool:
        return self.noise_sigma_g is not None

    def with_multiplier(self, k: float) -> BudgetRow:
        if self.noise_sigma_g is None:
            return self
        return BudgetRow(self.name, tuple(k * s for s in self.noise_sigma_g), self.basis,
                         self.noise_sigma_g, k)


@dataclass(frozen=True)
class ErrorBudget:
    """A tilt error budget (module docstring); ``reconstructed`` marks rows that are not
    the source's own (``provenance`` says how they were made)."""

    title: str
    columns: tuple[str, ...]
    rows: tuple[BudgetRow, ...]
    source: str = ""
    reconstructed: bool = False
    provenance: str = ""
    mission_uses: float | None = None
    mission_exceedances: float | None = None
    notes: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        for row in self.rows:
            if len(row.values_g) != len(self.columns):
                raise TiltError(
                    f"budget {self.title!r}: row {row.name!r} has {len(row.values_g)} values"
                    f" for {len(self.columns)} columns"
                )

    def worst_case_g(self) -> list[float]:
        return [sum(abs(r.values_g[c]) for r in self.rows) for c in range(len(self.columns))]

    def rss_g(self) -> list[float]:
        return [math.sqrt(sum(r.values_g[c] ** 2 for r in self.rows))
                for c in range(len(self.columns))]

    def derived_multiplier(self) -> float | None:
        """``k`` from the mission profile (None without one)."""
        if self.mission_uses is None or self.mission_exceedances is None:
            return None
        return multiplier_for(self.mission_uses, self.mission_exceedances)

    def with_multiplier(self, k: float) -> ErrorBudget:
        """The same budget with the noise row at ``k`` sigma."""
        return ErrorBudget(self.title, self.columns, tuple(r.with_multiplier(k) for r in self.rows),
                           self.source, self.reconstructed, self.provenance, self.mission_uses,
                           self.mission_exceedances, self.notes)

    def summary(self) -> dict[str, Any]:
        """JSON-ready: rows (mg), per column worst case and RSS (mg) and tilt (deg), and
        the noise multiplier analysis."""
        wc, rss = self.worst_case_g(), self.rss_g()
        noise = [r for r in self.rows if r.is_noise]
        k_note = noise[0].multiplier if noise else None
        out: dict[str, Any] = {
            "title": self.title,
            "source": self.source,
            "reconstructed": self.reconstructed,
            "provenance": self.provenance,
            "columns": list(self.columns),
            "rows": [{"name": r.name, "values_mg": [1e3 * v for v in r.values_g],
                      "basis": list(r.basis), "multiplier": r.multiplier} for r in self.rows],
            "worst_case_mg": [1e3 * v for v in wc],
            "worst_case_deg": [tilt_error_deg(v) for v in wc],
            "rss_mg": [1e3 * v for v in rss],
            "rss_deg": [tilt_error_deg(v) for v in rss],
        }
        if k_note is not None:
            out["noise_multiplier"] = {
                "used": k_note,
                "exceedance_two_sided": exceedance_two_sided(k_note),
                "exceedance_six_sigma_convention": exceedance_six_sigma_convention(k_note),
                "coverage_two_sided": 1.0 - exceedance_two_sided(k_note),
            }
        k = self.derived_multiplier()
        if k is not None:
            derived = self.with_multiplier(k)
            out["mission"] = {
                "uses": self.mission_uses,
                "expected_exceedances": self.mission_exceedances,
                "multiplier": k,
                "exceedance_per_use": exceedance_two_sided(k),
                "worst_case_mg": [1e3 * v for v in derived.worst_case_g()],
                "worst_case_deg": [tilt_error_deg(v) for v in derived.worst_case_g()],
                "rss_mg": [1e3 * v for v in derived.rss_g()],
                "rss_deg": [tilt_error_deg(v) for v in derived.rss_g()],
            }
            if k_note is not None and self.mission_uses is not None:
                out["mission"]["expected_exceedances_at_used_multiplier"] = (
                    self.mission_uses * exceedance_two_sided(k_note)
                )
        return out

    def to_toml(self) -> str:
        """The budget file (:func:`load_budget` reads it back)."""
        import tomli_w

        rows: list[dict[str, Any]] = []
        for r in self.rows:
            row: dict[str, Any] = {"name": r.name}
            if r.noise_sigma_g is not None:
                row["sigma_mg"] = [1e3 * v for v in r.noise_sigma_g]
                row["multiplier"] = r.multiplier
            else:
                row["values_mg"] = [1e3 * v for v in r.values_g]
            if r.basis:
                row["basis"] = list(r.basis)
            rows.append(row)
        d: dict[str, Any] = {"title": self.title, "source": self.source,
                             "reconstructed": self.reconstructed,
                             "provenance": self.provenance, "columns": list(self.columns),
                             "rows": rows, "notes": list(self.notes)}
        if self.mission_uses is not None and self.mission_exceedances is not None:
            d["mission"] = {"uses": self.mission_uses,
                            "expected_exceedances": self.mission_exceedances}
        return tomli_w.dumps(d)

    def render(self) -> str:
        """A plain-text table (mg, degrees) with the multiplier analysis."""
        s = self.summary()
        w = max(24, *(len(r.name) + 2 for r in self.rows))
        cw = max(14, *(len(c) + 2 for c in self.columns))
        lines = [self.title]
        if self.source:
            lines.append(f"source: {self.source}")
        if self.reconstructed:
            lines.append(f"ROWS RECONSTRUCTED: {self.provenance}")
        lines.append("term".ljust(w) + "".join(c.rjust(cw) for c in self.columns))
        for r in s["rows"]:
            lines.append(r["name"].ljust(w) + "".join(f"{v:{cw}.2f}" for v in r["values_mg"]))
        for label, key, fmt in (("worst-case sum (mg)", "worst_case_mg", ".1f"),
                                ("tilt, worst case (deg)", "worst_case_deg", ".2f"),
                                ("root-sum-square (mg)", "rss_mg", ".1f"),
                                ("tilt, RSS (deg)", "rss_deg", ".2f")):
            lines.append(label.ljust(w) + "".join(f"{v:{cw}{fmt}}" for v in s[key]))
        nm = s.get("noise_multiplier")
        if nm:
            lines.append(
                f"noise at {nm['used']:g} sigma: two-sided Gaussian exceedance"
                f" {nm['exceedance_two_sided']:.3g} per reading (coverage"
                f" {100 * nm['coverage_two_sided']:.7f} %); the 'Six Sigma' convention"
                f" (one-sided, 1.5 sigma shift) gives {nm['exceedance_six_sigma_convention']:.3g}"
                f" = {100 * nm['exceedance_six_sigma_convention']:.5f} %"
            )
        m = s.get("mission")
        if m:
            lines.append(
                f"mission: M = {m['uses']:g} uses, E = {m['expected_exceedances']:g} expected"
                f" exceedances -> k = {m['multiplier']:.3f} (r = {m['exceedance_per_use']:.3g}"
                " per use)"
            )
            if "expected_exceedances_at_used_multiplier" in m and nm:
                lines.append(
                    f"  at the used {nm['used']:g} sigma the mission expects"
                    f" {m['expected_exceedances_at_used_multiplier']:.3g} exceedances"
                )
            lines.append("worst case, k derived (mg)".ljust(w)
                         + "".join(f"{v:{cw}.1f}" for v in m["worst_case_mg"]))
            lines.append("tilt, k derived (deg)".ljust(w)
                         + "".join(f"{v:{cw}.2f}" for v in m["worst_case_deg"]))
        lines.extend(self.notes)
        return "\n".join(lines)


# ---------------------------------------------------------------------- file
def _numbers(v: Any, where: str, n: int) -> tuple[float, ...]:
    if not isinstance(v, list) or len(v) != n or not all(
        isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x) for x in v
    ):
        raise TiltError(f"{where}: must be a list of {n} finite numbers, got {v!r}")
    return tuple(float(x) for x in v)


def budget_from_dict(d: Mapping[str, Any], where: str) -> ErrorBudget:
    """Build from the TOML structure (see docs/calibration.md, "Tilt error budget")."""
    allowed = {"title", "source", "reconstructed", "provenance", "columns", "rows",
               "mission", "notes"}
    extra = sorted(set(d) - allowed)
    if extra:
        raise TiltError(f"{where}: unknown keys {extra}; allowed: {sorted(allowed)}")
    cols = d.get("columns")
    if not isinstance(cols, list) or not cols or not all(isinstance(c, str) for c in cols):
        raise TiltError(f"{where}: 'columns' must be a non-empty list of names")
    rows = []
    for i, r in enumerate(d.get("rows", [])):
        w = f"{where}: rows[{i}]"
        if not isinstance(r, Mapping) or not isinstance(r.get("name"), str):
            raise TiltError(f"{w}: each row needs a 'name'")
        bad = sorted(set(r) - {"name", "values_mg", "sigma_mg", "multiplier", "basis"})
        if bad:
            raise TiltError(f"{w} ({r['name']}): unknown keys {bad}")
        basis = tuple(str(b) for b in r.get("basis", []))
        if "sigma_mg" in r:
            sig = tuple(v / 1e3 for v in _numbers(r["sigma_mg"], f"{w} sigma_mg", len(cols)))
            k = r.get("multiplier")
            if isinstance(k, bool) or not isinstance(k, int | float) or not k > 0:
                raise TiltError(f"{w} ({r['name']}): a noise row needs 'multiplier' > 0")
            rows.append(BudgetRow(r["name"], tuple(k * s for s in sig), basis, sig, float(k)))
        else:
            vals = _numbers(r.get("values_mg"), f"{w} values_mg", len(cols))
            rows.append(BudgetRow(r["name"], tuple(v / 1e3 for v in vals), basis))
    if not rows:
        raise TiltError(f"{where}: no [[rows]]")
    mission = d.get("mission", {})
    return ErrorBudget(
        title=str(d.get("title", "")), columns=tuple(cols), rows=tuple(rows),
        source=str(d.get("source", "")), reconstructed=bool(d.get("reconstructed", False)),
        provenance=str(d.get("provenance", "")),
        mission_uses=mission.get("uses"), mission_exceedances=mission.get("expected_exceedances"),
        notes=tuple(str(n) for n in d.get("notes", [])),
    )


def load_budget(path: str | Path) -> ErrorBudget:
    data, _ = read_toml(path, "budget file", TiltError)
    return budget_from_dict(data, str(path))


# ------------------------------------------------------------- from sensor terms
@dataclass(frozen=True)
class AxisErrors:
    """The error terms of one accelerometer axis in one state (all in g or fractions).

    Attributes:
        sensitivity_error: fraction (0.01 = 1 %).
        offset_g: offset.
        nonlinearity: fraction of the range used.
        offset_change_g: total offset change over the temperature range.
        noise_sigma_g: 1-sigma noise of one (averaged) reading.
    """

    sensitivity_error: float
    offset_g: float
    nonlinearity: float
    offset_change_g: float
    noise_sigma_g: float


def budget_from_states(title: str, states: Sequence[tuple[str, AxisErrors]],
                       range_used_g: float, multiplier: float,
                       mission: tuple[float, float] | None = None,
                       notes: Sequence[str] = ()) -> ErrorBudget:
    """A budget whose columns are board states (e.g. before and after each calibration
    step): sensitivity and nonlinearity are scaled by the range used."""
    names = tuple(n for n, _ in states)
    e = [s for _, s in states]
    rows = (
        BudgetRow("sensitivity error", tuple(abs(s.sensitivity_error) * range_used_g for s in e),
                  (f"x {range_used_g:g} g range used",)),
        BudgetRow("offset", tuple(abs(s.offset_g) for s in e)),
        BudgetRow("nonlinearity", tuple(abs(s.nonlinearity) * range_used_g for s in e),
                  (f"x {range_used_g:g} g range used",)),
        BudgetRow("total offset change over temperature",
                  tuple(abs(s.offset_change_g) for s in e)),
        BudgetRow("noise", tuple(multiplier * s.noise_sigma_g for s in e), (),
                  tuple(s.noise_sigma_g for s in e), multiplier),
    )
    return ErrorBudget(title, names, rows,
                       mission_uses=None if mission is None else mission[0],
                       mission_exceedances=None if mission is None else mission[1],
                       notes=tuple(notes))


__all__ = [
    "SIX_SIGMA_SHIFT", "AxisErrors", "BudgetRow", "ErrorBudget", "budget_from_dict",
    "budget_from_states", "exceedance_six_sigma_convention", "exceedance_two_sided",
    "load_budget", "multiplier_for", "tilt_error_deg",
]
