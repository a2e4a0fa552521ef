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
  terms, ``E_p = E_{p-1} + D_p - D_{p-m}``, carried across chunks; for float input
  summed afresh from its m terms after every ``8 m`` moves, so its rounding does not
  accumulate), ``var = <E^2> / (2 m^4)``; TVAR (eq. 15) = ``tau^2 / 3 * MVAR``.
  Every term is formed from the kept X history in place (no term arrays).
* STDVAR / OSTDVAR: ``A_p = X_p - X_{p-m}`` (m times the m-sample mean), sample variance
  of ``A / m`` over non-overlapping (``p % m == 0``) or all positions.

Integer input (raw int16 counts) accumulates in int64 (two's-complement wrap-around is
harmless: every term is a difference whose true value fits in int64), so the terms are
exact; squares are summed in float64 in blocks of 4096 terms and the block sums are
added with Neumaier compensation. Float input uses the same compensated sums.

The per-term work runs in compiled kernels (``_stream_kernels``): one call per
decimation level adds every m's AVAR/OAVAR/HVAR/OHVAR terms of every channel, one call
per (level, m) its MVAR terms, one per m the noise-ID sums, reading the level histories
in place and writing into (accumulator x channel) tables. The chunk's own arrays (input
copy, phase, running sums, gap counts) live in engine-owned work buffers grown to the
largest chunk seen: after warm-up an update allocates no large temporary, whatever the
allocator does with freed memory.

NaN samples are gaps: the cumulative gap count ``G_p`` tells whether a term's window
holds one; such terms are skipped and counted, never bridged.

Memory modes:

* ``exact``: every overlapping term, needing the last ``3 m_max + 1`` phase values per
  channel (8 bytes each; MVAR adds one moving sum E per m and channel).
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
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from imubench.errors import StatsError
from imubench.stats._stream_kernels import level_sums, mvar_sums
from imubench.stats.edf import canonical_stat
from imubench.stats.noise_id import LAG1_MIN_POINTS, alpha_range, dmax_for, identifies_at
from imubench.stats.streaming_noise import ALPHA_UNKNOWN, RunningNoiseSums, concat_f
from imubench.stats.taus import averaging_factors, streaming_factors

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
# float input: the moving MVAR sum E is summed afresh after this many moves per q (its
# rounding then never accumulates over more than ~8 q terms); integer E is exact
_MVAR_REANCHOR = 8


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

    def __init__(self, tab: _Tables, row: int) -> None:
        # views of one row of the engine's tables, which the compiled kernels update
        self.n = tab.cnt[row]
        self.skipped = tab.skip[row]
        self.sum2 = tab.sum2[row]
        self.comp = tab.comp[row]
        self.sum1 = np.zeros(tab.sum2.shape[1])

    @staticmethod
    def _neumaier(total: np.ndarray, comp: np.ndarray, add: np.ndarray) -> None:
        t = total + add
        big = np.abs(total) >= np.abs(add)
        comp += np.where(big, (total - t) + add, (add - t) + total)
        total[...] = t

    def add_moments(self, v: np.ndarray, valid: np.ndarray | None) -> None:
        """Add terms ``v`` (k, nch) to the running mean and sum of squared deviations
        (the standard variances); ``valid`` masks terms free of gaps (None = all). The
        squared-difference families are summed by ``_stream_kernels`` instead."""
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


class _Tables:
    """All accumulators' sums as (accumulator row, channel) tables, so that one compiled
    call (:mod:`imubench.stats._stream_kernels`) updates every m of a level."""

    def __init__(self, rows: int, nch: int) -> None:
        self.sum2 = np.zeros((rows, nch))
        self.comp = np.zeros((rows, nch))
        self.cnt = np.zeros((rows, nch), np.int64)
        self.skip = np.zeros((rows, nch), np.int64)


