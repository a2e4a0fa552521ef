"""Streaming snapshot == batch statistic including noise ID, EDF and CIs (issue 4, acc. 1).

The reference is ``imubench.stats.compute(stat, y, rate, data_type="freq")`` (the batch
statistics of issue 3, whose noise identification is Stable32's rule: lag-1 ACF of
Riley & Greenhall, B1 ratio with R(n) below 30 averages), run on the whole series that the
engine received in random chunks of 1 to 1e5 samples. The deviations themselves are also
checked against allantools in tests/test_streaming.py.
"""

from __future__ import annotations

import io
import json

import numpy as np
import pytest

from imubench.errors import StatsError
from imubench.stats.api import compute
from imubench.stats.confidence import strided_edf
from imubench.stats.edf import edf
from imubench.stats.streaming import StreamingAllan

ALL_STATS = ("adev", "oadev", "mdev", "tdev", "hdev", "ohdev", "stdev", "ostdev")


def feed(eng: StreamingAllan, y: np.ndarray, rng: np.random.Generator,
         top: int = 100_000, gaps: np.ndarray | None = None) -> None:
    """Chunks of log-uniform length 1..top."""
    i = 0
    while i < len(y):
        k = int(np.exp(rng.uniform(0, np.log(top))))
        eng.update(y[i:i + k], gaps=None if gaps is None else gaps[i:i + k])
        i += k


def series(kind: str, n: int, rng: np.random.Generator) -> np.ndarray:
    w = rng.normal(size=n + 1)
    if kind == "white":
        return 0.3 + 0.01 * w[:n]
    if kind == "random_walk":
        return 0.3 + 1e-4 * np.cumsum(w[:n])
    if kind == "white_pm":  # differenced white noise: alpha = +2, exercises B1's R(n)
        return 0.3 + 0.01 * np.diff(w)
    f = np.fft.rfftfreq(n)
    spec = np.fft.rfft(w[:n])
    spec[1:] /= np.sqrt(f[1:])
    spec[0] = 0
    return 0.3 + 0.01 * np.fft.irfft(spec, n)


