"""Streaming engine == batch statistics, whatever the chunking (issue 4, acceptance 1).

References: allantools 2024.6 (an independent implementation) for gap-free data, and a
direct transcription of the NIST SP 1065 sums (loops over terms, skipping any term whose
window holds a NaN) for data with gaps.
"""

from __future__ import annotations

import subprocess
import sys

import allantools
import numpy as np
import pytest

from imubench.errors import StatsError
from imubench.stats.streaming import StreamingAllan

ALLANTOOLS = {
    "oadev": allantools.oadev, "adev": allantools.adev, "mdev": allantools.mdev,
    "tdev": allantools.tdev, "ohdev": allantools.ohdev, "hdev": allantools.hdev,
}


def feed(eng: StreamingAllan, y: np.ndarray, rng: np.random.Generator, top: int) -> None:
    i = 0
    while i < len(y):
        k = int(np.exp(rng.uniform(0, np.log(top))))
        eng.update(y[i:i + k])
        i += k


def power_law(kind: str, n: int, rng: np.random.Generator) -> np.ndarray:
    w = rng.normal(size=n)
    if kind == "white":
        return 0.3 + 0.01 * w
    if kind == "random_walk":
        return 0.3 + 1e-4 * np.cumsum(w)
    f = np.fft.rfftfreq(n)
    spec = np.fft.rfft(w)
    spec[1:] /= np.sqrt(f[1:])  # flicker: S_y ~ 1/f
    spec[0] = 0
    return 0.3 + 0.01 * np.fft.irfft(spec, n)


@pytest.mark.parametrize("kind", ["white", "flicker", "random_walk"])
def test_equals_allantools_under_random_chunking(kind: str) -> None:
    rng = np.random.default_rng(7)
    y = power_law(kind, 60000, rng)
    rate = 104.0  # not 1 Hz: allantools' realtime classes ignore tau0; this must not
    eng = StreamingAllan(rate, stats=tuple(ALLANTOOLS), max_tau_s=1e9)
    feed(eng, y, rng, 100000)
    snap = eng.snapshot()
    for stat, fn in ALLANTOOLS.items():
        r = snap[stat]  # type: ignore[index]
        taus, dev, _, n = fn(y, rate=rate, data_type="freq", taus=r.tau_s)
        assert len(dev) == len(r), stat
        np.testing.assert_array_equal(r.n, n.astype(np.int64), err_msg=stat)
        np.testing.assert_allclose(r.dev, dev, rtol=1e-10, err_msg=stat)
        np.testing.assert_allclose(r.tau_s, taus, rtol=1e-12)


def test_integer_counts_are_exact_and_scaled() -> None:
    rng = np.random.default_rng(3)
    counts = (rng.normal(size=50000) * 20 + 900).astype(np.int16)
    scale = 8.75e-3
    eng = StreamingAllan(52.0, stats=("oadev", "mdev", "ohdev"), max_tau_s=1e9, scale=scale)
    feed(eng, counts, rng, 5000)
    snap = eng.snapshot()
    y = counts.astype(float) * scale
    for stat in ("oadev", "mdev", "ohdev"):
        r = snap[stat]  # type: ignore[index]
        _, dev, _, _ = ALLANTOOLS[stat](y, rate=52.0, data_type="freq", taus=r.tau_s)
        np.testing.assert_allclose(r.dev, dev, rtol=1e-12, err_msg=stat)


