"""Streaming running-sum Allan engine: bounded state, exact, any chunking.

Every new rate sample ``y_p`` extends the phase ``X_p = X_{p-1} + (y_p - y_ref)``
(``X_0 = 0``; phase in units of y·tau0/tau0, i.e. the cumulative sum of the rate; the
constant ``y_ref``, the channel's first sample, cancels in every difference below and
keeps ``X`` small). Each new phase value completes one term per averaging factor ``m``
and statistic, which is added to running sums (the application note's optimised
cumulative-sum scheme); nothing grows with the length of the recording.

Terms (NIST SP 1065 definitions written on the cumulative rate sum X, tau = m tau0):

* OAVAR (SP 1065 eq. 11): ``D_p = X_p - 2X_{p-m} + X_{p-2m}``, ``var = <D^2> / (2 m^2)``;
  AVAR (eq. 10) keeps the terms with ``p % m == 0``.
* OHVAR (SP 1065 eq. 17, 1/6 normalisation): ``H_p = X_p - 3X_{p-m} + 3X_{p-2m} -
  X_{p-3m}``, ``var = <H^2> / (6 m^2)``; HVAR keeps ``p % m == 0``.
* MVAR (SP 1065 eq. 14): ``E_p = sum_{r=0}^{m-1} D_{p-r}`` (a moving sum of the OAVAR
  terms: differences of a running sum of D local to each chunk for m <= 256, of one kept
  across chunks beyond), ``var = <E^2> / (2 m^4)``; TVAR (eq. 15) = ``tau^2 / 3 * MVAR``.
  OAVAR, HVAR/OHVAR (``H_p = D_p - D_{p-m}``) and, at stride 1, MVAR share one D array.
* STDVAR / OSTDVAR: ``A_p = X_p - X_{p-m}`` (m times the m-sample mean), sample variance
  of ``A / m`` over non-overlapping (``p % m == 0``) or all positions.

Integer input (raw int16 counts) accumulates in int64 (two's-complement wrap-around is
harmless: every term is a difference whose true value fits in int64), so the terms are
exact; squares are summed in float64 per chunk (numpy's pairwise summation) and the
chunk sums are added with Neumaier compensation. Float input uses the same compensated
sums. NaN samples are gaps: the cumulative gap count ``G_p`` tells whether a term's
window holds one; such terms are skipped and counted, never bridged.

Memory modes:

* ``exact``: every overlapping term, needing the last ``3 m_max + 1`` phase values per
  channel (8 bytes each, plus the per-m moving-sum histories).
* ``bounded``: for ``m > overlap`` the overlapping estimators (OAVAR, MVAR, OHVAR,
  OSTDVAR) use only the terms at positions that are multiples of a stride
  ``s = m / overlap`` (power of two), from phase values and block sums decimated by ``s``,
  so the state per averaging factor is about ``3 * overlap`` numbers whatever ``m``.
  Non-overlapping AVAR, HVAR and STDVAR are unchanged (their terms lie on multiples of m).
  The EDF lost against full overlap is measured in ``bench/bench_streaming.py`` and
  documented in ``docs/streaming.md``. The MVAR gap test is conservative for ``s > 1``
  (it also rejects a term when the sample just after its window is a gap).

``snapshot()`` returns, for 1-D input, a mapping ``stat -> StatResult`` (the batch result
type), and for 2-D input a list with one such mapping per channel. With ``memory="exact"``
it equals the batch statistic ``compute(stat, y, rate_hz, "freq", taus)`` on everything
seen so far: same taus, term counts, noise types (``streaming_noise``: the batch's lag-1
ACF / B1 rule from running sums per m), EDF and confidence limits. In bounded mode alpha
is still the batch's (the noise-ID series, non-overlapping m-averages, is kept whole) and
the EDF is Greenhall's for the strided estimator (``confidence.strided_edf``).

Chunks shorter than ``_INBOX_ROWS`` are gathered before they are processed (the cost per
processed chunk is mostly per-m Python work); ``snapshot()`` and ``save_state()`` flush
them, so results always include every sample given.
"""

from __future__ import annotations

import contextlib
import io
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from imubench.errors import StatsError
from imubench.stats.edf import canonical_stat
from imubench.stats.streaming_noise import (
    LAG1_MIN_POINTS,
    RunningNoiseSums,
    concat_f,
    dmax_for,
)
from imubench.stats.taus import averaging_factors

# statistic (deviation name) -> (variance family, overlapping?)
STREAM_STATS: dict[str, tuple[str, bool]] = {
    "adev": ("avar", False),
    "oadev": ("avar", True),
    "mdev": ("mvar", True),
    "tdev": ("mvar", True),
    "hdev": ("hvar", False),
    "ohdev": ("hvar", True),
    "stdev": ("std", False),
    "ostdev": ("std", True),
}
_VAR_NAMES = {
    "avar": "adev",
    "oavar": "oadev",
    "mvar": "mdev",
    "tvar": "tdev",
    "hvar": "hdev",
    "ohvar": "ohdev",
    "stdvar": "stdev",
    "ostdvar": "ostdev",
}
#: Version of the save_state() layout (2: noise-ID sums, gap histories kept lazily).
STATE_FORMAT = 2
# update() chunks shorter than this are gathered before they are processed
_INBOX_ROWS = 1 << 16
# noise-ID phase values are added to the sums in batches of at least this many rows
_NOISE_BATCH = 256
# MVAR at q = m / stride <= this: terms from a chunk-local running sum (no history of
# its own); above it a running sum kept across chunks (re-summing q terms would dominate)
_LOCAL_MVAR_Q = 256
# term window length in units of m (phase values spanned minus one)
_SPAN = {"avar": 2, "hvar": 3, "mvar": 3, "std": 1}


