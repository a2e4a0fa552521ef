"""NBS14 (SP 1065 test suite) values, gaps, drift removal, taus, and allantools agreement."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import imubench.stats as st
from imubench.errors import StatsError
from imubench.stats.taus import averaging_factors

NBS = "allantools-stable32/nbs14"


def _nbs_table(path: Path) -> dict[str, list[float]]:
    out: dict[str, list[float]] = {}
    for line in path.read_text().splitlines():
        if line.startswith("#") or not line.strip():
            continue
        parts = line.split()
        vals = []
        for p in parts[1:]:
            try:
                vals.append(float(p))
            except ValueError:
                break
        out[parts[0]] = vals
    return out


@pytest.fixture(scope="module")
def nbs1000(reference_dir: Path) -> np.ndarray:
    return np.loadtxt(reference_dir / NBS / "nbs14_1000point_frequency.txt")


# statistic name in the table -> (our stat, bias correction, relative tolerance)
NBS1000 = {
    "ADEV": ("adev", False, 1e-6),
    "OADEV": ("oadev", False, 1e-6),
    "MDEV": ("mdev", False, 1e-6),
    "TDEV": ("tdev", False, 1e-6),
    "HDEV": ("hdev", False, 1e-6),
    "OHDEV": ("ohdev", False, 1e-6),
    "TOTDEV": ("totdev", False, 1e-6),
    "STDDEV_sample": ("stdev", False, 1e-6),
    "MTOTDEV_S32": ("mtotdev", False, 1e-4),
    "TTOTDEV_S32": ("ttotdev", False, 1e-4),
}


@pytest.mark.parametrize("name", sorted(NBS1000))
def test_nbs14_1000point(reference_dir: Path, nbs1000: np.ndarray, name: str) -> None:
    table = _nbs_table(reference_dir / NBS / "nbs14_1000point_reference.txt")
    stat, bias, rtol = NBS1000[name]
    res = st.compute(stat, nbs1000, 1.0, "freq", [1.0, 10.0, 100.0], alpha=0, bias_correction=bias)
    np.testing.assert_array_equal(res.m, [1, 10, 100])
    np.testing.assert_allclose(res.dev, table[name][:3], rtol=rtol)


def test_nbs14_1000point_mtot_ttot_published_bias(reference_dir: Path, nbs1000: np.ndarray) -> None:
    """Published SP 1065 MTOT/TTOT values = uncorrected / sqrt(0.73) (white FM factor)."""
    table = _nbs_table(reference_dir / NBS / "nbs14_1000point_reference.txt")
    for stat, key in (("mtotdev", "MTOTDEV_pub"), ("ttotdev", "TTOTDEV_pub")):
        res = st.compute(
            stat, nbs1000, 1.0, "freq", [1.0, 10.0, 100.0], alpha=0, bias_correction=False
        )
        np.testing.assert_allclose(res.dev / np.sqrt(0.73), table[key], rtol=2e-4)


def test_nbs14_1000point_htot_published(reference_dir: Path, nbs1000: np.ndarray) -> None:
    """HTOTDEV_pub is bias corrected (0.995 for white FM) except at m = 1 (= OHDEV)."""
    table = _nbs_table(reference_dir / NBS / "nbs14_1000point_reference.txt")
    res = st.htotdev(nbs1000, 1.0, "freq", [1.0, 10.0, 100.0], alpha=0, bias_correction=False)
    expect = np.array(table["HTOTDEV"]) * np.sqrt([1.0, 0.995, 0.995])
    np.testing.assert_allclose(res.dev, expect, rtol=1e-4)


def test_nbs14_1000point_theo1(reference_dir: Path, nbs1000: np.ndarray) -> None:
    table = _nbs_table(reference_dir / NBS / "nbs14_1000point_reference.txt")
    res = st.theo1(nbs1000, 1.0, "freq", afs=[10, 100, 998], alpha=0, bias_correction=False)
    np.testing.assert_allclose(res.tau_s, [7.5, 75.0, 748.5])
    np.testing.assert_allclose(res.dev[:2], table["THEO1_S32_m10_100_1000"][:2], rtol=1e-4)


NBS10_FREQ = np.array([892, 809, 823, 798, 671, 644, 883, 903, 677], dtype=float)
NBS10 = {
    "adev": [91.22945, 115.8082],
    "oadev": [91.22945, 85.95287],
    "mdev": [91.22945, 74.78849],
    "totdev": [91.22945, 93.90379],
    "hdev": [70.80608, 116.7980],
    "tdev": [52.67135, 86.35831],
    "ohdev": [70.80607, 85.61487],
    "stdev": [100.9770, 102.6039],
}


@pytest.mark.parametrize("stat", sorted(NBS10))
def test_nbs14_10point(stat: str) -> None:
    """SP 1065 p.107 values at tau = 1, 2 (the stop ratio is lifted: only 9 samples)."""
    res = st.compute(stat, NBS10_FREQ, 1.0, "freq", afs=[1, 2], alpha=0, bias_correction=False)
    np.testing.assert_allclose(res.dev, NBS10[stat], rtol=2e-6)


def test_nbs14_10point_mtot_ttot_stable32() -> None:
    m = st.mtotdev(NBS10_FREQ, 1.0, "freq", afs=[1, 2], alpha=0, bias_correction=False)
    t = st.ttotdev(NBS10_FREQ, 1.0, "freq", afs=[1, 2], alpha=0, bias_correction=False)
    np.testing.assert_allclose(m.dev, [64.509, 64.794], rtol=1e-4)
    np.testing.assert_allclose(t.dev, [37.244, 74.818], rtol=1e-4)


def test_phase_and_freq_inputs_agree(nbs1000: np.ndarray) -> None:
    x = np.concatenate([[0.0], np.cumsum(nbs1000)])
    for stat in ("oadev", "mdev", "totdev", "mtotdev", "htotdev", "theo1"):
        a = st.compute(stat, nbs1000, 1.0, "freq", alpha=0, bias_correction=False)
        b = st.compute(stat, x, 1.0, "phase", alpha=0, bias_correction=False)
        np.testing.assert_allclose(a.dev, b.dev, rtol=1e-9)


def test_allantools_independent_estimator() -> None:
    """allantools 2024.6 as an independent implementation, white FM, non-unit rate."""
    at = pytest.importorskip("allantools")
    rng = np.random.default_rng(7)
    y = rng.standard_normal(600)  # allantools' total statistics are slow pure Python
    rate = 100.0
    checks = {
        "adev": at.adev,
        "oadev": at.oadev,
        "mdev": at.mdev,
        "tdev": at.tdev,
        "hdev": at.hdev,
        "ohdev": at.ohdev,
        "totdev": at.totdev,
        "mtotdev": at.mtotdev,
        "ttotdev": at.ttotdev,
        "htotdev": at.htotdev,
    }
    for stat, fn in checks.items():
        ours = st.compute(stat, y, rate, "freq", alpha=0, bias_correction=False)
        _, dev, _, ns = fn(y, rate=rate, data_type="freq", taus=ours.tau_s)
        np.testing.assert_allclose(ours.dev, dev, rtol=1e-9, err_msg=stat)
        np.testing.assert_array_equal(ours.n, ns.astype(np.int64), err_msg=stat)
    ours = st.theo1(y, rate, "freq", alpha=0, bias_correction=False)
    _, dev, _, _ = at.theo1(y, rate=rate, data_type="freq", taus=ours.m / rate)
    np.testing.assert_allclose(ours.dev, dev, rtol=1e-9)


def test_gaps_are_skipped_and_counted(nbs1000: np.ndarray) -> None:
    y = nbs1000.copy()
    y[500] = np.nan
    # a term touches the gap if its frequency samples include y[500]: OAVAR uses 2m samples,
    # OHVAR 3m, MVAR 3m - 1 (phase points j..j+3m-1)
    for stat, span in (("oadev", 2), ("mdev", 3), ("ohdev", 3), ("adev", 2), ("totdev", 2)):
        res = st.compute(stat, y, 1.0, "freq", [1.0, 4.0], alpha=0, bias_correction=False)
        full = st.compute(stat, nbs1000, 1.0, "freq", [1.0, 4.0], alpha=0, bias_correction=False)
        np.testing.assert_array_equal(res.n + res.gaps, full.n)
        if stat in ("oadev", "mdev", "ohdev"):
            short = 1 if stat == "mdev" else 0
            np.testing.assert_array_equal(res.gaps, [span * 1 - short, span * 4 - short])
        assert np.all(res.gaps > 0) and np.all(np.isfinite(res.dev))
    # direct check of OAVAR at m=1 with the gapped terms dropped by hand
    x = np.concatenate([[0.0], np.cumsum(nbs1000 - nbs1000.mean())])
    d = x[2:] - 2 * x[1:-1] + x[:-2]
    keep = np.ones(d.size, bool)
    keep[[499, 500]] = False
    expect = np.sqrt(np.mean(d[keep] ** 2) / 2)
    got = st.oadev(y, 1.0, "freq", afs=[1], alpha=0).dev[0]
    assert got == pytest.approx(expect, rel=1e-12)


def test_phase_gap_and_theo1_gap() -> None:
    rng = np.random.default_rng(3)
    x = np.cumsum(rng.standard_normal(400))
    xg = x.copy()
    xg[200] = np.nan
    r = st.theo1(xg, 1.0, "phase", afs=[10], alpha=0, bias_correction=False)
    assert r.gaps[0] == 11 * 5  # rows i = 190..200 touch point 200, m/2 terms each
    r2 = st.mtotdev(xg, 1.0, "phase", afs=[2], alpha=0, bias_correction=False)
    assert r2.gaps[0] == 6 and np.isfinite(r2.dev[0])


def test_drift_removal_reports_drift() -> None:
    rng = np.random.default_rng(11)
    t = np.arange(20000) / 10.0
    y = 0.01 * rng.standard_normal(t.size) + 3e-4 * t
    res = st.oadev(y, 10.0, "freq", remove_drift=True, alpha=0)
    assert res.drift == pytest.approx(3e-4, rel=1e-2)
    clean = st.oadev(y - 3e-4 * t, 10.0, "freq", alpha=0)
    short = res.m <= 256  # at the longest taus the fitted and true lines differ visibly
    np.testing.assert_allclose(res.dev[short], clean.dev[short], rtol=1e-2)
    x = np.cumsum(y) / 10.0
    resp = st.oadev(x, 10.0, "phase", remove_drift=True, alpha=0)
    assert resp.drift == pytest.approx(3e-4, rel=1e-2)


def test_tau_selection_and_stop_ratios() -> None:
    assert averaging_factors("oadev", 1000, "octave", 1.0).tolist() == [1, 2, 4, 8, 16, 32, 64, 128]
    assert averaging_factors("totdev", 1000, "octave", 1.0)[-1] == 256
    assert averaging_factors("adev", 19982, "octave", 1.0)[-1] == 2048
    assert averaging_factors("mtotdev", 1000, "decade", 1.0).tolist() == [
        1,
        2,
        4,
        10,
        20,
        40,
        100,
        200,
    ]
    assert averaging_factors("mtotdev", 1000, "all", 1.0)[-1] == 333
    assert averaging_factors("theo1", 1000, "all", 1.0)[[0, -1]].tolist() == [10, 998]
    assert averaging_factors("oadev", 1000, 5, 1.0).tolist()[:4] == [1, 2, 3, 4]
    assert averaging_factors("oadev", 1000, [0.5, 3.2, 10.0], 0.5).tolist() == [1, 6, 20]
    with pytest.raises(StatsError, match="taus"):
        averaging_factors("oadev", 1000, "weekly", 1.0)


def test_bad_input_raises() -> None:
    with pytest.raises(StatsError, match="data_type"):
        st.oadev(np.ones(100), 1.0, "volts")
    with pytest.raises(StatsError, match="rate"):
        st.oadev(np.ones(100), -1.0)
    with pytest.raises(StatsError, match="unknown statistic"):
        st.compute("bogus", np.ones(100))


def test_result_to_dict_is_json_ready(nbs1000: np.ndarray) -> None:
    import json

    d = st.mdev(nbs1000, 1.0, "freq", alpha=0).to_dict()
    for key in (
        "stat",
        "data_type",
        "rate_hz",
        "tau_s",
        "m",
        "n",
        "var",
        "dev",
        "ci_low",
        "ci_high",
        "alpha",
        "edf",
    ):
        assert key in d
    json.dumps(d)
    assert d["m"][0] == 1 and d["stat"] == "mdev"