def sp1065_with_gaps(y: np.ndarray, m: int, stat: str) -> tuple[float, int, int]:
    """Direct sums over terms (SP 1065 eq. 11, 14, 17) skipping windows with NaN."""
    x = np.concatenate([[0.0], np.cumsum(np.nan_to_num(y))])
    bad = np.concatenate([[0], np.cumsum(np.isnan(y))])
    total, n, skipped = 0.0, 0, 0
    npts = len(x)
    if stat == "oadev":
        for k in range(npts - 2 * m):
            if bad[k + 2 * m] != bad[k]:
                skipped += 1
                continue
            total += (x[k + 2 * m] - 2 * x[k + m] + x[k]) ** 2
            n += 1
        return total / (2 * m * m * n), n, skipped
    if stat == "ohdev":
        for k in range(npts - 3 * m):
            if bad[k + 3 * m] != bad[k]:
                skipped += 1
                continue
            total += (x[k + 3 * m] - 3 * x[k + 2 * m] + 3 * x[k + m] - x[k]) ** 2
            n += 1
        return total / (6 * m * m * n), n, skipped
    for j in range(npts - 3 * m + 1):  # mdev: phase points j .. j+3m-1
        if bad[j + 3 * m - 1] != bad[j]:
            skipped += 1
            continue
        s = sum(x[i + 2 * m] - 2 * x[i + m] + x[i] for i in range(j, j + m))
        total += s * s
        n += 1
    return total / (2 * m**4 * n), n, skipped


def test_gaps_are_skipped_and_counted_never_bridged() -> None:
    rng = np.random.default_rng(11)
    y = rng.normal(size=3000)
    y[500:503] = np.nan
    y[2000] = np.nan
    eng = StreamingAllan(1.0, taus=[1, 2, 4, 16, 64], stats=("oadev", "mdev", "ohdev"),
                         max_tau_s=64)
    feed(eng, y, rng, 300)
    snap = eng.snapshot()
    for stat in ("oadev", "mdev", "ohdev"):
        r = snap[stat]  # type: ignore[index]
        for i, m in enumerate(r.m):
            var, n, skipped = sp1065_with_gaps(y, int(m), stat)
            assert r.n[i] == n and r.gaps[i] == skipped, (stat, m)
            assert r.var[i] == pytest.approx(var, rel=1e-10), (stat, m)
            assert skipped > 0


def _direct_with_gaps(y: np.ndarray, m: int, stat: str) -> tuple[float, int, int]:
    """:func:`sp1065_with_gaps` vectorised (SP 1065 eqs. 11, 14, 17 on the phase X of
    ``y``; a window holding a NaN is skipped), for records too long for its loops."""
    x = np.concatenate([[0.0], np.cumsum(np.nan_to_num(y))])
    bad = np.concatenate([[0], np.cumsum(np.isnan(y))])
    k = np.arange(len(x) - 2 * m)
    d = x[k + 2 * m] - 2 * x[k + m] + x[k]
    if stat == "oadev":
        ok = bad[k + 2 * m] == bad[k]
        return float(np.sum(d[ok] ** 2)) / (2 * m * m * ok.sum()), int(ok.sum()), int((~ok).sum())
    if stat == "ohdev":
        k = np.arange(len(x) - 3 * m)
        h = x[k + 3 * m] - 3 * x[k + 2 * m] + 3 * x[k + m] - x[k]
        ok = bad[k + 3 * m] == bad[k]
        return float(np.sum(h[ok] ** 2)) / (6 * m * m * ok.sum()), int(ok.sum()), int((~ok).sum())
    c = np.concatenate([[0.0], np.cumsum(d)])
    j = np.arange(len(x) - 3 * m + 1)
    e = c[j + m] - c[j]  # sum of d over j .. j+m-1
    ok = bad[j + 3 * m - 1] == bad[j]
    var = float(np.sum(e[ok] ** 2)) / (2.0 * float(m) ** 4 * ok.sum())
    return var, int(ok.sum()), int((~ok).sum())