def b1_tie(stat: str, m: np.ndarray, n_samples: int) -> np.ndarray:
    """Taus where the batch's B1 ratio is a tie: with K = 2 averages B1 = 1 identically
    and so is every expected B1(2, mu) boundary, so the noise type is decided by the last
    bit of rounding in either implementation (only stdev/ostdev reach m = N/2)."""
    return (n_samples // m == 2) & (stat in ("stdev", "ostdev"))


def assert_same(r, b, what: str, n_samples: int, dev_rtol: float = 1e-9) -> None:  # type: ignore[no-untyped-def]
    """Everything the batch result carries, term by term (B1 ties: see b1_tie)."""
    np.testing.assert_array_equal(r.m, b.m, err_msg=f"{what} m")
    np.testing.assert_array_equal(r.n, b.n, err_msg=f"{what} n")
    np.testing.assert_array_equal(r.gaps, b.gaps, err_msg=f"{what} gaps")
    np.testing.assert_allclose(r.tau_s, b.tau_s, rtol=1e-14, err_msg=f"{what} tau")
    np.testing.assert_allclose(r.dev, b.dev, rtol=dev_rtol, err_msg=f"{what} dev")
    ok = ~b1_tie(b.stat, b.m, n_samples)
    np.testing.assert_array_equal(r.alpha[ok], b.alpha[ok], err_msg=f"{what} alpha")
    np.testing.assert_array_equal(r.edf[ok], b.edf[ok], err_msg=f"{what} edf")
    # the limits are dev * f(edf, confidence): equal factors, to rounding
    for lim in ("ci_low", "ci_high"):
        ours, ref = getattr(r, lim)[ok], getattr(b, lim)[ok]
        np.testing.assert_allclose(ours / r.dev[ok], ref / b.dev[ok], rtol=1e-12,
                                   err_msg=f"{what} {lim}")
        np.testing.assert_allclose(ours, ref, rtol=dev_rtol, err_msg=f"{what} {lim}")


def batch_dev_rtol(kind: str, stat: str) -> float:
    # compute()'s MVAR on a random walk goes through prefix sums of the phase and keeps
    # ~7 digits (the engine agrees with allantools to 1e-10 there: tests/test_streaming.py)
    return 1e-6 if kind == "random_walk" and stat in ("mdev", "tdev") else 1e-9


@pytest.mark.parametrize("kind", ["white", "flicker", "random_walk", "white_pm"])
def test_snapshot_equals_batch_with_noise_id_and_ci(kind: str) -> None:
    rng = np.random.default_rng(17)
    y = series(kind, 40_000, rng)
    rate = 104.0
    eng = StreamingAllan(rate, stats=ALL_STATS, max_tau_s=1e9)
    feed(eng, y, rng)
    snap = eng.snapshot()
    alphas = set()
    for stat in ALL_STATS:
        b = compute(stat, y, rate, "freq", bias_correction=False)
        assert_same(snap[stat], b, f"{kind} {stat}", y.size,  # type: ignore[index]
                    batch_dev_rtol(kind, stat))
        alphas.update(int(a) for a in b.alpha)
    expected = {"white": 0, "flicker": -1, "random_walk": -2, "white_pm": 2}[kind]
    assert expected in alphas  # the noise is identified, not a fixed alpha


def test_snapshot_equals_batch_at_every_moment() -> None:
    """Snapshots taken mid-stream (B1 region at the long taus) match the batch on the
    prefix seen so far."""
    rng = np.random.default_rng(23)
    y = series("flicker", 30_000, rng)
    eng = StreamingAllan(50.0, taus=4, stats=("oadev", "mdev", "ohdev"), max_tau_s=1e6)
    done = 0
    for stop in (700, 2500, 9000, 30_000):
        feed(eng, y[done:stop], rng, top=3000)
        done = stop
        snap = eng.snapshot()
        for stat in ("oadev", "mdev", "ohdev"):
            b = compute(stat, y[:stop], 50.0, "freq", taus=4, bias_correction=False)
            assert_same(snap[stat], b, f"{stat} after {stop}", stop)  # type: ignore[index]


def test_gaps_noise_id_matches_batch_nan() -> None:
    rng = np.random.default_rng(5)
    counts = (rng.normal(size=(20_000, 2)) * 30).astype(np.int16)
    mask = np.zeros(counts.shape, bool)
    mask[[10, 5000, 5001, 12_000, 19_990], 0] = True
    mask[7000:7100, 1] = True
    eng = StreamingAllan(10.0, stats=("oadev", "mdev", "hdev", "ostdev"), max_tau_s=1e6)
    feed(eng, counts, rng, top=5000, gaps=mask)
    for ch, res in enumerate(eng.snapshot()):  # type: ignore[arg-type]
        y = counts[:, ch].astype(float)
        y[mask[:, ch]] = np.nan
        for stat in ("oadev", "mdev", "hdev", "ostdev"):
            b = compute(stat, y, 10.0, "freq", bias_correction=False)
            assert b.gaps.sum() > 0
            assert_same(res[stat], b, f"ch{ch} {stat}", y.size)


def test_restored_engine_keeps_noise_id() -> None:
    rng = np.random.default_rng(8)
    y = series("random_walk", 20_000, rng)
    kw = {"stats": ("oadev", "ohdev"), "max_tau_s": 1e6}
    whole = StreamingAllan(20.0, **kw)  # type: ignore[arg-type]
    whole.update(y)
    first = StreamingAllan(20.0, **kw)  # type: ignore[arg-type]
    first.update(y[:5003])
    resumed = StreamingAllan.load_state(first.save_state())
    resumed.update(y[5003:])
    for stat in ("oadev", "ohdev"):
        a, b = whole.snapshot()[stat], resumed.snapshot()[stat]  # type: ignore[index]
        np.testing.assert_array_equal(a.alpha, b.alpha)
        np.testing.assert_array_equal(a.edf, b.edf)
        np.testing.assert_allclose(a.ci_high, b.ci_high, rtol=1e-12)


def test_restored_engine_keeps_the_gap_free_runs_of_the_edf() -> None:
    """Gaps on both sides of a save/restore: the restored engine's EDF (which sums the
    gap-free runs' EDFs) equals the batch result's on the whole series; a state saved
    without the runs (before they were kept) still loads."""
    rng = np.random.default_rng(9)
    y = series("white", 20_000, rng)
    y[[700, 4_000, 4_001, 15_000]] = np.nan
    first = StreamingAllan(1.0, stats=("oadev", "mdev"), max_tau_s=1e6)
    first.update(y[:5_003])
    state = first.save_state()
    resumed = StreamingAllan.load_state(state)
    resumed.update(y[5_003:])
    for stat in ("oadev", "mdev"):
        b = compute(stat, y, 1.0, "freq", bias_correction=False)
        r = resumed.snapshot()[stat]  # type: ignore[index]
        np.testing.assert_array_equal(r.edf, b.edf, err_msg=stat)
    z = {k: v for k, v in np.load(io.BytesIO(state)).items()
         if k != "open_run" and not k.startswith("runs/")}
    buf = io.BytesIO()
    np.savez(buf, **z)
    StreamingAllan.load_state(buf.getvalue()).update(y[5_003:])


def test_bounded_mode_alpha_exact_and_edf_of_strided_estimator() -> None:
    """Bounded mode: the noise-ID series (non-overlapping m-averages) is kept whole, so
    alpha equals the batch's; the EDF is Greenhall's for the strided estimator."""
    rng = np.random.default_rng(3)
    y = series("white", 60_000, rng)
    overlap = 8
    eng = StreamingAllan(1.0, stats=("oadev", "mdev", "ohdev", "adev"), max_tau_s=1e6,
                         memory="bounded", overlap=overlap)
    feed(eng, y, rng)
    snap = eng.snapshot()
    n_phase = y.size + 1
    for stat in ("oadev", "mdev", "ohdev", "adev"):
        r = snap[stat]  # type: ignore[index]
        b = compute(stat, y, 1.0, "freq", bias_correction=False)
        np.testing.assert_array_equal(r.alpha, b.alpha, err_msg=stat)
        for i, m in enumerate(r.m):
            m = int(m)
            stride = m // overlap if (m > overlap and stat != "adev") else 1
            assert r.edf[i] == strided_edf(stat, int(r.alpha[i]), m, n_phase, stride)
            if stride == 1:
                assert r.edf[i] == b.edf[i]
            else:  # fewer terms: the EDF may only drop, and for white FM barely
                assert r.edf[i] <= b.edf[i] * (1 + 1e-2)
                assert r.n[i] < b.n[i]


def test_strided_edf_term_count_matches_engine() -> None:
    """The strided EDF is evaluated for M = 1 + floor((N - L) / s) terms; the bounded
    engine forms exactly that many MVAR and OAVAR terms."""
    y = np.random.default_rng(0).normal(size=50_000)
    eng = StreamingAllan(1.0, taus=[256, 1024], stats=("oadev", "mdev"), alpha=0,
                         memory="bounded", overlap=16)
    eng.update(y)
    snap = eng.snapshot()
    n_phase = y.size + 1
    for stat, d, modified in (("oadev", 2, False), ("mdev", 2, True)):
        r = snap[stat]  # type: ignore[index]
        for m, n in zip(r.m, r.n, strict=True):
            s = int(m) // 16
            big_l = (d + 1) * m if modified else 1 + d * m
            assert n == 1 + (n_phase - big_l) // s, (stat, m)


def test_strided_edf_reduces_to_edf_and_rejects_bad_stride() -> None:
    assert strided_edf("oadev", 0, 64, 10_001, 1) == edf("oadev", 0, 64, 10_001)
    # S = m / s large: Greenhall's asymptotic form, no loss against full overlap
    full = edf("mdev", -2, 4096, 200_001)
    assert strided_edf("mdev", -2, 4096, 200_001, 16) == pytest.approx(full, rel=2e-2)
    # S = 1 (stride m) is the non-overlapping estimator
    assert strided_edf("oadev", 0, 64, 10_001, 64) == pytest.approx(
        edf("adev", 0, 64, 10_001), rel=1e-12)
    with pytest.raises(StatsError, match="stride 3"):
        strided_edf("oadev", 0, 64, 10_001, 3)
    with pytest.raises(StatsError, match="'adev'"):
        strided_edf("adev", 0, 64, 10_001, 2)


def test_bad_input_is_named() -> None:
    eng = StreamingAllan(10.0)
    with pytest.raises(StatsError, match=r"shape \(2, 2, 2\)"):
        eng.update(np.zeros((2, 2, 2)))
    with pytest.raises(StatsError, match="snapshot\\(\\) before any update"):
        eng.snapshot()
    with pytest.raises(StatsError, match="not a saved StreamingAllan state"):
        StreamingAllan.load_state(b"garbage")
    eng.update(np.zeros((5, 2)))
    with pytest.raises(StatsError, match="3 channels, engine has 2"):
        eng.update(np.zeros((5, 3)))
    with pytest.raises(StatsError, match="mixing integer and float"):
        eng.update(np.zeros((5, 2), np.int16))
    # a state saved by another layout version is refused with a clear message
    z = dict(np.load(io.BytesIO(eng.save_state())))
    meta = json.loads(bytes(z["__meta__"]).decode())
    meta["format"] = 1
    z["__meta__"] = np.frombuffer(json.dumps(meta).encode(), np.uint8)
    buf = io.BytesIO()
    np.savez(buf, **z)
    with pytest.raises(StatsError, match="state format 1 is not 2"):
        StreamingAllan.load_state(buf.getvalue())


# -- the real recordings (imu-real, rate data at rates other than 1 Hz) -------------------
def _recordings(reference_dir, full: bool):  # type: ignore[no-untyped-def]
    base = reference_dir / "imu-real"
    out = []
    z = np.load(base / "adis16405" / "adis16405_rep1.npz")
    counts = z["gyro_counts"] if full else z["gyro_counts"][:300_000]
    out.append(("adis16405 gyro counts", counts, float(z["gyro_lsb_dps"]), float(z["fs_hz"])))
    z = np.load(base / "samsung-s5-static" / "samsung_galaxy_s5_static.npz")
    out.append(("samsung-s5 gyro", z["gyro_measured_rad_s"], None, float(z["fs_hz"])))
    z = np.load(base / "mtig-contaminated" / "mtig_gyro_x_contaminated.npz")
    gx = z["gyro_x"] if full else z["gyro_x"][:200_000]
    out.append(("mtig gyro x", gx, None, float(z["fs_hz"])))
    return out


def _check_recordings(reference_dir, stats: tuple[str, ...], full: bool) -> None:  # type: ignore[no-untyped-def]
    rng = np.random.default_rng(42)
    for name, data, lsb, fs in _recordings(reference_dir, full):
        assert fs != 1.0
        eng = StreamingAllan(fs, stats=stats, scale=lsb, max_tau_s=1e9)
        feed(eng, data, rng)
        snap = eng.snapshot()
        per_ch = [snap] if data.ndim == 1 else snap
        for ch, res in enumerate(per_ch):  # type: ignore[arg-type]
            y = (data if data.ndim == 1 else data[:, ch]).astype(float)
            if lsb is not None:
                y = y * lsb
            for stat in stats:
                b = compute(stat, y, fs, "freq", bias_correction=False)
                assert_same(res[stat], b, f"{name} ch{ch} {stat}", y.size)  # type: ignore[index]


def test_real_recordings_equal_batch(reference_dir) -> None:  # type: ignore[no-untyped-def]
    _check_recordings(reference_dir, ("oadev", "mdev", "ohdev"), full=False)


@pytest.mark.slow
def test_real_recordings_equal_batch_full_all_stats(reference_dir) -> None:  # type: ignore[no-untyped-def]
    _check_recordings(reference_dir, ALL_STATS, full=True)


def test_gaps_noise_id_over_many_processed_chunks() -> None:
    """Integer counts with gap masks over several processed chunks (>= 65536 rows each),
    so that the noise-ID values of long m (fewer than 256 per chunk) wait across chunks
    before they are summed: the result still equals the batch on the NaN-marked series."""
    rng = np.random.default_rng(5)
    n = 120_000
    base = rng.normal(size=(n, 3)) * 20 + np.cumsum(rng.normal(size=(n, 3)), axis=0) * 0.05
    mask = np.zeros((n, 3), bool)
    for ch in range(3):
        for _ in range(ch * 3):
            i = rng.integers(0, n - 50)
            mask[i:i + rng.integers(1, 40), ch] = True
    counts = base.astype(np.int32)
    eng = StreamingAllan(100.0, stats=("oadev", "ohdev"), max_tau_s=8192 / 100)
    feed(eng, counts, rng, top=30_000, gaps=mask)
    for ch, res in enumerate(eng.snapshot()):  # type: ignore[arg-type]
        y = counts[:, ch].astype(float)
        y[mask[:, ch]] = np.nan
        for stat in ("oadev", "ohdev"):
            b = compute(stat, y, 100.0, "freq", bias_correction=False)
            keep = np.isin(b.m, res[stat].m)
            np.testing.assert_array_equal(res[stat].m, b.m[keep])
            np.testing.assert_array_equal(res[stat].alpha, b.alpha[keep], err_msg=f"ch{ch}")
            np.testing.assert_allclose(res[stat].dev, b.dev[keep], rtol=1e-10)
            np.testing.assert_array_equal(res[stat].n, b.n[keep])
