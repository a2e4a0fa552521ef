"""Brute-force cross-checks of the fast kernels against plain-numpy transcriptions.

Each reference below is written from the published formula, term by term, with no shared
code: Theo1 from NIST SP 1065 eq. (31) (blocked-FFT path of ``theo``), the MTOT/HTOT
subsequence sum from SP 1065 eq. (27) (sliding-prefix kernel of ``_kernels``), and the
lag-1 autocorrelation noise identification from Riley & Greenhall (2004) / SP 1065
section 5.6 (fused kernel of ``noise_id.lag1_alpha``).
"""

from __future__ import annotations

import numpy as np
import pytest

from imubench.errors import StatsError
from imubench.stats import _kernels as k
from imubench.stats import theo
from imubench.stats.noise_id import identify_alpha, lag1_alpha


def _series(kind: str, n: int, seed: int) -> np.ndarray:
    """White, random-walk (with a large offset) and integrated random-walk sequences."""
    rng = np.random.default_rng(seed)
    w = rng.standard_normal(n)
    if kind == "white":
        return w
    if kind == "walk":
        return np.cumsum(w) + 1e3
    return np.cumsum(np.cumsum(w))


def _theo1_sum_sp1065(x: np.ndarray, m: int) -> float:
    """sum_{i=0}^{N-m-1} sum_{d=0}^{m/2-1} [(x_i - x_{i-d+m/2}) + (x_{i+m} - x_{i+d+m/2})]^2
    / (m/2 - d), SP 1065 eq. (31) without its normalisation."""
    n = x.size
    i = np.arange(n - m)
    s = 0.0
    for d in range(m // 2):
        e = (x[i] - x[i - d + m // 2]) + (x[i + m] - x[i + d + m // 2])
        s += float(np.sum(e * e)) / (m // 2 - d)
    return s


@pytest.mark.parametrize("kind", ["white", "walk"])
def test_theo1_blocked_fft_equals_sp1065_sum(kind: str) -> None:
    y = _series(kind, 500, 7)
    x = np.concatenate([[0.0], np.cumsum(y)])
    ms = np.arange(2, 420, 2, dtype=np.int64)  # several FFT blocks, partial and full
    ref = np.array([_theo1_sum_sp1065(x, int(m)) for m in ms])
    for n_fft in (ms.size, 60, 0):  # all by FFT, split, all direct
        got = theo.theo1_sums_nogap(x, ms, n_fft)
        np.testing.assert_allclose(got, ref, rtol=1e-9)


def test_theo1_cost_model_sends_dense_factors_to_fft() -> None:
    n = 100_001
    support = theo.theobr_support_m(n)
    octave = np.array([16384, 32768, 65536], dtype=np.int64)
    srt = np.unique(np.concatenate([support, octave]))
    assert theo.fft_count(srt, n) == support.size  # the octave tail stays direct
    assert theo.fft_count(np.array([10, 16, 32], dtype=np.int64), n) == 0


def _subseq_sum_sp1065(series: np.ndarray, m: int, starts: np.ndarray) -> float:
    """sum over starts of mean_j z_j^2 / m^2: each 3m subsequence detrended by the
    half-means slope, reflected (uninverted, even) to 9m points, z_j the second difference
    of m-point averages times m (SP 1065 eq. (27))."""
    n3 = 3 * m
    h = n3 // 2
    total = 0.0
    for s in starts:
        v = series[s : s + n3]
        slope = (v[n3 - h :].mean() - v[:h].mean()) / (n3 - h)
        d = v - slope * np.arange(n3)
        e = np.concatenate([d[::-1], d, d[::-1]])
        avg = np.array([e[j : j + m].sum() for j in range(8 * m + 1)])
        z = avg[2 * m : 2 * m + 6 * m] - 2.0 * avg[m : m + 6 * m] + avg[: 6 * m]
        total += float(np.mean(z * z)) / m**2
    return total


@pytest.mark.parametrize("kind", ["white", "walk"])
@pytest.mark.parametrize("m", [1, 5, 24])
def test_mtot_sliding_kernel_equals_sp1065(kind: str, m: int) -> None:
    y = _series(kind, 400, 11)
    starts = np.arange(y.size - 3 * m + 1, dtype=np.int64)  # > PREFIX_REFRESH in a row
    gapped = starts[(starts % 37) != 3]  # runs broken by skipped starts
    for st in (starts, gapped):
        ref = _subseq_sum_sp1065(y, m, st)
        assert k.subseq_meansq_sum(y, m, st) == pytest.approx(ref, rel=1e-11)


def _lag1_alpha_numpy(x: np.ndarray, m: int, data_type: str, dmax: int) -> int:
    """Riley & Greenhall lag-1 recipe in plain numpy (NaN pairs skipped)."""
    z = x[::m] if data_type == "phase" else np.diff(x[::m]) / m
    d = 0
    while True:
        ok = np.isfinite(z)
        n = int(ok.sum())
        c = z - z[ok].mean()
        den = float(np.sum(c[ok] ** 2))
        pair = ok[:-1] & ok[1:]
        r1 = float(np.sum(c[:-1][pair] * c[1:][pair])) / den * (n - 1) / n
        delta = r1 / (1.0 + r1)
        if delta < 0.25 or d >= dmax:
            p = -round(2.0 * delta) - 2 * d
            return int(p + 2 if data_type == "phase" else p)
        z = np.diff(z)
        d += 1


@pytest.mark.parametrize("data_type", ["phase", "freq"])
def test_fused_lag1_equals_numpy_recipe(data_type: str) -> None:
    rng = np.random.default_rng(5)
    for kind in ("white", "walk", "run"):
        for seed in range(3):
            x = np.concatenate([[0.0], np.cumsum(_series(kind, 3000, seed))])
            if data_type == "phase":
                x = _series(kind, 3001, seed)
            x[rng.integers(0, x.size, 5)] = np.nan  # gaps
            for m in (1, 2, 3, 8, 50):
                for dmax in (2, 3):
                    assert lag1_alpha(x, m, data_type, dmax=dmax) == _lag1_alpha_numpy(
                        x, m, data_type, dmax
                    ), (kind, seed, m, dmax)


def test_identify_alpha_counts_points_like_numpy() -> None:
    x = np.concatenate([[0.0], np.cumsum(np.random.default_rng(2).standard_normal(299))])
    x[::7] = np.nan
    # freq averages at m = 9: finite where both decimated phase points are finite
    fd = np.isfinite(x[::9])
    big = x.size
    assert k.points_at_tau(x, 9, True, big) == int(np.count_nonzero(fd[1:] & fd[:-1]))
    assert k.points_at_tau(x, 9, False, big) == int(np.count_nonzero(fd))
    assert k.points_at_tau(x, 1, False, 30) == 30  # stops counting at the limit
    assert identify_alpha(x, 2, "freq", "oadev") == _lag1_alpha_numpy(x, 2, "freq", 2)
    with pytest.raises(StatsError, match="dmax=4"):
        lag1_alpha(x, 1, "freq", dmax=4)


def test_mtot_thread_split_equals_one_pass(monkeypatch: pytest.MonkeyPatch) -> None:
    from imubench.stats import total

    y = _series("walk", 2000, 3)
    starts = np.arange(y.size - 3 * 40 + 1, dtype=np.int64)
    one = k.subseq_meansq_sum(y, 40, starts)
    monkeypatch.setattr(total, "THREADS", 3)
    monkeypatch.setattr(total, "THREAD_MIN_WORK", 1)
    assert total._subseq_meansq_sum(y, 40, starts) == pytest.approx(one, rel=1e-12)