def test_long_gaps_fed_whole_are_skipped_and_counted() -> None:
    """Gap stretches fed as whole chunks (an overrun consumer's gap rows), gaps in every
    window of a call (a long tau after a gap, in calls of 65536 rows and, flushed by
    snapshots, of 1000 whose running MDEV sum must move on), and short gaps inside
    chunks: the kernels' O(1) shortcuts for terms that all or none hold a gap give the
    direct sums."""
    rng = np.random.default_rng(13)
    chunk = 1 << 16
    y = rng.normal(size=10 * chunk)
    y[chunk:2 * chunk] = np.nan  # one chunk of gap rows
    y[200_000:200_050] = np.nan
    y[4 * chunk + 100:4 * chunk + 110] = np.nan  # after m = 32768 formed terms
    taus = [1, 3, 16, 64, 1024, 32_768]  # 3 m > a call at the longest
    eng = StreamingAllan(1.0, taus=taus, stats=("oadev", "mdev", "ohdev", "ostdev"),
                         max_tau_s=32_768)
    for lo in range(0, 5 * chunk, chunk):
        eng.update(y[lo:lo + chunk])
    for lo in range(5 * chunk, 5 * chunk + 110_000, 1000):
        eng.update(y[lo:lo + 1000])
        eng.snapshot()  # processes the 1000 rows gathered
    feed(eng, y[5 * chunk + 110_000:], rng, 5000)
    snap = eng.snapshot()
    for stat in ("oadev", "mdev", "ohdev"):
        r = snap[stat]  # type: ignore[index]
        assert list(r.m) == taus, stat
        for i, m in enumerate(r.m):
            var, n, skipped = _direct_with_gaps(y, int(m), stat)
            assert r.n[i] == n and r.gaps[i] == skipped, (stat, m)
            assert r.var[i] == pytest.approx(var, rel=1e-9), (stat, m)
    r = snap["ostdev"]  # type: ignore[index]
    bad = np.concatenate([[0], np.cumsum(np.isnan(y))])
    for i, m in enumerate(r.m):  # terms X_i - X_{i-m}, i = m .. n
        ok = bad[m:] == bad[:-m]
        assert r.n[i] == ok.sum() and r.gaps[i] == (~ok).sum(), m


def test_integer_gap_mask_matches_float_nan() -> None:
    rng = np.random.default_rng(5)
    counts = rng.integers(-500, 500, size=(4000, 2)).astype(np.int16)
    mask = np.zeros(counts.shape, bool)
    mask[1000:1010, 0] = True
    mask[3000, :] = True
    f = counts.astype(float)
    f[mask] = np.nan
    a = StreamingAllan(10.0, stats=("oadev", "mdev", "hdev"))
    b = StreamingAllan(10.0, stats=("oadev", "mdev", "hdev"))
    a.update(counts, gaps=mask)
    b.update(f)
    for ra, rb in zip(a.snapshot(), b.snapshot(), strict=True):  # type: ignore[arg-type]
        for stat in ("oadev", "mdev", "hdev"):
            np.testing.assert_array_equal(ra[stat].n, rb[stat].n)
            np.testing.assert_allclose(ra[stat].var, rb[stat].var, rtol=1e-12)


@pytest.mark.parametrize(("memory", "rtol"), [("exact", 1e-12), ("bounded", 1e-9)])
def test_save_and_restore_resumes(memory: str, rtol: float) -> None:
    """A restored engine continues as if never stopped (bounded mode: block sums are
    float sums whose rounding depends on where chunks start, hence the looser rtol)."""
    rng = np.random.default_rng(2)
    y = rng.normal(size=(20000, 3))
    kw = {"stats": ("oadev", "mdev", "ostdev"), "memory": memory, "overlap": 8}
    whole = StreamingAllan(100.0, **kw)
    whole.update(y)
    first = StreamingAllan(100.0, **kw)
    first.update(y[:7777])
    resumed = StreamingAllan.load_state(first.save_state())
    resumed.update(y[7777:])
    for ra, rb in zip(whole.snapshot(), resumed.snapshot(), strict=True):  # type: ignore[arg-type]
        for stat in ("oadev", "mdev", "ostdev"):
            np.testing.assert_array_equal(ra[stat].n, rb[stat].n)
            np.testing.assert_allclose(ra[stat].var, rb[stat].var, rtol=rtol)


