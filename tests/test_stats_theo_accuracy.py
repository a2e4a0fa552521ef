"""TheoBR and TheoH against an independent estimator, and numerical accuracy of the kernels.

* TheoBR: allantools' Theo1 (an independent O(N m^2) implementation) and OADEV, combined
  with the bias-removal ratio of NIST SP 1065 eq. (32) (Howe & Tasset 2004), written here
  from the handbook: kf = 1/(n+1) sum_{i=0}^{n} OAVAR(m = 9 + 3i) / Theo1(m = 12 + 4i),
  n = floor(0.1 N / 3 - 3), TheoBR(m) = kf Theo1(m).
* TheoH (SP 1065 eq. (33), as Stable32 plots it): OAVAR at m <= 0.1 T / tau0, TheoBR beyond.
* Frequency input with a large constant offset (an IMU axis at 1 g) gives the offset-free
  numbers; gapped kernels equal a brute-force sum written from the SP 1065 formulas.
"""

from __future__ import annotations

import allantools as at
import numpy as np
import pytest

import imubench.stats as st


def _theobr_reference(y: np.ndarray, ms: np.ndarray) -> np.ndarray:
    n_phase = y.size + 1
    nb = int(np.floor(0.1 * n_phase / 3.0 - 3.0))
    i = np.arange(nb + 1)
    m_avar = (9 + 3 * i).astype(float)
    m_theo = (12 + 4 * i).astype(float)
    _, oadev, _, _ = at.oadev(y, rate=1.0, data_type="freq", taus=m_avar)
    _, theo, _, _ = at.theo1(y, rate=1.0, data_type="freq", taus=m_theo)
    kf = float(np.mean(oadev**2 / theo**2))
    _, theo_m, _, _ = at.theo1(y, rate=1.0, data_type="freq", taus=ms.astype(float))
    return np.sqrt(kf) * theo_m


@pytest.fixture(scope="module")
def flicker_walk() -> np.ndarray:
    rng = np.random.default_rng(2026)
    white = rng.standard_normal(360)
    return white + 0.05 * np.cumsum(rng.standard_normal(360))  # white + random-walk FM


def test_theobr_matches_allantools_theo1_with_sp1065_ratio(flicker_walk: np.ndarray) -> None:
    ms = np.array([10, 16, 40, 100, 200, 300], dtype=np.int64)
    ours = st.theobr(flicker_walk, 1.0, "freq", afs=ms, alpha=0)
    np.testing.assert_array_equal(ours.m, ms)
    np.testing.assert_allclose(ours.tau_s, 0.75 * ms)
    np.testing.assert_allclose(ours.dev, _theobr_reference(flicker_walk, ms), rtol=1e-9)
    assert any("TheoBR kf" in note for note in ours.notes)


def test_theoh_is_oadev_then_theobr(flicker_walk: np.ndarray) -> None:
    res = st.theoh(flicker_walk, 1.0, "freq", "octave", alpha=0)
    k = int(np.floor(0.1 * flicker_walk.size))  # 0.1 T / tau0 = 36
    short = res.m <= k
    assert short.any() and (~short).any()
    assert np.all(res.m[~short] % 2 == 0) and np.all(0.75 * res.m[~short] > k)
    oa = st.oadev(flicker_walk, 1.0, "freq", afs=res.m[short], alpha=0)
    br = st.theobr(flicker_walk, 1.0, "freq", afs=res.m[~short], alpha=0)
    np.testing.assert_array_equal(res.var[short], oa.var)
    np.testing.assert_array_equal(res.var[~short], br.var)
    np.testing.assert_array_equal(res.tau_s, np.concatenate([oa.tau_s, br.tau_s]))
    np.testing.assert_array_equal(res.ci_low, np.concatenate([oa.ci_low, br.ci_low]))
    # and the long-tau part is the independent TheoBR of the test above
    np.testing.assert_allclose(
        res.dev[~short], _theobr_reference(flicker_walk, res.m[~short]), rtol=1e-9
    )


@pytest.mark.parametrize(
    ("stat", "n", "afs"),
    [
        ("oadev", 1_000_000, None),
        ("mdev", 1_000_000, None),
        ("ohdev", 1_000_000, None),
        ("totdev", 1_000_000, None),
        ("ostdev", 1_000_000, None),
        ("mtotdev", 20_000, [1, 8, 64]),
        ("htotdev", 20_000, [2, 8, 64]),
        ("theo1", 20_000, [10, 64, 512]),
    ],
)
def test_large_frequency_offset_is_harmless(stat: str, n: int, afs: list[int] | None) -> None:
    """1e6 rate samples offset by 1e3 (integrated without care this loses ~7 digits)."""
    y = np.random.default_rng(5).standard_normal(n)
    kw = {"alpha": 0, "bias_correction": False, "afs": afs}
    clean = st.compute(stat, y, 100.0, "freq", **kw)
    offset = st.compute(stat, y + 1e3, 100.0, "freq", **kw)
    np.testing.assert_allclose(offset.dev, clean.dev, rtol=1e-9)


def _brute(stat: str, x: np.ndarray, m: int, tau0: float) -> tuple[float, int]:
    """SP 1065 eqs. (11), (15), (19), (25) term by term; a term is used only if every phase
    point it reads is finite (phase input: NaN marks a gap)."""
    n = x.size
    terms = []
    if stat == "oadev":
        for i in range(n - 2 * m):
            terms.append(
                x[i + 2 * m] - 2 * x[i + m] + x[i]
                if np.isfinite(x[i : i + 2 * m + 1]).all()
                else np.nan
            )
        norm = 2.0 * (m * tau0) ** 2
    elif stat == "ohdev":
        for i in range(n - 3 * m):
            ok = np.isfinite(x[i : i + 3 * m + 1]).all()
            terms.append(x[i + 3 * m] - 3 * x[i + 2 * m] + 3 * x[i + m] - x[i] if ok else np.nan)
        norm = 6.0 * (m * tau0) ** 2
    else:  # mdev
        for j in range(n - 3 * m + 1):
            seg = x[j : j + 3 * m]
            ok = np.isfinite(seg).all()
            s = sum(x[i + 2 * m] - 2 * x[i + m] + x[i] for i in range(j, j + m)) if ok else np.nan
            terms.append(s)
        norm = 2.0 * m**2 * (m * tau0) ** 2
    t = np.array(terms)
    t = t[np.isfinite(t)]
    return float(np.sum(t * t) / (norm * t.size)), int(t.size)


@pytest.mark.parametrize("stat", ["oadev", "ohdev", "mdev"])
@pytest.mark.parametrize("m", [1, 3, 8])
def test_gapped_kernels_equal_brute_force(stat: str, m: int) -> None:
    rng = np.random.default_rng(9)
    x = np.cumsum(rng.standard_normal(300))
    x[[40, 41, 150, 299]] = np.nan
    res = st.compute(stat, x, 2.0, "phase", afs=[m], alpha=0)
    var, n = _brute(stat, x - np.nanmean(x), m, 0.5)
    assert int(res.n[0]) == n
    assert res.var[0] == pytest.approx(var, rel=1e-12)