def _canonical(stat: str) -> str:
    name = _VAR_NAMES.get(stat, stat)
    if name not in STREAM_STATS:
        raise StatsError(
            f"streaming statistic {stat!r} is not supported; choose from {', '.join(STREAM_STATS)}"
        )
    return name


class _Accumulator:
    """Running sums for one (statistic, m): term count, terms skipped for gaps, and
    Σv² (Neumaier-compensated) -- or, for the standard variances, the running mean in
    ``sum1`` and the sum of squared deviations in ``sum2``."""

    __slots__ = ("comp", "n", "skipped", "sum1", "sum2")

    def __init__(self, nch: int) -> None:
        self.n = np.zeros(nch, np.int64)
        self.skipped = np.zeros(nch, np.int64)
        self.sum2 = np.zeros(nch)
        self.comp = np.zeros(nch)
        self.sum1 = np.zeros(nch)

    @staticmethod
    def _neumaier(total: np.ndarray, comp: np.ndarray, add: np.ndarray) -> None:
        t = total + add
        big = np.abs(total) >= np.abs(add)
        comp += np.where(big, (total - t) + add, (add - t) + total)
        total[...] = t

    def add(self, v: np.ndarray, valid: np.ndarray | None, first_moment: bool) -> None:
        """Add terms ``v`` (k, nch); ``valid`` masks terms free of gaps (None = all)."""
        if v.shape[0] == 0:
            return
        vf = v.astype(np.float64, copy=False)
        if valid is None:
            self.n += v.shape[0]
        else:
            vf = np.where(valid, vf, 0.0)
            cnt = np.count_nonzero(valid, axis=0)
            self.n += cnt
            self.skipped += v.shape[0] - cnt
        if not first_moment:
            self._neumaier(self.sum2, self.comp, np.einsum("ij,ij->j", vf, vf))
            return
        # mean and sum of squared deviations, merged per chunk (Chan, Golub & LeVeque
        # 1979): stable when the mean is large against the spread (a gyro's bias).
        n_old = self.n - (v.shape[0] if valid is None else np.count_nonzero(valid, axis=0))
        n_b = self.n - n_old
        with np.errstate(invalid="ignore", divide="ignore"):
            mean_b = np.where(n_b > 0, np.einsum("ij->j", vf) / n_b, 0.0)
            dev = vf - mean_b
            if valid is not None:
                dev = np.where(valid, dev, 0.0)
            m2_b = np.einsum("ij,ij->j", dev, dev)
            delta = mean_b - self.sum1
            frac = np.where(self.n > 0, n_b / self.n, 0.0)
            self.sum1 = self.sum1 + delta * frac  # running mean
            self._neumaier(self.sum2, self.comp, m2_b + delta * delta * n_old * frac)

    def state(self) -> dict[str, np.ndarray]:
        return {k: getattr(self, k) for k in self.__slots__}


class _Seq:
    """Append-only history of the last ``keep`` rows of a 2-D sequence, as a linear
    buffer that is compacted when full (amortised O(1) per row, contiguous slices)."""

    def __init__(self, keep: int, nch: int, dtype: np.dtype) -> None:
        self.keep = keep
        self.buf = np.zeros((min(2 * keep, 1024), nch), dtype, order="F")
        self.start = 0  # absolute index of buf[0]
        self.stop = 0  # absolute index one past the last row

    def append(self, rows: np.ndarray) -> None:
        k = rows.shape[0]
        fill = self.stop - self.start
        if fill + k > self.buf.shape[0]:
            tail = min(fill, self.keep)
            need = tail + k
            if need > self.buf.shape[0]:  # grow (allocation follows the chunk size seen)
                size = need + min(self.keep, need)  # amortised: room for >= one more chunk
                grown = np.zeros((max(size, 1024), self.buf.shape[1]), self.buf.dtype,
                                 order="F")
                grown[:tail] = self.buf[fill - tail : fill]
                self.buf = grown
            else:  # compact: keep only the last `keep` rows
                self.buf[:tail] = self.buf[fill - tail : fill]
            self.start = self.stop - tail
            fill = tail
        self.buf[fill : fill + k] = rows
        self.stop += k

    def zeros_like(self, dtype: np.dtype) -> _Seq:
        """A sequence holding zeros at the same absolute indices as this one."""
        z = _Seq(self.keep, self.buf.shape[1], dtype)
        z.buf = np.zeros(self.buf.shape, dtype)
        z.start, z.stop = self.start, self.stop
        return z

    def view(self, lo: int, hi: int) -> np.ndarray:
        """Rows with absolute indices lo..hi-1 (must still be held)."""
        if lo < self.start:
            raise AssertionError(f"history too short: need {lo}, hold from {self.start}")
        return self.buf[lo - self.start : hi - self.start]


@dataclass
class _Level:
    """Sequences decimated by ``stride`` (1 in exact mode)."""

    stride: int
    x_at: _Seq  # X at positions b*stride
    g_at: _Seq  # G at positions b*stride
    bs: _Seq | None  # block sums of X over [b*s, b*s+s-1]
    g_end: _Seq | None  # G at positions b*s+s-1
    part_sum: np.ndarray  # partial block sum being built
    ms: list[int]
    cd: dict[int, _Seq]  # per-m running sum of block second differences (MVAR)
    bs_live: bool = True  # block sums still needed (MVAR stats, or young noise-ID m)