def test_a_measured_rate_moves_the_taus_not_the_factors() -> None:
    """A chip 3.75 % fast samples at 107.9 Hz for its nominal 104: the taus are reported
    at the measured rate, on the factors chosen at the nominal one, also after a saved
    state is resumed; the deviations are those of batch statistics at 107.9 Hz."""
    from imubench.stats.api import compute

    rng = np.random.default_rng(4)
    y = rng.normal(size=30000)
    eng = StreamingAllan(104.0, taus=[0.1, 1.0, 10.0], stats=("oadev", "tdev"))
    eng.update(y[:10000])
    eng.set_rate(107.9)
    resumed = StreamingAllan.load_state(eng.save_state())
    resumed.update(y[10000:])
    assert resumed.rate_hz == 107.9 and resumed.nominal_rate_hz == 104.0
    for stat in ("oadev", "tdev"):
        got = resumed.snapshot()[stat]  # type: ignore[index]
        np.testing.assert_array_equal(got.m, [10, 104, 1040])
        np.testing.assert_allclose(got.tau_s, got.m / 107.9)
        ref = compute(stat, y, 107.9, "freq", list(got.m / 107.9))
        np.testing.assert_allclose(got.dev, ref.dev, rtol=1e-9)
    with pytest.raises(StatsError, match="not within 10 %"):
        eng.set_rate(208.0)


