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
  terms, kept as a running cumulative sum ``CD`` so ``E_p = CD_p - CD_{p-m}``),
  ``var = <E^2> / (2 m^4)``; TVAR (eq. 15) = ``tau^2 / 3 * MVAR``.
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
it equals the batch statistic on everything seen so far (same taus, term counts, CIs).
"""

from __future__ import annotations

import io
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from imubench.errors import StatsError
from imubench.stats.taus import averaging_factors

# statistic (deviation name) -> (variance family, overlapping?)
STREAM_STATS: dict[str, tuple[str, bool]] = {
    "adev": ("avar", False), "oadev": ("avar", True),
    "mdev": ("mvar", True), "tdev": ("mvar", True),
    "hdev": ("hvar", False), "ohdev": ("hvar", True),
    "stdev": ("std", False), "ostdev": ("std", True),
}
_VAR_NAMES = {
    "avar": "adev", "oavar": "oadev", "mvar": "mdev", "tvar": "tdev", "hvar": "hdev",
    "ohvar": "ohdev", "stdvar": "stdev", "ostdvar": "ostdev",
}
# term window length in units of m (phase values spanned minus one)
_SPAN = {"avar": 2, "hvar": 3, "mvar": 3, "std": 1}


def _canonical(stat: str) -> str:
    name = _VAR_NAMES.get(stat, stat)
    if name not in STREAM_STATS:
        raise StatsError(
            f"streaming statistic {stat!r} is not supported; choose from "
            f"{', '.join(STREAM_STATS)}"
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
        vf = v.astype(np.float64)
        if valid is None:
            self.n += v.shape[0]
        else:
            vf = np.where(valid, vf, 0.0)
            cnt = valid.sum(axis=0)
            self.n += cnt
            self.skipped += v.shape[0] - cnt
        if not first_moment:
            self._neumaier(self.sum2, self.comp, np.einsum("ij,ij->j", vf, vf))
            return
        # mean and sum of squared deviations, merged per chunk (Chan, Golub & LeVeque
        # 1979): stable when the mean is large against the spread (a gyro's bias).
        n_old = self.n - (v.shape[0] if valid is None else valid.sum(axis=0))
        n_b = self.n - n_old
        with np.errstate(invalid="ignore", divide="ignore"):
            mean_b = np.where(n_b > 0, vf.sum(axis=0) / n_b, 0.0)
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
        self.buf = np.zeros((min(2 * keep, 1024), nch), dtype)
        self.start = 0  # absolute index of buf[0]
        self.stop = 0  # absolute index one past the last row

    def append(self, rows: np.ndarray) -> None:
        k = rows.shape[0]
        fill = self.stop - self.start
        if fill + k > self.buf.shape[0]:
            tail = min(fill, self.keep)
            need = tail + k
            if 2 * need > self.buf.shape[0]:  # grow (allocation follows the data seen)
                grown = np.zeros((max(2 * need, 1024), self.buf.shape[1]), self.buf.dtype)
                grown[:tail] = self.buf[fill - tail:fill]
                self.buf = grown
            else:  # compact: keep only the last `keep` rows
                self.buf[:tail] = self.buf[fill - tail:fill]
            self.start = self.stop - tail
            fill = tail
        self.buf[fill:fill + k] = rows
        self.stop += k

    def view(self, lo: int, hi: int) -> np.ndarray:
        """Rows with absolute indices lo..hi-1 (must still be held)."""
        if lo < self.start:
            raise AssertionError(f"history too short: need {lo}, hold from {self.start}")
        return self.buf[lo - self.start:hi - self.start]


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


class StreamingAllan:
    """Running-sum Allan-family engine for one or several channels of rate data.

    Args:
        rate_hz: sample rate of the input (tau0 = 1 / rate_hz).
        taus: ``"octave"``, ``"decade"``, ``int`` (points per decade) or tau values (s).
        stats: deviation names from :data:`STREAM_STATS` (variance names accepted).
        max_tau_s: largest tau kept (default: 1e4 samples' worth... i.e. 2**20 tau0).
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
        self.max_m = int(max_tau_s * self.rate_hz) if max_tau_s else 2**20
        if self.max_m < 1:
            raise StatsError(f"max_tau_s={max_tau_s} is shorter than one sample period")
        ms: set[int] = set()
        for stat in self.stats:
            ms.update(int(m) for m in averaging_factors(
                stat, 10**15, taus, self.tau0_s, max_af_override=self.max_m))
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
        self.n_samples = 0
        self.n_gaps = np.zeros(nch, np.int64)
        self._ref = np.zeros(nch, dtype)
        self._ref_set = np.zeros(nch, bool)
        self._x_last = np.zeros((1, nch), dtype)
        self._g_last = np.zeros((1, nch), np.int64)
        need_bs = "mvar" in {STREAM_STATS[s][0] for s in self.stats}
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
            lv.x_at = _Seq(keep, nch, dtype)
            lv.g_at = _Seq(keep, nch, np.dtype(np.int64))
            lv.x_at.append(np.zeros((1, nch), dtype))  # X_0 = 0 at position 0
            lv.g_at.append(np.zeros((1, nch), np.int64))
            if need_bs:
                lv.bs = _Seq(keep, nch, dtype)
                lv.g_end = _Seq(keep, nch, np.dtype(np.int64))
                if s == 1:  # block 0 is position 0: X_0 = 0, G_0 = 0
                    lv.bs.append(np.zeros((1, nch), dtype))
                    lv.g_end.append(np.zeros((1, nch), np.int64))
                for m in lv.ms:
                    lv.cd[m] = _Seq(m // s + 2, nch, dtype)
        self.acc: dict[tuple[str, int], _Accumulator] = {
            (stat, m): _Accumulator(nch) for stat in self.stats for m in self.ms
        }

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
        step = 1 << 16
        for lo in range(0, arr.shape[0], step):
            self._update(arr[lo:lo + step], None if mask is None else mask[lo:lo + step])

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
        p0 = self.n_samples  # phase positions p0+1 .. p0+c are new
        x = np.cumsum(np.concatenate([self._x_last, y0]), axis=0)[1:]
        if gaps is None:
            g = np.broadcast_to(self._g_last, (c, self._nch))
        else:
            g = self._g_last + np.cumsum(gaps, axis=0, dtype=np.int64)
            self.n_gaps += gaps.sum(axis=0)
        self._x_last = x[-1:].copy()
        self._g_last = g[-1:].copy()
        self.n_samples += c
        for lv in self.levels.values():
            self._update_level(lv, p0, x, g)

    def _update_level(self, lv: _Level, p0: int, x: np.ndarray, g: np.ndarray) -> None:
        s = lv.stride
        c = x.shape[0]
        # phase values at multiples of s among positions p0+1..p0+c
        first = (p0 // s + 1) * s
        sel = np.arange(first - p0 - 1, c, s)
        i_old = lv.x_at.stop
        if sel.size:
            lv.x_at.append(x[sel])
            lv.g_at.append(g[sel])
        i_new = lv.x_at.stop
        b_old = b_new = 0
        if lv.bs is not None:
            b_old = lv.bs.stop
            if s == 1:
                lv.bs.append(x)
                lv.g_end.append(g)  # type: ignore[union-attr]
            else:
                # blocks [b*s, b*s+s-1]; positions p0+1..p0+c; block of position p is p // s
                pos = p0 + 1 + np.arange(c)
                ends = np.nonzero(pos % s == s - 1)[0]
                csum = np.cumsum(x, axis=0)
                if ends.size:
                    prev_end = np.concatenate([[-1], ends[:-1]])
                    sums = csum[ends] - np.where(prev_end[:, None] >= 0,
                                                 csum[np.maximum(prev_end, 0)], 0)
                    sums[0] += lv.part_sum
                    lv.bs.append(sums)
                    lv.g_end.append(g[ends])  # type: ignore[union-attr]
                    lv.part_sum = csum[-1] - csum[ends[-1]]
                else:
                    lv.part_sum = lv.part_sum + csum[-1]
            b_new = lv.bs.stop
        for m in lv.ms:
            q = m // s
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

                def lagged(seq: _Seq, lag: int, i0: int = idx0, k: int = n_t,
                           st: int = step) -> np.ndarray:
                    return seq.view(i0 - lag, i0 - lag + (k - 1) * st + 1)[::st]

                xa = lv.x_at
                if fam == "avar":
                    v = lagged(xa, 0) - 2 * lagged(xa, q) + lagged(xa, 2 * q)
                elif fam == "hvar":
                    v = lagged(xa, 0) - lagged(xa, 3 * q)
                    v -= 3 * (lagged(xa, q) - lagged(xa, 2 * q))
                else:
                    v = lagged(xa, 0) - lagged(xa, q)
                valid = None
                if not (self._g_last == 0).all():
                    valid = lagged(lv.g_at, 0) == lagged(lv.g_at, span)
                self.acc[(stat, m)].add(v, valid, fam == "std")
            if lv.bs is not None and b_new > b_old:
                self._update_mvar(lv, m, b_old, b_new)

    def _update_mvar(self, lv: _Level, m: int, b_old: int, b_new: int) -> None:
        s = lv.stride
        q = m // s
        bs = lv.bs
        assert bs is not None and lv.g_end is not None
        cd = lv.cd[m]
        lo = max(b_old, 2 * q)
        if lo < b_new:
            d = (bs.view(lo, b_new) - 2 * bs.view(lo - q, b_new - q)
                 + bs.view(lo - 2 * q, b_new - 2 * q))
            if cd.stop == 0:
                # CD is indexed from block 2q on; pad so absolute indices line up
                cd.start = cd.stop = 2 * q - 1
                cd.append(np.zeros((1, d.shape[1]), d.dtype))
            last = cd.view(cd.stop - 1, cd.stop)
            cd.append(np.cumsum(np.concatenate([last, d]), axis=0)[1:])
        lo = max(b_old, 3 * q - 1)
        if lo >= b_new:
            return
        e = cd.view(lo, b_new) - cd.view(lo - q, b_new - q)
        valid = None
        if not (self._g_last == 0).all():
            # window y_{b0 s+1} .. y_{(b0+3q) s - 1}, b0 = b - 3q + 1
            g_end = lv.g_end.view(lo, b_new)
            g_start = lv.g_at.view(lo - 3 * q + 1, b_new - 3 * q + 1)
            valid = g_end == g_start
        for stat in ("mdev", "tdev"):
            if stat in self.stats:
                self.acc[(stat, m)].add(e, valid, False)

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
        from imubench.stats.result import StatResult

        if self._nch is None:
            raise StatsError("snapshot() before any update()")
        per_channel: list[dict[str, StatResult]] = [{} for _ in range(self._nch)]
        n_freq = self.n_samples
        for stat in self.stats:
            try:
                allowed = set(int(m) for m in averaging_factors(stat, n_freq, self.taus,
                                                                self.tau0_s))
            except StatsError:
                allowed = set()
            ms = [m for m in self.ms if m in allowed]
            rows = [self._variance(stat, m) for m in ms]
            for ch in range(self._nch):
                var = np.array([r[0][ch] for r in rows])
                n = np.array([r[1][ch] for r in rows], dtype=np.int64)
                keep = n > 0
                mm = np.array(ms, dtype=np.int64)[keep]
                var = var[keep]
                n = n[keep]
                skipped = np.array([self.acc[(stat, m)].skipped[ch] for m in mm], np.int64)
                per_channel[ch][stat] = self._result(stat, mm, n, var, skipped, n_freq)
        return per_channel[0] if self._one_d else per_channel

    def _result(self, stat: str, m: np.ndarray, n: np.ndarray, var: np.ndarray,
                skipped: np.ndarray, n_freq: int) -> Any:
        from imubench.stats.confidence import confidence_arrays
        from imubench.stats.result import StatResult

        alpha = np.full(m.shape, 0 if self.alpha is None else self.alpha, dtype=np.int64)
        edf, lo, hi = confidence_arrays(stat, alpha, m, n_freq + 1, var, self.confidence)
        return StatResult(
            stat=stat, data_type="freq", rate_hz=self.rate_hz, tau_s=m * self.tau0_s,
            m=m, n=n, var=var, dev=np.sqrt(var), ci_low=lo, ci_high=hi, alpha=alpha,
            edf=edf, confidence=self.confidence, bias_corrected=False,
            bias_factor=np.ones(m.shape), drift=None, gaps=skipped,
            notes=(f"streaming memory={self.memory}",),
        )

    # -- persistence ------------------------------------------------------------------
    def save_state(self) -> bytes:
        """Serialise the whole engine state (config, sums, histories) to bytes."""
        if self._nch is None:
            raise StatsError("save_state() before any update()")
        arrays: dict[str, np.ndarray] = {
            "scale": self.scale, "ref": self._ref, "ref_set": self._ref_set,
            "x_last": self._x_last, "g_last": self._g_last, "n_gaps": self.n_gaps,
        }
        for (stat, m), acc in self.acc.items():
            for k, v in acc.state().items():
                arrays[f"acc/{stat}/{m}/{k}"] = v
        for s, lv in self.levels.items():
            arrays[f"lv/{s}/part_sum"] = lv.part_sum
            seqs = {"x_at": lv.x_at, "g_at": lv.g_at, "bs": lv.bs, "g_end": lv.g_end}
            seqs.update({f"cd{m}": q for m, q in lv.cd.items()})
            for name, seq in seqs.items():
                if seq is not None:
                    arrays[f"lv/{s}/{name}"] = seq.buf[: seq.stop - seq.start]
                    arrays[f"lv/{s}/{name}/start"] = np.array([seq.start, seq.stop])
        meta = {
            "rate_hz": self.rate_hz, "taus": self.taus, "stats": list(self.stats),
            "max_m": self.max_m, "memory": self.memory, "overlap": self.overlap,
            "confidence": self.confidence, "alpha": self.alpha, "n_samples": self.n_samples,
            "nch": self._nch, "one_d": self._one_d, "int": self._int,
        }
        buf = io.BytesIO()
        np.savez(buf, __meta__=np.frombuffer(json.dumps(meta).encode(), np.uint8), **arrays)
        return buf.getvalue()

    @classmethod
    def load_state(cls, data: bytes) -> StreamingAllan:
        """Rebuild an engine from :meth:`save_state` bytes; updates continue seamlessly."""
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            meta = json.loads(bytes(z["__meta__"]).decode())
            taus = meta["taus"]
            eng = cls(meta["rate_hz"], taus=taus, stats=meta["stats"],
                      max_tau_s=meta["max_m"] / meta["rate_hz"], memory=meta["memory"],
                      overlap=meta["overlap"], scale=z["scale"],
                      confidence=meta["confidence"], alpha=meta["alpha"])
            dtype = np.int64 if meta["int"] else np.float64
            eng._one_d = meta["one_d"]
            eng._setup(np.zeros((0, meta["nch"]), dtype))
            eng.n_samples = meta["n_samples"]
            eng._ref = z["ref"]
            eng._ref_set = z["ref_set"]
            eng._x_last = z["x_last"]
            eng._g_last = z["g_last"]
            eng.n_gaps = z["n_gaps"]
            for (stat, m), acc in eng.acc.items():
                for k in acc.__slots__:
                    setattr(acc, k, z[f"acc/{stat}/{m}/{k}"].copy())
            for s, lv in eng.levels.items():
                lv.part_sum = z[f"lv/{s}/part_sum"].copy()
                seqs = {"x_at": lv.x_at, "g_at": lv.g_at, "bs": lv.bs, "g_end": lv.g_end}
                seqs.update({f"cd{m}": q for m, q in lv.cd.items()})
                for name, seq in seqs.items():
                    if seq is None:
                        continue
                    rows = z[f"lv/{s}/{name}"]
                    start, stop = (int(v) for v in z[f"lv/{s}/{name}/start"])
                    seq.buf = np.zeros((max(2 * rows.shape[0], 1024), rows.shape[1]),
                                       rows.dtype)
                    seq.buf[: rows.shape[0]] = rows
                    seq.start, seq.stop = start, stop
        return eng