class StreamingAllan:
    """Running-sum Allan-family engine for one or several channels of rate data.

    Args:
        rate_hz: sample rate of the input (tau0 = 1 / rate_hz).
        taus: ``"octave"``, ``"decade"``, ``int`` (points per decade) or tau values (s).
        stats: deviation names from :data:`STREAM_STATS` (variance names accepted).
        max_tau_s: largest tau kept, seconds (default: 2**20 samples, i.e. 2**20 tau0).
        memory: ``"exact"`` or ``"bounded"`` (see module docstring).
        overlap: bounded mode's overlap factor m / stride.
        scale: multiply the input by this per channel (e.g. dps per LSB for raw counts).
        confidence: CI confidence of the snapshots.
        alpha: fix the noise type for the CIs (None: identify from the running sums).
    """

    def __init__(
        self,
        rate_hz: float,
        taus: str | int | Sequence[float] = "octave",
        stats: Sequence[str] = ("oadev",),
        max_tau_s: float | None = None,
        memory: str = "exact",
        *,
        overlap: int = 64,
        scale: float | Sequence[float] | None = None,
        confidence: float = 0.683,
        alpha: int | None = None,
    ) -> None:
        if rate_hz <= 0:
            raise StatsError(f"rate_hz must be positive, got {rate_hz}")
        if memory not in ("exact", "bounded"):
            raise StatsError(f"memory must be 'exact' or 'bounded', got {memory!r}")
        self.rate_hz = float(rate_hz)
        self.tau0_s = 1.0 / self.rate_hz
        self.stats = tuple(dict.fromkeys(_canonical(s) for s in stats))
        self.taus = taus
        self.memory = memory
        self.overlap = int(overlap)
        self.confidence = confidence
        self.alpha = alpha
        # largest m; a tau given as m / rate_hz must not lose m to rounding
        self.max_m = int(np.floor(max_tau_s * self.rate_hz * (1 + 1e-12))) if max_tau_s else 2**20
        if self.max_m < 1:
            raise StatsError(f"max_tau_s={max_tau_s} is shorter than one sample period")
        ms: set[int] = set()
        for stat in self.stats:
            ms.update(
                int(m)
                for m in averaging_factors(
                    stat, 10**15, taus, self.tau0_s, max_af_override=self.max_m
                )
            )
        if not ms:
            raise StatsError(f"no averaging factor <= {self.max_m} from taus={taus!r}")
        self.ms = sorted(ms)
        self._scale_arg = scale
        self._nch: int | None = None
        self._one_d = True
        self._int: bool | None = None

    # -- set-up on first data -----------------------------------------------------
    def _stride(self, m: int) -> int:
        if self.memory == "exact" or m <= self.overlap:
            return 1
        s = 1 << int(np.floor(np.log2(m / self.overlap)))
        return int(min(s, m & -m))

    def _setup(self, chunk: np.ndarray) -> None:
        nch = chunk.shape[1]
        self._nch = nch
        self._int = chunk.dtype.kind in "iu"
        dtype = np.dtype(np.int64 if self._int else np.float64)
        self._dtype = dtype
        if self._scale_arg is None:
            self.scale = np.ones(nch)
        else:
            self.scale = np.broadcast_to(np.asarray(self._scale_arg, float), (nch,)).copy()
        self._n_proc = 0  # samples processed (phase positions 1.._n_proc exist)
        self._inbox: list[tuple[np.ndarray, np.ndarray | None]] = []
        self._inbox_rows = 0
        self._gaps_seen = False
        self.n_gaps = np.zeros(nch, np.int64)
        self._ref = np.zeros(nch, dtype)
        self._ref_set = np.zeros(nch, bool)
        self._x_last = np.zeros((1, nch), dtype)
        self._g_last = np.zeros((1, nch), np.int64)
        self._mvar_stats = "mvar" in {STREAM_STATS[s][0] for s in self.stats}
        need_bs = self._mvar_stats or self.alpha is None
        self.levels: dict[int, _Level] = {}
        for m in self.ms:
            s = self._stride(m)
            lv = self.levels.get(s)
            if lv is None:
                lv = _Level(s, None, None, None, None, np.zeros(nch, dtype), [], {})  # type: ignore[arg-type]
                self.levels[s] = lv
            lv.ms.append(m)
        for s, lv in self.levels.items():
            qmax = max(lv.ms) // s
            keep = 3 * qmax + 2
            # the gap counts G (g_at, g_end) are only kept once a gap has been seen;
            # before that they are all zero (see _first_gap)
            lv.x_at = _Seq(keep, nch, dtype)
            lv.x_at.append(np.zeros((1, nch), dtype))  # X_0 = 0 at position 0
            lv.g_at = lv.x_at.zeros_like(np.dtype(np.int64))
            if need_bs:
                if s == 1:  # blocks of one sample: the block sums are X itself
                    lv.bs, lv.g_end = lv.x_at, lv.g_at
                else:
                    lv.bs = _Seq(keep, nch, dtype)
                    lv.g_end = lv.bs.zeros_like(np.dtype(np.int64))
                for m in lv.ms:
                    if m // s > _LOCAL_MVAR_Q:
                        lv.cd[m] = _Seq(m // s + 2, nch, dtype)
        self.acc: dict[tuple[str, int], _Accumulator] = {
            (stat, m): _Accumulator(nch) for stat in self.stats for m in self.ms
        }
        # noise identification (alpha=None): running lag-1/B1 sums per m, and while m can
        # still fall back to B1 (< 30 averages) an MVAR with the noise-ID gap rule
        self._noise: dict[int, RunningNoiseSums] = {}
        self._nid_young: dict[int, bool] = {}
        self._noise_pending: dict[int, list[tuple[np.ndarray, np.ndarray | None]]] = {
            m: [] for m in self.ms}
        if self.alpha is None:
            dmax = [dmax_for(canonical_stat(st)) for st in self.stats]
            for m in self.ms:
                self._noise[m] = RunningNoiseSums(m, nch, orders=max(dmax) + 1)
                self._nid_young[m] = True
                self.acc[("_nmvar", m)] = _Accumulator(nch)

    # -- update ---------------------------------------------------------------------
    def update(self, chunk: np.ndarray | Sequence[float], gaps: np.ndarray | None = None) -> None:
        """Add samples: 1-D (one channel) or 2-D (samples x channels).

        NaN samples are gaps. For integer input (which has no NaN) pass ``gaps``, a
        boolean mask of the chunk's shape (or one flag per sample), True where a sample
        was lost; the values there are ignored.
        """
        arr = np.asarray(chunk)
        one_d = arr.ndim == 1
        if one_d:
            arr = arr[:, None]
        mask = None
        if gaps is not None:
            mask = np.asarray(gaps, bool)
            if mask.ndim == 1:
                mask = mask[:, None]
            mask = np.broadcast_to(mask, arr.shape)
        if arr.ndim != 2:
            raise StatsError(f"update() takes 1-D or 2-D data, got shape {arr.shape}")
        if self._nch is None:
            if arr.dtype.kind not in "iuf":
                raise StatsError(f"update() takes numbers, got dtype {arr.dtype}")
            self._one_d = one_d
            self._setup(arr)
        if arr.shape[1] != self._nch:
            raise StatsError(f"chunk has {arr.shape[1]} channels, engine has {self._nch}")
        if (arr.dtype.kind in "iu") != self._int:
            raise StatsError("mixing integer and float chunks in one engine is not allowed")
        if arr.shape[0] < _INBOX_ROWS:
            # small chunks (a FIFO read) are gathered: the cost per processed chunk is
            # mostly per-m Python work, whatever its length; snapshot() flushes them
            self._inbox.append((arr.copy(), None if mask is None else mask.copy()))
            self._inbox_rows += arr.shape[0]
            if self._inbox_rows >= _INBOX_ROWS:
                self._flush_inbox()
            return
        self._flush_inbox()
        self._process(arr, mask)

    @property
    def n_samples(self) -> int:
        """Samples (rows) given to update() so far."""
        return self._n_proc + self._inbox_rows if self._nch is not None else 0

    def _flush_inbox(self) -> None:
        if not self._inbox:
            return
        arrs = [a for a, _ in self._inbox]
        if all(mk is None for _, mk in self._inbox):
            mask = None
        else:
            mask = concat_f(
                [np.zeros(a.shape, bool) if mk is None else mk for a, mk in self._inbox]
            )
        self._inbox = []
        self._inbox_rows = 0
        self._process(concat_f(arrs), mask)

    def _process(self, arr: np.ndarray, mask: np.ndarray | None) -> None:
        # column-contiguous from here on (see streaming_noise.concat_f)
        arr = np.asfortranarray(arr)
        mask = None if mask is None else np.asfortranarray(mask)
        step = 1 << 16
        for lo in range(0, arr.shape[0], step):
            self._update(arr[lo : lo + step], None if mask is None else mask[lo : lo + step])

    def _update(self, y: np.ndarray, mask: np.ndarray | None) -> None:
        c = y.shape[0]
        if c == 0:
            return
        if self._int:
            y0 = y.astype(np.int64)
            gaps = mask
        else:
            y0 = y.astype(np.float64)
            gaps = np.isnan(y)
            if mask is not None:
                gaps |= mask
        if gaps is not None and not gaps.any():
            gaps = None
        unset = ~self._ref_set
        if unset.any():
            for j in np.nonzero(unset)[0]:
                col = y0[:, j] if gaps is None else y0[~gaps[:, j], j]
                if col.size:
                    self._ref[j] = col[0]
                    self._ref_set[j] = True
        y0 = y0 - self._ref
        if gaps is not None:
            y0[gaps] = 0
        p0 = self._n_proc  # phase positions p0+1 .. p0+c are new
        x = np.cumsum(y0, axis=0)
        x += self._x_last
        if gaps is None:
            g = np.broadcast_to(self._g_last, (c, self._nch))
        else:
            g = self._g_last + np.cumsum(gaps, axis=0, dtype=np.int64)
            self.n_gaps += np.count_nonzero(gaps, axis=0)
        self._x_last = x[-1:].copy()
        self._g_last = g[-1:].copy()
        self._n_proc += c
        if gaps is not None and not self._gaps_seen:
            self._first_gap()
        if self._noise:
            self._update_noise(p0, x, g, gaps)
        csum = None
        if any(s > 1 and lv.bs is not None and lv.bs_live for s, lv in self.levels.items()):
            csum = np.cumsum(x, axis=0)  # chunk-local running sum of X for block sums
        for lv in self.levels.values():
            self._update_level(lv, p0, x, g, csum)

    def _first_gap(self) -> None:
        """Start keeping gap counts: every G so far is 0."""
        self._gaps_seen = True
        for s, lv in self.levels.items():
            lv.g_at = lv.x_at.zeros_like(np.dtype(np.int64))
            if lv.bs is not None:
                lv.g_end = lv.g_at if s == 1 else lv.bs.zeros_like(np.dtype(np.int64))

    def _flush_noise(self, m: int | None = None) -> None:
        """Add the batched phase values of m (or of every m) to the noise-ID sums."""
        for mm in [m] if m is not None else list(self._noise):
            pending = self._noise_pending[mm]
            if not pending:
                continue
            sums = self._noise[mm]
            xs = concat_f([p[0] for p in pending])
            gs = None
            if any(p[1] is not None for p in pending):
                gs = concat_f([p[1] if p[1] is not None  # before the first gap: G = 0
                               else np.zeros(p[0].shape, np.int64) for p in pending])
            sums.add(xs, gs)
            pending.clear()
            if self._nid_young[mm] and sums.points().min() >= LAG1_MIN_POINTS:
                self._nid_young[mm] = False  # lag-1 from now on: B1's MVAR not needed

    def _update_noise(self, p0: int, x: np.ndarray, g: np.ndarray,
                      gaps: np.ndarray | None) -> None:
        """Feed the phase at the multiples of each m (NaN where that rate sample is a gap,
        as ``api._noise_phase`` marks it) to the running noise-ID sums."""
        c = x.shape[0]
        for m in self._noise:
            i0 = (p0 // m + 1) * m - p0 - 1
            if i0 >= c:
                continue
            xs = x[i0::m].astype(np.float64)
            gs = None
            if self._gaps_seen:  # cumulative gap counts at the same positions
                gs = g[i0::m]
                if gaps is not None:
                    xs[gaps[i0::m]] = np.nan
            pending = self._noise_pending[m]
            pending.append((xs, gs))
            # a few values per chunk (long m) are batched: the sums' cost is per call
            if xs.shape[0] >= _NOISE_BATCH or len(pending) * xs.shape[0] >= _NOISE_BATCH:
                self._flush_noise(m)
        if not self._mvar_stats:
            for lv in self.levels.values():
                if lv.bs_live and not any(self._nid_young[m] for m in lv.ms):
                    lv.bs_live = False

    def _update_level(
        self, lv: _Level, p0: int, x: np.ndarray, g: np.ndarray, csum: np.ndarray | None
    ) -> None:
        s = lv.stride
        c = x.shape[0]
        # phase values at multiples of s among positions p0+1..p0+c
        i_old = lv.x_at.stop
        b_old = b_new = 0
        if lv.bs is not None and lv.bs_live:
            b_old = lv.bs.stop
        if s == 1:
            lv.x_at.append(x)
            if self._gaps_seen:
                lv.g_at.append(g)
        else:
            sel = slice((p0 // s + 1) * s - p0 - 1, c, s)
            lv.x_at.append(x[sel])
            if self._gaps_seen:
                lv.g_at.append(g[sel])
        i_new = lv.x_at.stop
        if lv.bs is not None and lv.bs_live:
            if s > 1:
                # blocks [b*s, b*s+s-1] end at rows p - p0 - 1 with p % s == s - 1; their
                # sums are differences of the chunk's running sum ``csum`` of X
                assert csum is not None
                e0 = (s - 1 - (p0 + 1)) % s
                if e0 < c:
                    ends = csum[e0::s]
                    sums = np.empty_like(ends)
                    sums[0] = ends[0] + lv.part_sum
                    np.subtract(ends[1:], ends[:-1], out=sums[1:])
                    lv.bs.append(sums)
                    if self._gaps_seen:
                        lv.g_end.append(g[e0::s])  # type: ignore[union-attr]
                    lv.part_sum = csum[-1] - ends[-1]
                else:
                    lv.part_sum = lv.part_sum + csum[-1]
            b_new = lv.bs.stop
        if i_new == i_old and b_new == b_old:
            return  # a long stride: no new phase value or block in this chunk
        gaps = self._gaps_seen
        xa = lv.x_at
        for m in lv.ms:
            q = m // s
            # second differences D_i = X_i - 2 X_{i-q} + X_{i-2q} (level indices) shared
            # by AVAR, OAVAR, HVAR, OHVAR (H_i = D_i - D_{i-q}) and, at stride 1, MVAR
            d_lo = max(i_old - q, 2 * q)
            dd: np.ndarray | None = None
            if d_lo < i_new:
                x0 = xa.view(d_lo, i_new)
                dd = x0 - xa.view(d_lo - q, i_new - q)
                dd -= xa.view(d_lo - q, i_new - q)
                dd += xa.view(d_lo - 2 * q, i_new - 2 * q)
            for stat in self.stats:
                fam, overlapping = STREAM_STATS[stat]
                if fam == "mvar":
                    continue
                span = _SPAN[fam] * q
                lo = max(i_old, span)
                if lo >= i_new:
                    continue
                # non-overlapping terms sit on positions that are multiples of m
                idx0 = lo if overlapping else -(-lo // q) * q
                if idx0 >= i_new:
                    continue
                step = 1 if overlapping else q
                n_t = (i_new - 1 - idx0) // step + 1
                hi = idx0 + (n_t - 1) * step + 1
                if fam == "avar":
                    assert dd is not None
                    v = dd[idx0 - d_lo : hi - d_lo : step]
                elif fam == "hvar":
                    assert dd is not None
                    v = (
                        dd[idx0 - d_lo : hi - d_lo : step]
                        - dd[idx0 - q - d_lo : hi - q - d_lo : step]
                    )
                else:
                    v = xa.view(idx0, hi)[::step] - xa.view(idx0 - q, hi - q)[::step]
                valid = None
                if gaps:
                    valid = (
                        lv.g_at.view(idx0, hi)[::step]
                        == lv.g_at.view(idx0 - span, hi - span)[::step]
                    )
                self.acc[(stat, m)].add(v, valid, fam == "std")
            if b_new > b_old and (self._mvar_stats or self._nid_young.get(m, False)):
                self._update_mvar(lv, m, b_old, b_new, dd if s == 1 else None, d_lo)

    def _update_mvar(
        self, lv: _Level, m: int, b_old: int, b_new: int, dd: np.ndarray | None, d_lo: int
    ) -> None:
        s = lv.stride
        q = m // s
        assert lv.bs is not None and lv.g_end is not None
        if q <= _LOCAL_MVAR_Q:
            e = self._mvar_terms_local(lv, q, b_old, b_new, dd, d_lo)
        else:
            e = self._mvar_terms_cd(lv, m, b_old, b_new, dd, d_lo)
        if e is None:
            return
        lo = b_new - e.shape[0]
        self._add_mvar_terms(lv, m, s, q, lo, b_new, e)

    def _mvar_terms_cd(
        self, lv: _Level, m: int, b_old: int, b_new: int, dd: np.ndarray | None, d_lo: int
    ) -> np.ndarray | None:
        """New MVAR terms from the running sum ``cd`` of d kept across chunks (long q:
        recomputing q - 1 differences per chunk would cost more than the chunk)."""
        q = m // lv.stride
        bs = lv.bs
        assert bs is not None
        cd = lv.cd[m]
        lo = max(b_old, 2 * q)
        if lo < b_new:
            if dd is not None:  # stride 1: the block sums are X, d is the shared D
                d = dd[lo - d_lo :]
            else:
                d = (
                    bs.view(lo, b_new)
                    - 2 * bs.view(lo - q, b_new - q)
                    + bs.view(lo - 2 * q, b_new - 2 * q)
                )
            if cd.stop == 0:
                # CD is indexed from block 2q on; pad so absolute indices line up
                cd.start = cd.stop = 2 * q - 1
                cd.append(np.zeros((1, d.shape[1]), d.dtype))
            last = cd.view(cd.stop - 1, cd.stop)
            run = np.cumsum(d, axis=0)
            run += last
            cd.append(run)
        lo = max(b_old, 3 * q - 1)
        if lo >= b_new:
            return None
        return cd.view(lo, b_new) - cd.view(lo - q, b_new - q)

    @staticmethod
    def _mvar_terms_local(
        lv: _Level, q: int, b_old: int, b_new: int, dd: np.ndarray | None, d_lo: int
    ) -> np.ndarray | None:
        """New MVAR terms E_b = sum_{j=b-q+1}^{b} d_j (d: second differences of the block
        sums) from a running sum local to this chunk: no history beyond the block sums,
        q - 1 differences recomputed per chunk (used for q <= _LOCAL_MVAR_Q)."""
        lo = max(b_old, 3 * q - 1)
        if lo >= b_new:
            return None
        d0 = lo - q + 1
        if dd is not None and d0 >= d_lo:  # stride 1: the block sums are X: d is D
            d = dd[d0 - d_lo :]
        else:
            bs = lv.bs
            assert bs is not None
            d = bs.view(d0, b_new) - bs.view(d0 - q, b_new - q)
            d -= bs.view(d0 - q, b_new - q)
            d += bs.view(d0 - 2 * q, b_new - 2 * q)
        run = np.cumsum(d, axis=0)
        e = run[q - 1 :].copy(order="F")
        e[1:] -= run[:-q]
        return e

    def _add_mvar_terms(
        self, lv: _Level, m: int, s: int, q: int, lo: int, b_new: int, e: np.ndarray
    ) -> None:
        """Add MVAR terms E_b, b = lo..b_new-1, skipping (and counting) gap windows."""
        valid = valid_noise = None
        if self._gaps_seen:
            # window y_{b0 s+1} .. y_{(b0+3q) s - 1}, b0 = b - 3q + 1
            g_end = lv.g_end.view(lo, b_new)
            g_start = lv.g_at.view(lo - 3 * q + 1, b_new - 3 * q + 1)
            valid = valid_noise = g_end == g_start
            if s == 1:
                # noise ID's MVAR (noise_id._mvar on api._noise_phase) also rejects a
                # term when the sample just before its window is a gap: y_{b-3m+1}..y_b
                if lo - 3 * q >= 0:
                    g_before = lv.g_at.view(lo - 3 * q, b_new - 3 * q)
                else:  # G_{-1} = 0 = G_0 for the first term
                    g_before = np.concatenate(
                        [np.zeros((1, e.shape[1]), np.int64), lv.g_at.view(0, b_new - 3 * q)]
                    )
                valid_noise = g_end == g_before
        for stat in ("mdev", "tdev"):
            if stat in self.stats:
                self.acc[(stat, m)].add(e, valid, False)
        if self._nid_young.get(m, False):
            self.acc[("_nmvar", m)].add(e, valid_noise, False)

    # -- results --------------------------------------------------------------------
    def _variance(self, stat: str, m: int) -> tuple[np.ndarray, np.ndarray]:
        acc = self.acc[(stat, m)]
        fam = STREAM_STATS[stat][0]
        n = acc.n
        s2 = acc.sum2 + acc.comp
        with np.errstate(invalid="ignore", divide="ignore"):
            if fam == "avar":
                var = s2 / (2.0 * m * m * n)
            elif fam == "hvar":
                var = s2 / (6.0 * m * m * n)
            elif fam == "mvar":
                var = s2 / (2.0 * float(m) ** 4 * n)
                if stat == "tdev":
                    var = var * (m * self.tau0_s) ** 2 / 3.0
            else:  # sum2 holds the sum of squared deviations from the running mean
                var = s2 / (n - 1) / (m * m)
        var = np.where(n > (1 if fam == "std" else 0), var, np.nan) * self.scale**2
        return var, n

    def snapshot(self) -> Mapping[str, Any] | list[Mapping[str, Any]]:
        """Results so far: ``{stat: StatResult}`` (1-D input) or one such per channel."""
        if self._nch is None:
            raise StatsError("snapshot() before any update()")
        self._flush_inbox()
        self._flush_noise()
        per_channel: list[dict[str, Any]] = [{} for _ in range(self._nch)]
        n_freq = self.n_samples
        lag1_cache: dict[tuple[int, int], np.ndarray] = {}
        for stat in self.stats:
            try:
                allowed = set(
                    int(m) for m in averaging_factors(stat, n_freq, self.taus, self.tau0_s)
                )
            except StatsError:
                allowed = set()
            # rows whose every term touched a gap stay (n = 0, var NaN), as in batch
            mm = np.array([m for m in self.ms if m in allowed], dtype=np.int64)
            rows = [self._variance(stat, int(m)) for m in mm]
            var = np.array([r[0] for r in rows]).reshape(mm.size, self._nch).T
            n = np.array([r[1] for r in rows], np.int64).reshape(mm.size, self._nch).T
            skipped = (
                np.array([self.acc[(stat, int(m))].skipped for m in mm], np.int64)
                .reshape(mm.size, self._nch)
                .T
            )
            alpha = self._alphas(stat, mm, n_freq + 1, lag1_cache)
            for ch, res in enumerate(self._results(stat, mm, n, var, skipped, n_freq, alpha)):
                per_channel[ch][stat] = res
        return per_channel[0] if self._one_d else per_channel

    def _alphas(
        self, stat: str, ms: np.ndarray, n_phase: int, lag1_cache: dict[tuple[int, int], np.ndarray]
    ) -> np.ndarray:
        """Noise exponent (channels x m) as ``compute(..., data_type="freq")`` identifies
        it (``noise_id.identify_alpha``), from the running sums; or the fixed ``alpha``."""
        nch = int(self._nch or 0)
        if self.alpha is not None:
            return np.full((nch, ms.size), self.alpha, dtype=np.int64)
        from imubench.stats.noise_id import alpha_range
        from imubench.stats.streaming_noise import ALPHA_UNKNOWN

        var_stat = canonical_stat(stat)
        lo, hi = alpha_range(var_stat)
        dmax = dmax_for(var_stat)
        out = np.empty((nch, ms.size), dtype=np.int64)
        # batch subtracts the mean of the valid samples before zeroing the gaps: c is
        # that mean minus the engine's reference sample (X_N over the valid count)
        with np.errstate(invalid="ignore", divide="ignore"):
            c = self._x_last[0].astype(np.float64) / (self._n_proc - self._g_last[0])
        for i, m in enumerate(ms):
            sums = self._noise[int(m)]
            pts = sums.points()
            lag1 = lag1_cache.get((int(m), dmax))
            if lag1 is None:  # the lag-1 result depends on dmax only, not on the statistic
                lag1 = np.full(nch, ALPHA_UNKNOWN, dtype=np.int64)
                for ch in np.nonzero(pts >= LAG1_MIN_POINTS)[0]:
                    with contextlib.suppress(StatsError):  # stays ALPHA_UNKNOWN
                        lag1[ch] = sums.lag1_alpha(int(ch), dmax, float(c[ch]))
                lag1_cache[(int(m), dmax)] = lag1
            for ch in range(nch):
                if pts[ch] >= LAG1_MIN_POINTS:
                    a = int(lag1[ch])
                    out[ch, i] = a if a == ALPHA_UNKNOWN else min(max(a, lo), hi)
                else:
                    out[ch, i] = sums.identify(ch, var_stat, n_phase,
                                               self._noise_mvar(int(m), ch), float(c[ch]))
        return out

    def _noise_mvar(self, m: int, ch: int) -> float | None:
        """Unscaled MVAR at m with the noise-ID gap rule (None: no term formed)."""
        acc = self.acc[("_nmvar", m)]
        n = int(acc.n[ch])
        if n == 0:
            return None
        return float((acc.sum2[ch] + acc.comp[ch]) / (2.0 * float(m) ** 4 * n))

    def _results(
        self,
        stat: str,
        m: np.ndarray,
        n: np.ndarray,
        var: np.ndarray,
        skipped: np.ndarray,
        n_freq: int,
        alpha: np.ndarray,
    ) -> list[Any]:
        """One StatResult per channel; arrays are (channels x m)."""
        from imubench.stats.confidence import confidence_arrays
        from imubench.stats.result import StatResult

        overlapping = STREAM_STATS[stat][1]
        stride = np.array([self._stride(int(mm)) if overlapping else 1 for mm in m], dtype=np.int64)
        edf, lo, hi = confidence_arrays(
            stat, alpha, m, n_freq + 1, var, self.confidence, stride=stride
        )
        out = []
        for ch in range(var.shape[0]):
            out.append(
                StatResult(
                    stat=stat,
                    data_type="freq",
                    rate_hz=self.rate_hz,
                    tau_s=m * self.tau0_s,
                    m=m,
                    n=n[ch],
                    var=var[ch],
                    dev=np.sqrt(var[ch]),
                    ci_low=lo[ch],
                    ci_high=hi[ch],
                    alpha=alpha[ch],
                    edf=edf[ch],
                    confidence=self.confidence,
                    bias_corrected=False,
                    bias_factor=np.ones(m.shape),
                    drift=None,
                    gaps=skipped[ch],
                    notes=(f"streaming memory={self.memory}",),
                )
            )
        return out

    # -- persistence ------------------------------------------------------------------
    def save_state(self) -> bytes:
        """Serialise the whole engine state (config, sums, histories) to bytes."""
        if self._nch is None:
            raise StatsError("save_state() before any update()")
        self._flush_inbox()
        self._flush_noise()
        arrays: dict[str, np.ndarray] = {
            "scale": self.scale,
            "ref": self._ref,
            "ref_set": self._ref_set,
            "x_last": self._x_last,
            "g_last": self._g_last,
            "n_gaps": self.n_gaps,
        }
        for (stat, m), acc in self.acc.items():
            for k, v in acc.state().items():
                arrays[f"acc/{stat}/{m}/{k}"] = v
        for m, sums in self._noise.items():
            for k, v in sums.state().items():
                arrays[f"nid/{m}/{k}"] = v
            arrays[f"nid/{m}/young"] = np.array([self._nid_young[m]])
        for s, lv in self.levels.items():
            arrays[f"lv/{s}/part_sum"] = lv.part_sum
            arrays[f"lv/{s}/bs_live"] = np.array([lv.bs_live])
            for name, seq in self._level_seqs(s, lv).items():
                if seq is not None:  # only the rows a future term can reach
                    held = min(seq.stop - seq.start, seq.keep)
                    arrays[f"lv/{s}/{name}"] = seq.view(seq.stop - held, seq.stop)
                    arrays[f"lv/{s}/{name}/start"] = np.array([seq.stop - held, seq.stop])
        meta = {
            "rate_hz": self.rate_hz,
            "taus": self.taus,
            "stats": list(self.stats),
            "max_m": self.max_m,
            "memory": self.memory,
            "overlap": self.overlap,
            "confidence": self.confidence,
            "alpha": self.alpha,
            "n_samples": self.n_samples,
            "nch": self._nch,
            "one_d": self._one_d,
            "int": self._int,
            "gaps_seen": self._gaps_seen, "format": STATE_FORMAT,
        }
        buf = io.BytesIO()
        np.savez(buf, __meta__=np.frombuffer(json.dumps(meta).encode(), np.uint8), **arrays)
        return buf.getvalue()

    def _level_seqs(self, s: int, lv: _Level) -> dict[str, _Seq | None]:
        """The histories of one level that persist (stride 1 shares X with its block
        sums; gap counts exist only once a gap was seen)."""
        seqs: dict[str, _Seq | None] = {"x_at": lv.x_at}
        if s > 1:
            seqs["bs"] = lv.bs
        if self._gaps_seen:
            seqs["g_at"] = lv.g_at
            if s > 1:
                seqs["g_end"] = lv.g_end
        seqs.update({f"cd{m}": q for m, q in lv.cd.items()})
        return seqs

    @classmethod
    def load_state(cls, data: bytes) -> StreamingAllan:
        """Rebuild an engine from :meth:`save_state` bytes; updates continue seamlessly."""
        try:
            z = np.load(io.BytesIO(data), allow_pickle=False)
            meta = json.loads(bytes(z["__meta__"]).decode())
        except (OSError, ValueError, KeyError) as exc:
            raise StatsError(
                f"load_state: not a saved StreamingAllan state ({exc}); pass the bytes "
                "that save_state() returned"
            ) from exc
        if meta.get("format") != STATE_FORMAT:
            raise StatsError(
                f"load_state: state format {meta.get('format')!r} is not {STATE_FORMAT} (saved "
                "by another version of the engine); start a new analysis"
            )
        with z:
            taus = meta["taus"]
            eng = cls(
                meta["rate_hz"],
                taus=taus,
                stats=meta["stats"],
                max_tau_s=meta["max_m"] / meta["rate_hz"],
                memory=meta["memory"],
                overlap=meta["overlap"],
                scale=z["scale"],
                confidence=meta["confidence"],
                alpha=meta["alpha"],
            )
            dtype = np.int64 if meta["int"] else np.float64
            eng._one_d = meta["one_d"]
            eng._setup(np.zeros((0, meta["nch"]), dtype))
            eng._n_proc = meta["n_samples"]
            if meta["gaps_seen"]:
                eng._first_gap()
            eng._ref = z["ref"]
            eng._ref_set = z["ref_set"]
            eng._x_last = z["x_last"]
            eng._g_last = z["g_last"]
            eng.n_gaps = z["n_gaps"]
            for (stat, m), acc in eng.acc.items():
                for k in acc.__slots__:
                    setattr(acc, k, z[f"acc/{stat}/{m}/{k}"].copy())
            for m, sums in eng._noise.items():
                sums.load({k: z[f"nid/{m}/{k}"] for k in sums.state()})
                eng._nid_young[m] = bool(z[f"nid/{m}/young"][0])
            for s, lv in eng.levels.items():
                lv.part_sum = z[f"lv/{s}/part_sum"].copy()
                lv.bs_live = bool(z[f"lv/{s}/bs_live"][0])
                for name, seq in eng._level_seqs(s, lv).items():
                    if seq is None:
                        continue
                    rows = z[f"lv/{s}/{name}"]
                    start, stop = (int(v) for v in z[f"lv/{s}/{name}/start"])
                    seq.buf = np.zeros((max(2 * rows.shape[0], 1024), rows.shape[1]),
                                       rows.dtype, order="F")
                    seq.buf[: rows.shape[0]] = rows
                    seq.start, seq.stop = start, stop
        return eng