def test_standard_deviations_match_numpy() -> None:
    rng = np.random.default_rng(9)
    y = rng.normal(size=10000) + 5.0
    eng = StreamingAllan(1.0, taus=[1, 10, 100], stats=("stdev", "ostdev"))
    feed(eng, y, rng, 1000)
    snap = eng.snapshot()
    for i, m in enumerate(snap["stdev"].m):  # type: ignore[index]
        blocks = y[: len(y) // m * m].reshape(-1, m).mean(axis=1)
        assert snap["stdev"].dev[i] == pytest.approx(blocks.std(ddof=1), rel=1e-10)  # type: ignore[index]
        moving = np.convolve(y, np.ones(m) / m, "valid")
        assert snap["ostdev"].dev[i] == pytest.approx(moving.std(ddof=1), rel=1e-10)  # type: ignore[index]


def test_bounded_mode_tracks_exact_mode_closely() -> None:
    rng = np.random.default_rng(4)
    y = rng.normal(size=200000)
    ex = StreamingAllan(100.0, stats=("oadev", "mdev", "ohdev"), memory="exact")
    bd = StreamingAllan(100.0, stats=("oadev", "mdev", "ohdev"), memory="bounded", overlap=16)
    ex.update(y)
    bd.update(y)
    se, sb = ex.snapshot(), bd.snapshot()
    for stat in ("oadev", "mdev", "ohdev"):
        e, b = se[stat], sb[stat]  # type: ignore[index]
        np.testing.assert_array_equal(e.m, b.m)
        small = e.m <= 16
        np.testing.assert_allclose(b.dev[small], e.dev[small], rtol=1e-12)
        # decimated overlap: the same statistic from a subset of its terms
        big = e.m > 16
        assert np.all(np.abs(np.log(b.dev[big] / e.dev[big])) < 0.25)
        assert np.all(b.n[big] < e.n[big])


@pytest.fixture(scope="module")
def adis(reference_dir):  # type: ignore[no-untyped-def]
    data = np.load(reference_dir / "imu-real" / "adis16405" / "adis16405_rep1.npz")
    return data["gyro_counts"][:300000], float(data["gyro_lsb_dps"]), float(data["fs_hz"])


def test_real_recording_adis16405_counts(adis) -> None:  # type: ignore[no-untyped-def]
    counts, lsb, fs = adis
    rng = np.random.default_rng(1)
    eng = StreamingAllan(fs, stats=("oadev", "mdev"), scale=lsb, max_tau_s=1e6)
    feed(eng, counts, rng, 100000)
    snap = eng.snapshot()
    for ch, res in enumerate(snap):  # type: ignore[arg-type]
        y = counts[:, ch] * lsb
        for stat in ("oadev", "mdev"):
            r = res[stat]
            _, dev, _, n = ALLANTOOLS[stat](y, rate=fs, data_type="freq", taus=r.tau_s)
            np.testing.assert_array_equal(r.n, n.astype(np.int64))
            np.testing.assert_allclose(r.dev, dev, rtol=1e-10)


def test_six_channels_together_equal_sp1065_per_channel() -> None:
    """2-D input (the daemon's 6 channels) with gaps at different places per channel:
    every channel equals the direct SP 1065 sums of that channel alone."""
    rng = np.random.default_rng(21)
    y = rng.normal(size=(2000, 6)) + np.arange(6) * 100.0
    for ch in range(6):
        y[rng.integers(0, 2000, ch), ch] = np.nan  # channel 0 has no gap
    eng = StreamingAllan(1.0, taus=[1, 2, 4, 16, 64], stats=("oadev", "mdev", "ohdev"),
                         max_tau_s=64)
    feed(eng, y, rng, 700)
    for ch, snap in enumerate(eng.snapshot()):  # type: ignore[arg-type]
        for stat in ("oadev", "mdev", "ohdev"):
            r = snap[stat]
            for i, m in enumerate(r.m):
                var, n, skipped = sp1065_with_gaps(y[:, ch], int(m), stat)
                assert r.n[i] == n and r.gaps[i] == skipped, (ch, stat, m)
                assert r.var[i] == pytest.approx(var, rel=1e-10), (ch, stat, m)


@pytest.mark.parametrize("memory", ["bounded", "exact"])
def test_no_large_temporaries_per_chunk(memory: str) -> None:
    """After warm-up a 65536 x 6 chunk allocates far less than one float64 copy of it:
    the work arrays are the engine's own (grown to the largest chunk, then reused), so
    the allocator's heap trimming cannot make every chunk page-fault afresh."""
    import tracemalloc

    y = (np.random.default_rng(2).normal(size=(1 << 19, 6)) * 20).astype(np.int16)
    eng = StreamingAllan(6660.0, stats=("oadev", "mdev", "ohdev"), memory=memory,
                         max_tau_s=4096 / 6660.0)
    chunk = 1 << 16
    for i in range(0, 6 * chunk, chunk):
        eng.update(y[i:i + chunk])
    tracemalloc.start()
    try:
        for i in range(6 * chunk, 8 * chunk, chunk):
            eng.update(y[i:i + chunk])
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    one_copy = chunk * 6 * 8
    assert peak < one_copy // 4, f"{peak} bytes allocated at peak (one copy: {one_copy})"


def test_warm_up_compiles_the_gap_kernels_too() -> None:
    """After :func:`warm_up`, an engine fed gaps (a gap inside a chunk, a chunk of gap
    rows) compiles no new kernel variant: a daemon compiled them at its first gap, and
    an outside reviewer's engine at 6660 Hz lost 20 % of a run meanwhile. In a fresh
    interpreter, so that no other test has compiled them first."""
    script = """
import numpy as np
from numba.core.registry import CPUDispatcher
from imubench.stats import _stream_kernels
from imubench.stats.streaming import STREAM_STATS, StreamingAllan, warm_up
warm_up()
kernels = {n: k for n, k in vars(_stream_kernels).items() if isinstance(k, CPUDispatcher)}
before = {n: len(k.signatures) for n, k in kernels.items()}
rng = np.random.default_rng(1)
for memory in ("bounded", "exact"):
    for integer in (True, False):
        eng = StreamingAllan(100.0, taus=10, stats=list(STREAM_STATS), max_tau_s=300.0,
                             memory=memory)
        y = rng.normal(size=(70_000, 2))
        mask = np.zeros(y.shape, bool)
        mask[30_000:30_100] = True
        if integer:
            counts = (y * 100).astype(np.int64)
            eng.update(counts, gaps=mask)
            eng.update(counts, gaps=np.ones(y.shape, bool))
            eng.update(counts)
        else:
            eng.update(np.where(mask, np.nan, y))
            eng.update(np.full(y.shape, np.nan))
            eng.update(y)
        eng.snapshot()
print({n: len(k.signatures) - before[n] for n, k in kernels.items()
       if len(k.signatures) != before[n]})
"""
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         check=True, timeout=600)
    assert out.stdout.strip() == "{}", f"compiled after warm_up: {out.stdout}"