class _Seq:
    """Append-only history of the last ``keep`` rows of a 2-D sequence, as a linear
    buffer that is compacted when full (amortised O(1) per row, contiguous slices)."""

    def __init__(self, keep: int, nch: int, dtype: np.dtype) -> None:
        self.keep = keep
        self.buf = np.zeros((min(2 * keep, 1024), nch), dtype, order="F")
        self.start = 0  # absolute index of buf[0]
        self.stop = 0  # absolute index one past the last row

    def append(self, rows: np.ndarray) -> None:
        self.reserve(rows.shape[0])[...] = rows

    def reserve(self, k: int) -> np.ndarray:
        """Append k rows and return them (uninitialised) for the caller to fill."""
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
        self.stop += k
        return self.buf[fill : fill + k]

    def zeros_like(self, dtype: np.dtype) -> _Seq:
        """A sequence holding zeros at the same absolute indices as this one."""
        z = _Seq(self.keep, self.buf.shape[1], dtype)
        z.buf = np.zeros(self.buf.shape, dtype, order="F")
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
    mv_e: dict[int, np.ndarray]  # per m: MVAR term E at the last block (per channel)
    mv_age: dict[int, np.ndarray]  # per m: moves of E since it was summed (-1: not kept)
    bs_live: bool = True  # block sums still needed (MVAR stats, or young noise-ID m)
    qs: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # m // stride
    rows: np.ndarray = field(default_factory=lambda: np.zeros((0, 4), np.int64))
    mv_rows: dict[int, np.ndarray] = field(default_factory=dict)  # per m: mdev, tdev rows


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
        self.nominal_rate_hz = float(rate_hz)
        """The rate the averaging factors were chosen at (the chip's nominal ODR)."""
        self.rate_hz = float(rate_hz)
        """The rate taus are reported in (:meth:`set_rate`)."""
        self.tau0_s = 1.0 / self.rate_hz
        self.stats = tuple(dict.fromkeys(_canonical(s) for s in stats))
        self.taus = taus
        self.memory = memory
        self.overlap = int(overlap)
        self.confidence = confidence
        self.alpha = alpha
        self.max_m, self.ms = streaming_factors(self.stats, taus, self.rate_hz, max_tau_s)
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
        # gathered small chunks (rows 0.._inbox_rows-1; the gap mask only once one came)
        self._inbox = np.empty((0, nch), dtype, order="F")
        self._inbox_mask = np.zeros((0, nch), bool, order="F")
        self._inbox_masked = False  # some gathered chunk came with a gap mask
        self._inbox_rows = 0
        self._gaps_seen = False
        self.n_gaps = np.zeros(nch, np.int64)
        # gap-free runs of samples per channel, for the EDF (confidence.runs_edf): the
        # lengths of the closed runs (length -> count) and of the open one
        self._runs: list[dict[int, int]] = [{} for _ in range(nch)]
        self._open_run = np.zeros(nch, np.int64)
        self._ref = np.zeros(nch, dtype)
        self._ref_set = np.zeros(nch, bool)
        self._x_last = np.zeros((1, nch), dtype)
        self._g_last = np.zeros((1, nch), np.int64)
        self._mvar_stats = "mvar" in {STREAM_STATS[s][0] for s in self.stats}
        self._std_stats = [s for s in self.stats if STREAM_STATS[s][0] == "std"]
        self._no_g = np.zeros((0, nch), np.int64, order="F")  # G buffer before any gap
        self._scr = np.empty(0)  # see _scratch
        self._bufs: dict[str, np.ndarray] = {}  # see _work
        need_bs = self._mvar_stats or self.alpha is None
        self.levels: dict[int, _Level] = {}
        for m in self.ms:
            s = self._stride(m)
            lv = self.levels.get(s)
            if lv is None:
                lv = _Level(s, None, None, None, None, np.zeros(nch, dtype), [], {}, {})  # type: ignore[arg-type]
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
                    lv.mv_e[m] = np.zeros(nch, dtype)
                    lv.mv_age[m] = np.array([-1], np.int64)
        keys = [(stat, m) for stat in self.stats for m in self.ms]
        if self.alpha is None:
            keys += [("_nmvar", m) for m in self.ms]
        self._tab = _Tables(len(keys), nch)
        self._row = {k: i for i, k in enumerate(keys)}
        self.acc: dict[tuple[str, int], _Accumulator] = {
            k: _Accumulator(self._tab, i) for k, i in self._row.items()
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
        for lv in self.levels.values():
            # kernel tables of the level: q = m / stride and the accumulator row of each
            # D/H family at that m (-1: statistic not asked for)
            lv.qs = np.array([m // lv.stride for m in lv.ms], np.int64)
            lv.rows = np.array(
                [[self._row.get((st, m), -1) for st in ("oadev", "adev", "ohdev", "hdev")]
                 for m in lv.ms], np.int64).reshape(len(lv.ms), 4)
            lv.mv_rows = {m: np.array([self._row.get((st, m), -1) for st in ("mdev", "tdev")],
                                      np.int64) for m in lv.ms}

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
            self._gather(arr, mask)
            if self._inbox_rows >= _INBOX_ROWS:
                self._flush_inbox()
            return
        self._flush_inbox()
        self._process(arr, mask)

    def set_rate(self, rate_hz: float) -> None:
        """Report taus at ``rate_hz``, the rate the samples were really taken at (a chip
        whose clock runs 3.75 % fast samples at 107.9 Hz for its nominal 104: at the
        nominal rate every tau would read 3.75 % long). The averaging factors stay those
        chosen at :attr:`nominal_rate_hz`; a rate more than 10 % from it is not a clock
        error but another ODR, and is refused."""
        if not (rate_hz > 0 and abs(rate_hz / self.nominal_rate_hz - 1.0) <= 0.1):
            raise StatsError(f"set_rate: {rate_hz} Hz is not within 10 % of the nominal "
                             f"{self.nominal_rate_hz:g} Hz the engine was made for")
        self.rate_hz = float(rate_hz)
        self.tau0_s = 1.0 / self.rate_hz

    @property
    def input_is_integer(self) -> bool | None:
        """Whether the engine sums integer counts (True) or float values (False); None
        before the first update."""
        return self._int

    @property
    def channel_scale(self) -> np.ndarray | None:
        """The factor each channel's input is multiplied by (unit per count for raw
        counts, 1 for values); None before the first update."""
        return self.scale if self._nch is not None else None

    @property
    def n_samples(self) -> int:
        """Samples (rows) given to update() so far."""
        return self._n_proc + self._inbox_rows if self._nch is not None else 0

    def _gather(self, arr: np.ndarray, mask: np.ndarray | None) -> None:
        """Copy a small chunk into the inbox buffer (grown only: 2 x _INBOX_ROWS)."""
        k, n = self._inbox_rows, arr.shape[0]
        if k + n > self._inbox.shape[0]:
            grown = np.empty((max(k + n, 2 * _INBOX_ROWS), arr.shape[1]), self._inbox.dtype,
                             order="F")
            grown[:k] = self._inbox[:k]
            self._inbox = grown
        np.copyto(self._inbox[k:k + n], arr, casting="unsafe" if self._int else "same_kind")
        if mask is not None and not self._inbox_masked:
            if self._inbox_mask.shape[0] < self._inbox.shape[0]:
                self._inbox_mask = np.zeros(self._inbox.shape, bool, order="F")
            self._inbox_mask[:k] = False
            self._inbox_masked = True
        if self._inbox_masked:
            if self._inbox_mask.shape[0] < k + n:
                grown_m = np.zeros(self._inbox.shape, bool, order="F")
                grown_m[:k] = self._inbox_mask[:k]
                self._inbox_mask = grown_m
            self._inbox_mask[k:k + n] = False if mask is None else mask
        self._inbox_rows = k + n

    def _flush_inbox(self) -> None:
        k = self._inbox_rows
        if not k:
            return
        self._inbox_rows = 0
        mask = self._inbox_mask[:k] if self._inbox_masked else None
        self._inbox_masked = False
        self._process(self._inbox[:k], mask)

    def _process(self, arr: np.ndarray, mask: np.ndarray | None) -> None:
        # (arr is copied into column-contiguous work arrays by _update)
        mask = None if mask is None else np.asfortranarray(mask)
        step = 1 << 16
        for lo in range(0, arr.shape[0], step):
            self._update(arr[lo : lo + step], None if mask is None else mask[lo : lo + step])

    def _update(self, y: np.ndarray, mask: np.ndarray | None) -> None:
        c = y.shape[0]
        if c == 0:
            return
        # per-chunk arrays live in engine-owned buffers (grown only, see _work): no large
        # temporary per chunk, so the allocator's heap trimming cannot cost page faults
        y0 = self._work("y0", c, self._dtype)
        np.copyto(y0, y, casting="unsafe" if self._int else "same_kind")
        if self._int:
            gaps = mask
        else:
            gaps = np.isnan(y0, out=self._work("nan", c, np.dtype(bool)))
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
        y0 -= self._ref
        if gaps is not None:
            np.copyto(y0, 0, where=gaps)
        p0 = self._n_proc  # phase positions p0+1 .. p0+c are new
        x = np.cumsum(y0, axis=0, out=self._work("x", c, self._dtype))
        x += self._x_last
        if gaps is None:
            g = np.broadcast_to(self._g_last, (c, self._g_last.shape[-1]))
        else:
            g = np.cumsum(gaps, axis=0, dtype=np.int64,
                          out=self._work("g", c, np.dtype(np.int64)))
            g += self._g_last
            self.n_gaps += np.count_nonzero(gaps, axis=0)
        self._count_runs(gaps, c)
        self._x_last = x[-1:].copy()
        self._g_last = g[-1:].copy()
        self._n_proc += c
        if gaps is not None and not self._gaps_seen:
            self._first_gap()
        if self._noise:
            self._update_noise(p0, x, g, gaps)
        csum = None
        if any(s > 1 and lv.bs is not None and lv.bs_live for s, lv in self.levels.items()):
            # chunk-local running sum of X for block sums
            csum = np.cumsum(x, axis=0, out=self._work("csum", c, self._dtype))
        for lv in self.levels.values():
            self._update_level(lv, p0, x, g, csum)

    def _count_runs(self, gaps: np.ndarray | None, c: int) -> None:
        """Extend the gap-free runs by a chunk of ``c`` samples (``gaps``: its mask)."""
        if gaps is None:
            self._open_run += c
            return
        for j in range(gaps.shape[1]):
            at = np.nonzero(gaps[:, j])[0]
            if at.size == 0:
                self._open_run[j] += c
                continue
            closed = np.diff(np.concatenate(([-1], at))) - 1
            closed[0] += self._open_run[j]
            runs = self._runs[j]
            for length in closed[closed > 0].tolist():
                runs[length] = runs.get(length, 0) + 1
            self._open_run[j] = c - 1 - at[-1]

    def runs(self, channel: int) -> tuple[np.ndarray, np.ndarray]:
        """The channel's gap-free runs as :meth:`imubench.stats.prep.PhaseData.runs`
        gives them for the same samples in one batch (a run of L samples links L + 1
        phase points)."""
        runs = dict(self._runs[channel])
        if self._open_run[channel] > 0:
            open_len = int(self._open_run[channel])
            runs[open_len] = runs.get(open_len, 0) + 1
        if not runs:
            return np.ones(1, np.int64), np.ones(1, np.int64)
        lengths, counts = zip(*sorted(runs.items()), strict=True)
        return np.array(lengths, np.int64) + 1, np.array(counts, np.int64)

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
            self._noise_added(mm)

    def _noise_added(self, m: int) -> None:
        if self._nid_young[m] and self._noise[m].points().min() >= LAG1_MIN_POINTS:
            self._nid_young[m] = False  # lag-1 from now on: B1's MVAR not needed

    def _work(self, name: str, rows: int, dtype: np.dtype) -> np.ndarray:
        """Engine-owned (rows, channels) work array, column-contiguous, reused by every
        chunk and grown only (to the largest chunk seen)."""
        buf = self._bufs.get(name)
        if buf is None or buf.shape[0] < rows:
            buf = np.empty((rows, int(self._nch or 0)), dtype, order="F")
            self._bufs[name] = buf
        return buf[:rows]

    def _scratch(self, n: int) -> np.ndarray:
        """A float64 work array of at least n values, kept by the engine (grown only)."""
        if self._scr.size < n:
            self._scr = np.empty(max(n, 2 * self._scr.size))
        return self._scr

    def _update_noise(self, p0: int, x: np.ndarray, g: np.ndarray,
                      gaps: np.ndarray | None) -> None:
        """Feed the phase at the multiples of each m (NaN where that rate sample is a gap,
        as ``api._noise_phase`` marks it) to the running noise-ID sums."""
        c = x.shape[0]
        for m in self._noise:
            i0 = (p0 // m + 1) * m - p0 - 1
            if i0 >= c:
                continue
            n_new = (c - 1 - i0) // m + 1
            pending = self._noise_pending[m]
            if n_new >= _NOISE_BATCH and not pending and not self._gaps_seen:
                # many values and no gap yet: summed in place by a compiled kernel
                self._noise[m].add_strided(x, i0, self._scratch(n_new + 8))
                self._noise_added(m)
                continue
            xs = x[i0::m].astype(np.float64)
            gs = None
            if self._gaps_seen:  # cumulative gap counts at the same positions
                gs = g[i0::m].copy()  # g is a work buffer, reused by the next chunk
                if gaps is not None:
                    xs[gaps[i0::m]] = np.nan
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
                    sums = lv.bs.reserve(ends.shape[0])
                    np.add(ends[0], lv.part_sum, out=sums[0])
                    np.subtract(ends[1:], ends[:-1], out=sums[1:])
                    if self._gaps_seen:
                        lv.g_end.append(g[e0::s])  # type: ignore[union-attr]
                    lv.part_sum = csum[-1] - ends[-1]
                else:
                    lv.part_sum = lv.part_sum + csum[-1]
            b_new = lv.bs.stop
        if i_new == i_old and b_new == b_old:
            return  # a long stride: no new phase value or block in this chunk
        tab = self._tab
        if i_new > i_old and lv.rows.max(initial=-1) >= 0:
            g, g0 = (lv.g_at.buf, lv.g_at.start) if self._gaps_seen else (self._no_g, 0)
            level_sums(lv.x_at.buf, lv.x_at.start, g, g0, i_old, i_new, lv.qs, lv.rows,
                       tab.sum2, tab.comp, tab.cnt, tab.skip, s)
        for m in lv.ms:
            for stat in self._std_stats:
                self._update_std(lv, stat, m, i_old, i_new)
            if b_new > b_old and (self._mvar_stats or self._nid_young.get(m, False)):
                self._update_mvar(lv, m, b_old, b_new)

    def _update_std(self, lv: _Level, stat: str, m: int, i_old: int, i_new: int) -> None:
        """STDVAR / OSTDVAR terms A_i = X_i - X_{i-q} (level indices i_old..i_new-1)."""
        q = m // lv.stride
        overlapping = STREAM_STATS[stat][1]
        lo = max(i_old, q)
        # non-overlapping terms sit on positions that are multiples of m
        idx0 = lo if overlapping else -(-lo // q) * q
        if idx0 >= i_new:
            return
        step = 1 if overlapping else q
        n_t = (i_new - 1 - idx0) // step + 1
        hi = idx0 + (n_t - 1) * step + 1
        acc = self.acc[(stat, m)]
        clean = 0  # terms 0..clean-1 are tested for gaps (``tested``), the rest hold none
        tested = None
        if self._gaps_seen:  # G never decreases: O(1) tests and a bisection, as in
            g = lv.g_at  # _stream_kernels
            g_last = g.view(hi - 1, hi)[0]
            if ((g.view(idx0, idx0 + 1)[0] > g.view(hi - 1 - q, hi - q)[0])
                    | (g_last - g.view(idx0 - 1, idx0)[0] == lv.stride * (hi - idx0))).all():
                acc.skipped += n_t  # a gap in every term's window, or at every term's end
                return
            g_start = g.view(idx0 - q, hi - q)[::step]  # G at each term's window start
            clean = max(int(np.searchsorted(g_start[:, ch], g_last[ch]))
                        for ch in range(g_start.shape[1]))
            tested = g.view(idx0, hi)[::step][:clean] == g_start[:clean]
        xa = lv.x_at
        v = xa.view(idx0, hi)[::step] - xa.view(idx0 - q, hi - q)[::step]
        if clean:
            acc.add_moments(v[:clean], tested)
        if clean < n_t:
            acc.add_moments(v[clean:], None)

    def _update_mvar(self, lv: _Level, m: int, b_old: int, b_new: int) -> None:
        """Add the new MVAR terms of m (blocks b_old..b_new-1 of the level)."""
        s = lv.stride
        q = m // s
        assert lv.bs is not None and lv.g_end is not None
        rows = lv.mv_rows[m]
        noise_row = self._row[("_nmvar", m)] if self._nid_young.get(m, False) else -1
        tab = self._tab
        if self._gaps_seen:
            ga, ga0, ge, ge0 = lv.g_at.buf, lv.g_at.start, lv.g_end.buf, lv.g_end.start
        else:
            ga, ga0, ge, ge0 = self._no_g, 0, self._no_g, 0
        mvar_sums(lv.bs.buf, lv.bs.start, ga, ga0, ge, ge0, b_old, b_new, q, s == 1, rows,
                  noise_row, tab.sum2, tab.comp, tab.cnt, tab.skip,
                  self._scratch(b_new - b_old), lv.mv_e[m], lv.mv_age[m],
                  -1 if self._int else _MVAR_REANCHOR * q, s)

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
                    int(m) for m in averaging_factors(stat, n_freq, self.taus,
                                                      1.0 / self.nominal_rate_hz)
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
        channels: list[Mapping[str, Any]] = [*per_channel]
        return per_channel[0] if self._one_d else channels

    def _alphas(
        self, stat: str, ms: np.ndarray, n_phase: int, lag1_cache: dict[tuple[int, int], np.ndarray]
    ) -> np.ndarray:
        """Noise exponent (channels x m) as ``compute(..., data_type="freq")`` identifies
        it (``noise_id.identify_alpha``), from the running sums; or the fixed ``alpha``."""
        nch = int(self._nch or 0)
        if self.alpha is not None:
            return np.full((nch, ms.size), self.alpha, dtype=np.int64)

        var_stat = canonical_stat(stat)
        lo, hi = alpha_range(var_stat)
        dmax = dmax_for(var_stat)
        out = np.empty((nch, ms.size), dtype=np.int64)
        # batch subtracts the mean of the valid samples before zeroing the gaps: c is
        # that mean minus the engine's reference sample (X_N over the valid count)
        with np.errstate(invalid="ignore", divide="ignore"):
            c = self._x_last[0].astype(np.float64) / (self._n_proc - self._g_last[0])
        for i, m in enumerate(ms):
            # beyond half the largest m Stable32 keeps the previous tau's alpha (where known)
            held = np.zeros(nch, dtype=bool)
            if i and not identifies_at(var_stat, int(m), n_phase):
                held = out[:, i - 1] != ALPHA_UNKNOWN
                out[held, i] = out[held, i - 1]
            if held.all():
                continue
            sums = self._noise[int(m)]
            pts = sums.points()
            lag1 = lag1_cache.get((int(m), dmax))
            if lag1 is None:  # the lag-1 result depends on dmax only, not on the statistic
                lag1 = np.full(nch, ALPHA_UNKNOWN, dtype=np.int64)
                for ch in np.nonzero(pts >= LAG1_MIN_POINTS)[0]:
                    with contextlib.suppress(StatsError):  # stays ALPHA_UNKNOWN
                        lag1[ch] = sums.lag1_alpha(int(ch), dmax, float(c[ch]))
                lag1_cache[(int(m), dmax)] = lag1
            for ch in np.nonzero(~held)[0]:
                if pts[ch] >= LAG1_MIN_POINTS:
                    a = int(lag1[ch])
                    out[ch, i] = a if a == ALPHA_UNKNOWN else min(max(a, lo), hi)
                else:
                    out[ch, i] = sums.b1_identify(int(ch), var_stat, n_phase,
                                                  self._noise_mvar(int(m), int(ch)), float(c[ch]))
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
        runs = [self.runs(ch) for ch in range(var.shape[0])]
        edf, lo, hi = confidence_arrays(
            stat, alpha, m, runs, var, self.confidence, stride=stride
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
        arrays: dict[str, Any] = {
            "scale": self.scale,
            "ref": self._ref,
            "ref_set": self._ref_set,
            "x_last": self._x_last,
            "g_last": self._g_last,
            "n_gaps": self.n_gaps,
            "open_run": self._open_run,
        }
        for j, runs in enumerate(self._runs):
            arrays[f"runs/{j}"] = np.array(sorted(runs.items()), np.int64).reshape(-1, 2)
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
            "rate_hz": self.nominal_rate_hz,
            "measured_rate_hz": self.rate_hz,
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
            eng.set_rate(meta.get("measured_rate_hz", meta["rate_hz"]))
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
            if "open_run" in z.files:
                eng._open_run = z["open_run"].copy()
                eng._runs = [{int(k): int(v) for k, v in z[f"runs/{j}"]}
                             for j in range(meta["nch"])]
            else:  # saved before the runs were kept: the gap-free runs are unknown, and
                # the EDF is that of one run of every sample, as it was then
                eng._open_run[:] = meta["n_samples"]
            for (stat, m), acc in eng.acc.items():
                for k in acc.__slots__:  # in place: n, skipped, sum2, comp are table views
                    getattr(acc, k)[...] = z[f"acc/{stat}/{m}/{k}"]
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


_WARM = False


def warm_up() -> None:
    """Compile (or load from the numba cache) every kernel a streaming engine uses: both
    input kinds (integer raw counts, floats), both memory modes, every statistic,
    noise identification and snapshots, without and with gaps (the gap counts are other
    array types: until 2026-12-06 they were compiled at a daemon's first gap, and an
    outside reviewer's engine at 6660 Hz lost 20 % of a 35 s run meanwhile). The first
    call on a machine with an empty cache (``NUMBA_CACHE_DIR``) takes tens of seconds;
    later ones load the cache (about a second); repeated calls in one process return at
    once."""
    global _WARM
    if _WARM:
        return
    rng = np.random.default_rng(0)
    x = rng.normal(size=(4096, 2))
    for memory in ("bounded", "exact"):
        for data in ((x * 100).astype(np.int64), x):
            for gap in (False, True):
                eng = StreamingAllan(100.0, taus="octave", stats=list(STREAM_STATS),
                                     max_tau_s=8.0, memory=memory)
                mask = np.zeros(data.shape, bool)
                mask[1000:1010] = gap
                if data.dtype.kind == "i":
                    eng.update(data, gaps=mask)
                    eng.update(data[:7], gaps=mask[:7])
                else:
                    eng.update(np.where(mask, np.nan, data))
                    eng.update(data[:7])
                eng.snapshot()
    _WARM = True
