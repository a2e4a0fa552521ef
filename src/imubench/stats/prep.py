"""Input preparation: phase conversion, gap bookkeeping and linear frequency drift removal.

Conventions (NIST SP 1065 section 4.1): phase x in seconds, fractional frequency (or a
sensor's rate, e.g. dps) y; for frequency input ``x[0] = 0, x[k] = tau0 * sum(y[:k])`` so
that variances of a rate signal carry the rate's units squared. The frequency mean is
subtracted before integration (it cancels in every statistic, see docs/statistics.md, and
keeps cumulative sums well conditioned: a 1e6-sample record offset by 1e3 gives the
offset-free result to 1e-9). NaN samples are gaps: :class:`PhaseData` keeps a prefix
count of them so that a term spanning phase points ``a..b`` can be tested in O(1) and
skipped, never bridged.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imubench.errors import StatsError


@dataclass(frozen=True)
class PhaseData:
    """Phase-form data ready for the kernels.

    x: float64 phase, NaN replaced by 0 (only terms free of gaps are ever used).
    tau0_s: sampling interval. gap_prefix: None without gaps, else an int64 prefix count G
    such that the span of phase points a..b (inclusive) is gap-free iff
    ``G[b + gap_end_offset] - G[a] == 0``: for phase input G[k] = #NaN in x[:k] and the
    offset is 1; for frequency input G[k] = #NaN in y[:k] (span a..b uses y[a:b]) and the
    offset is 0.
    """

    x: np.ndarray
    tau0_s: float
    gap_prefix: np.ndarray | None
    gap_end_offset: int = 1

    @property
    def n_phase(self) -> int:
        return int(self.x.size)

    def runs(self) -> tuple[np.ndarray, np.ndarray]:
        """The gap-free runs: (their distinct lengths in phase points, how many runs have
        each); ``([n_phase], [1])`` without gaps. A phase gap removes its point; a
        frequency gap y[k] cuts x[k] from x[k+1], so a run of L frequency samples is L + 1
        phase points. Runs of one point are left out (they hold no difference)."""
        if self.gap_prefix is None:
            return np.array([self.n_phase], dtype=np.int64), np.ones(1, dtype=np.int64)
        bad = np.diff(self.gap_prefix) > 0
        if self.gap_end_offset == 1:  # phase: bad[k] is x[k] missing
            good = ~bad
            extra = 0
        else:  # frequency: bad[k] is y[k] missing; a run of L samples links L + 1 points
            good = ~bad[: self.n_phase - 1]
            extra = 1
        edges = np.diff(np.concatenate(([0], good.astype(np.int8), [0])))
        lengths = np.nonzero(edges == -1)[0] - np.nonzero(edges == 1)[0] + extra
        lengths, counts = np.unique(lengths[lengths > 1], return_counts=True)
        return lengths.astype(np.int64), counts.astype(np.int64)

    def span_ok(self, a: np.ndarray | int, b: np.ndarray | int) -> np.ndarray | bool:
        """True where phase points a..b (inclusive) contain no gap."""
        if self.gap_prefix is None:
            return np.ones(np.shape(a), dtype=bool) if np.ndim(a) else True
        g = self.gap_prefix
        return (g[np.asarray(b) + self.gap_end_offset] - g[np.asarray(a)]) == 0


def _as_float_array(data: object) -> tuple[np.ndarray, float, bool]:
    """1-D float64 view (no copy when possible), its NaN-free mean (NaN if every sample is
    NaN) and whether it holds NaN.

    The plain mean (one pass, no temporary) is finite exactly when the data hold neither
    NaN nor inf (barring overflow), so the NaN/inf scans run only when it is not.
    """
    try:
        arr = np.asarray(data, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise StatsError(f"data must be a 1-D array of numbers: {exc}") from exc
    if arr.ndim != 1:
        raise StatsError(f"data must be 1-D, got shape {arr.shape}")
    mean = float(arr.mean()) if arr.size else float("nan")
    if np.isfinite(mean):
        return arr, mean, False
    if np.any(np.isinf(arr)):
        raise StatsError("data contains +/-inf; mark missing samples with NaN instead")
    nan = np.isnan(arr)
    return arr, float(np.nanmean(arr)) if not nan.all() else float("nan"), bool(nan.any())


def remove_drift_freq(y: np.ndarray, tau0_s: float) -> tuple[np.ndarray, float]:
    """Remove the least-squares linear frequency drift from y (NaN ignored).

    Returns (y - D t, D) with D in y-units per second, t = k tau0 (SP 1065 sec. 5.3.x,
    linear frequency drift model).
    """
    ok = np.isfinite(y)
    if ok.sum() < 3:
        raise StatsError("remove_drift needs at least 3 valid frequency samples")
    t = np.arange(y.size, dtype=np.float64) * tau0_s
    slope, _ = np.polyfit(t[ok], y[ok], 1)
    return y - slope * t, float(slope)


def remove_drift_phase(x: np.ndarray, tau0_s: float) -> tuple[np.ndarray, float]:
    """Remove the least-squares quadratic (linear frequency drift) from phase x.

    x(t) = a + b t + (D / 2) t^2 (SP 1065 eq. for the quadratic phase model); returns
    (x - D t^2 / 2, D) with D in fractional frequency (or rate units) per second.
    """
    ok = np.isfinite(x)
    if ok.sum() < 4:
        raise StatsError("remove_drift needs at least 4 valid phase samples")
    t = np.arange(x.size, dtype=np.float64) * tau0_s
    c2, _, _ = np.polyfit(t[ok], x[ok], 2)
    return x - c2 * t * t, float(2.0 * c2)


def to_phase(
    data: object, rate_hz: float, data_type: str, remove_drift: bool = False
) -> tuple[PhaseData, float | None]:
    """Validate input and convert to :class:`PhaseData`; returns (phase, removed drift)."""
    if not (isinstance(rate_hz, int | float) and np.isfinite(rate_hz) and rate_hz > 0):
        raise StatsError(f"rate must be a positive finite number of Hz, got {rate_hz!r}")
    tau0 = 1.0 / float(rate_hz)
    arr, mean, has_gaps = _as_float_array(data)
    drift: float | None = None
    if data_type not in ("freq", "phase"):
        raise StatsError(f"data_type must be 'phase' or 'freq', got {data_type!r}")
    if data_type == "freq" and arr.size < 2:
        raise StatsError(f"need at least 2 frequency samples, got {arr.size}")
    if data_type == "phase" and arr.size < 3:
        raise StatsError(f"need at least 3 phase samples, got {arr.size}")
    if not np.isfinite(mean):
        raise StatsError(f"every {'frequency' if data_type == 'freq' else 'phase'} sample is NaN")
    if remove_drift:
        fn = remove_drift_freq if data_type == "freq" else remove_drift_phase
        arr, drift = fn(arr, tau0)
        mean = float(np.nanmean(arr)) if has_gaps else float(arr.mean())
    if data_type == "freq":
        # x[0] = 0, x[k] = tau0 * sum(y[:k] - mean): the mean (an IMU's 1 g, a clock's
        # offset) is removed before integration so the phase stays small and exact
        x = np.empty(arr.size + 1)
        x[0] = 0.0
        y = x[1:]
        np.subtract(arr, mean, out=y)
        # span a..b of phase uses y[a:b]; G[k] = #NaN in y[:k]
        gp = _zero_gaps(y) if has_gaps else None
        if tau0 != 1.0:
            y *= tau0
        np.cumsum(y, out=y)
        return PhaseData(x, tau0, gp, gap_end_offset=0), drift
    x = np.subtract(arr, mean)
    return PhaseData(x, tau0, _zero_gaps(x) if has_gaps else None), drift


def _zero_gaps(v: np.ndarray) -> np.ndarray:
    """Set the NaN samples of ``v`` to 0 in place; return G with G[k] = #NaN in v[:k]."""
    bad = np.isnan(v)
    v[bad] = 0.0
    gp = np.zeros(v.size + 1, dtype=np.int64)
    np.cumsum(bad, out=gp[1:])
    return gp
