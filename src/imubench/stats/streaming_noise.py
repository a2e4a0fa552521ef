"""Streaming noise identification: the batch rule of :mod:`imubench.stats.noise_id` from
bounded running sums per averaging factor.

What the batch statistics do for rate data (``compute(..., data_type="freq")`` with
``alpha=None``; see ``noise_id.identify_alpha``): at averaging factor m the series at tau
is the non-overlapping m-averages of the rate, ``z_k = (x_{(k+1)m} - x_{km}) / m`` from the
phase ``x`` (the cumulative rate sum), with ``x_p`` unknown (NaN) when rate sample
``y_p`` (1-based) is a gap.

* Lag-1 ACF (Riley & Greenhall 2004; NIST SP 1065 section 5.6), used when at least
  ``LAG1_MIN_POINTS`` finite z exist: for d = 0, 1, ... (z differenced d times)
  ``r1 = (n-1)/n * sum_pairs (z_i - zbar)(z_{i+1} - zbar) / sum (z_i - zbar)^2`` with
  ``zbar`` the mean of the n finite values and the pair sum over pairs of finite values;
  ``delta = r1 / (1 + r1)``; stop when ``delta < 0.25`` or ``d = dmax`` (2 for the Allan
  family, 3 for the Hadamard family); ``alpha = -round(2 delta) - 2 d``.
  Expanding the centred sums, everything needed per difference order d is seven running
  sums: n, S = sum z, S2 = sum z^2, and over finite pairs n_p, S_l = sum z_i,
  S_r = sum z_{i+1}, S_lag = sum z_i z_{i+1}:
  ``num = S_lag - zbar (S_l + S_r) + n_p zbar^2``, ``den = S2 - n zbar^2``.
  Order 0 is summed about a shift (its first finite value) so that a large mean (a
  gyro's bias) does not cancel digits away; the centred sums are shift-invariant.
* Barnes B1 ratio with R(n) (see ``noise_id.b1_alpha``) otherwise:
  ``B1 = var_ddof1(z) / AVAR``, ``AVAR = 0.5 <(z_{k+1} - z_k)^2>`` (the order-1 sums),
  compared with ``noise_id.b1_expected(analysis_terms(stat, m, N), mu)``; mu = -2 is split
  into white/flicker PM by ``R(n) = MVAR / AVAR`` against ``noise_id.rn_expected``.
  The MVAR comes from the engine (an exact MVAR with the noise-ID gap rule, kept only
  while this m can still fall back to B1, i.e. fewer than 30 averages seen).

The state per averaging factor is 4 orders x 7 sums (+ compensation) and the last 5
phase values per channel: nothing grows with the recording.
"""

from __future__ import annotations

import math

import numpy as np

from imubench.errors import StatsError
from imubench.stats._stream_kernels import noise_sums_finite
from imubench.stats.noise_id import (
    alpha_range,
    analysis_terms,
    b1_expected,
    rn_expected,
)

#: Highest difference order of the m-averages kept (dmax of the Hadamard family).
MAX_ORDER = 3
_TAIL = MAX_ORDER + 2  # phase values needed for one new pair at the highest order
# indices of the sums: seven of the m-averages u (count, sum, sum of squares, pair count,
# left/right pair sums, lag products) and seven more with the gap fractions g
_N, _S, _S2, _NP, _SL, _SR, _SLAG = range(7)
_G, _UG, _GG, _GL, _GR, _UGLAG, _GGLAG = range(7, 14)
_NSUMS = 14
ALPHA_UNKNOWN = -99


def concat_f(parts: list[np.ndarray], dtype: np.dtype | type | None = None) -> np.ndarray:
    """Row-wise concatenation into a Fortran-ordered (column-contiguous) array.

    The engine keeps (samples x channels) arrays column-contiguous: numpy's reductions,
    running sums and einsum along the sample axis are 4-6x faster that way for a few
    channels than on C-ordered arrays (np.concatenate would return C order)."""
    out = np.empty((sum(p.shape[0] for p in parts), parts[0].shape[1]),
                   dtype or np.result_type(*parts), order="F")
    i = 0
    for p in parts:
        out[i:i + p.shape[0]] = p
        i += p.shape[0]
    return out


class RunningNoiseSums:
    """Running lag-1 / B1 sums of the m-averages of one averaging factor, per channel.

    The batch series at tau is ``w_k = u_k - c (1 - g_k)`` with ``u_k`` the m-average of
    ``y - y_ref`` (gap samples counted as 0), ``g_k`` the fraction of gap samples in the
    window and ``c = ybar - y_ref`` (the batch subtracts the mean of all valid samples
    before it zeroes the gaps). ``c`` is known only at snapshot time, so the sums of u
    and of g (and their products) are kept apart and combined by :meth:`_combined`;
    the constant ``-c`` drops out of every centred sum. Without gaps g = 0 and only the
    seven u sums are ever non-zero.
    """

    __slots__ = ("comp", "gtail", "m", "orders", "shift", "shift_set", "sums", "tail",
                 "tail_n")

    def __init__(self, m: int, nch: int, orders: int = MAX_ORDER + 1) -> None:
        self.m = int(m)
        self.orders = orders  # difference orders kept: dmax + 1
        self.sums = np.zeros((MAX_ORDER + 1, _NSUMS, nch))
        self.comp = np.zeros((MAX_ORDER + 1, _NSUMS, nch))
        self.tail = np.zeros((_TAIL, nch))
        self.gtail = np.zeros((_TAIL, nch))
        self.tail_n = 1  # x_0 = 0 at position 0 (never a gap)
        self.shift = np.zeros(nch)
        self.shift_set = np.zeros(nch, bool)

    def add(self, x_new: np.ndarray, g_new: np.ndarray | None = None) -> None:
        """Add phase values at the next multiples of m, shape (k, nch) (NaN = unknown),
        with the cumulative gap counts G there (None: no gap since the last call)."""
        k = x_new.shape[0]
        if k == 0:
            return
        cnt = self.tail_n
        buf = concat_f([self.tail[_TAIL - cnt:], x_new], np.float64)
        z = np.diff(buf, axis=0)
        z /= self.m
        gbuf = None
        if g_new is not None:
            gbuf = concat_f([self.gtail[_TAIL - cnt:], g_new], np.float64)
        elif self.gtail[-1].any():
            gbuf = concat_f([self.gtail[_TAIL - cnt:],
                             np.broadcast_to(self.gtail[-1], x_new.shape)], np.float64)
        h = None
        if gbuf is not None:
            h = np.diff(gbuf, axis=0)
            h /= self.m
            if not h.any():
                h = None
        add = np.zeros_like(self.sums)
        finite = not np.isnan(z).any()
        for d in range(self.orders):
            if d:
                z = z[1:] - z[:-1]
                if h is not None:
                    h = h[1:] - h[:-1]
            if z.shape[0] == 0:
                break
            j0 = max(0, cnt - d - 1)  # first element whose newest phase point is new
            if d == 0:
                if not self.shift_set.all():
                    self._set_shift(z[j0:])
                z -= self.shift  # differences of z (the higher orders) are unchanged
            if finite and h is None:
                self._add_finite(add[d], z, j0)
            else:
                self._add_masked(add[d], z, h, j0)
        self._accumulate(add)
        n_keep = min(_TAIL, buf.shape[0])
        self.tail[_TAIL - n_keep:] = buf[buf.shape[0] - n_keep:]
        if gbuf is not None:
            self.gtail[_TAIL - n_keep:] = gbuf[gbuf.shape[0] - n_keep:]
        self.tail_n = n_keep

    def add_strided(self, x: np.ndarray, i0: int, scratch: np.ndarray) -> None:
        """``add(x[i0::m])`` for phase rows x (int64 or float64, (rows, nch)) free of gaps
        and unknown values, read in place by a compiled kernel
        (``_stream_kernels.noise_sums_finite``); ``scratch``: float64, >= 5 + rows / m."""
        xs = x[i0::self.m]
        if not self.shift_set.all() or self.gtail[-1].any() or xs.shape[0] == 0:
            self.add(xs.astype(np.float64))  # first values (shift) or after a gap
            return
        add = np.zeros_like(self.sums)
        noise_sums_finite(x, i0, self.m, self.tail, self.tail_n, self.orders, self.shift,
                          add, scratch)
        self._accumulate(add)
        buf = np.concatenate([self.tail[_TAIL - self.tail_n:], xs[-_TAIL:]])
        n_keep = min(_TAIL, buf.shape[0])
        self.tail[_TAIL - n_keep:] = buf[buf.shape[0] - n_keep:]
        self.tail_n = n_keep

    def _accumulate(self, add: np.ndarray) -> None:
        """sums += add, Neumaier-compensated (the compensation in ``comp``)."""
        t = self.sums + add
        big = np.abs(self.sums) >= np.abs(add)
        self.comp += np.where(big, (self.sums - t) + add, (add - t) + self.sums)
        self.sums = t

    @staticmethod
    def _add_finite(out: np.ndarray, z: np.ndarray, j0: int) -> None:
        """The u sums of the new elements ``w = z[j0:]``, nothing NaN, no gap (einsum:
        ``sum(axis=0)`` of a narrow C-ordered array is slow, BLAS threads slower)."""
        w = z[j0:]
        k = w.shape[0]
        out[_N] = k
        out[_S] = np.einsum("ij->j", w)
        out[_S2] = np.einsum("ij,ij->j", w, w)
        if j0 == 0:  # pairs (w_i, w_{i+1}) inside w
            if k > 1:
                out[_NP] = k - 1
                out[_SL] = out[_S] - w[-1]
                out[_SR] = out[_S] - w[0]
                out[_SLAG] = np.einsum("ij,ij->j", w[:-1], w[1:])
        else:  # every new element pairs with its predecessor z[j-1]
            a = z[j0 - 1:-1]
            out[_NP] = k
            out[_SL] = out[_S] - w[-1] + a[0]
            out[_SR] = out[_S]
            out[_SLAG] = np.einsum("ij,ij->j", a, w)

    @staticmethod
    def _add_masked(out: np.ndarray, z: np.ndarray, h: np.ndarray | None, j0: int) -> None:
        """All sums of the new elements, skipping NaN elements and pairs touching one."""
        def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
            return np.einsum("ij,ij->j", a, b)

        fin_all = np.isfinite(z)
        z0 = np.where(fin_all, z, 0.0)
        h0 = None if h is None else np.where(fin_all, h, 0.0)
        fin = fin_all[j0:]
        w = z0[j0:]
        out[_N] = np.count_nonzero(fin, axis=0)
        out[_S] = np.einsum("ij->j", w)
        out[_S2] = dot(w, w)
        lo = max(j0, 1)  # new elements that have a predecessor
        both = fin_all[lo - 1:-1] & fin_all[lo:]
        a = np.where(both, z0[lo - 1:-1], 0.0)
        b = np.where(both, z0[lo:], 0.0)
        out[_NP] = np.count_nonzero(both, axis=0)
        out[_SL] = np.einsum("ij->j", a)
        out[_SR] = np.einsum("ij->j", b)
        out[_SLAG] = dot(a, b)
        if h0 is None:
            return
        v = h0[j0:]
        ga = np.where(both, h0[lo - 1:-1], 0.0)
        gb = np.where(both, h0[lo:], 0.0)
        out[_G] = np.einsum("ij->j", v)
        out[_UG] = dot(w, v)
        out[_GG] = dot(v, v)
        out[_GL] = np.einsum("ij->j", ga)
        out[_GR] = np.einsum("ij->j", gb)
        out[_UGLAG] = dot(a, gb) + dot(ga, b)
        out[_GGLAG] = dot(ga, gb)

    def _set_shift(self, w: np.ndarray) -> None:
        for j in np.nonzero(~self.shift_set)[0]:
            ok = np.isfinite(w[:, j])
            if ok.any():
                self.shift[j] = w[np.argmax(ok), j]
                self.shift_set[j] = True

    def points(self) -> np.ndarray:
        """Finite m-averages seen so far, per channel (the 'points at tau')."""
        return (self.sums[0, _N] + self.comp[0, _N]).astype(np.int64)

    # -- identification ---------------------------------------------------------------
    def _combined(self, d: int, ch: int, c: float) -> np.ndarray:
        """The seven sums of the batch series ``w = u + c g`` at difference order d."""
        t = self.sums[d, :, ch] + self.comp[d, :, ch]
        if not c or not t[_G:].any():
            return t[:_G]
        s = t[:_G].copy()
        s[_S] += c * t[_G]
        s[_S2] += 2.0 * c * t[_UG] + c * c * t[_GG]
        s[_SL] += c * t[_GL]
        s[_SR] += c * t[_GR]
        s[_SLAG] += c * t[_UGLAG] + c * c * t[_GGLAG]
        return s

    def _lag1_r1(self, d: int, ch: int, c: float) -> float:
        s = self._combined(d, ch, c)
        n = s[_N]
        if n < 3:
            raise StatsError(f"lag-1 ACF needs at least 3 finite points, got {int(n)}")
        zbar = s[_S] / n
        den = s[_S2] - n * zbar * zbar
        if den == 0.0:
            raise StatsError("lag-1 ACF: the series is constant (zero variance)")
        num = s[_SLAG] - zbar * (s[_SL] + s[_SR]) + s[_NP] * zbar * zbar
        return float(num / den) * (n - 1) / n

    def lag1_alpha(self, ch: int, dmax: int, c: float = 0.0) -> int:
        """``noise_id.lag1_alpha(x, m, "freq", dmin=0, dmax)`` from the running sums;
        ``c`` = mean of the valid samples minus the engine's reference sample."""
        d = 0
        while True:
            r1 = self._lag1_r1(d, ch, c)
            delta = r1 / (1.0 + r1)
            if delta < 0.25 or d >= dmax:
                return int(-round(2.0 * delta) - 2 * d)
            d += 1

    def avar(self, ch: int, c: float = 0.0) -> float:
        """0.5 <(z_{k+1} - z_k)^2> over finite pairs of m-averages (B1's AVAR)."""
        s1 = self._combined(1, ch, c)
        if s1[_N] < 1:
            raise StatsError("B1 ratio: no finite pair of frequency averages")
        return float(0.5 * s1[_S2] / s1[_N])

    def b1_alpha(self, ch: int, n_terms: int, mvar: float | None, c: float = 0.0) -> int:
        """``noise_id.b1_alpha(x, m, "freq", n_terms)`` from the running sums.

        ``mvar``: the (unscaled) MVAR at m with the noise-ID gap rule, or None where it
        cannot be formed (the batch then returns white PM).
        """
        s0 = self._combined(0, ch, c)
        k = int(s0[_N])
        if k < 2:
            raise StatsError(f"B1 noise identification at m={self.m}: only {k} averages")
        avar = self.avar(ch, c)
        if avar <= 0.0:
            raise StatsError(f"B1 noise identification at m={self.m}: zero Allan variance")
        var = (s0[_S2] - s0[_S] * s0[_S] / k) / (k - 1)
        b1 = float(var) / avar
        mus = (2, 1, 0, -1, -2)
        n_exp = max(int(n_terms), 2)
        expected = [b1_expected(n_exp, mu) for mu in mus]
        for i, mu in enumerate(mus[:-1]):
            if b1 > math.sqrt(expected[i] * expected[i + 1]):
                return -mu - 1
        if mvar is None or not np.isfinite(mvar):
            return 2
        rn = mvar / avar
        return 1 if rn > math.sqrt(rn_expected(self.m, 2) * rn_expected(self.m, 1)) else 2

    def b1_identify(self, ch: int, var_stat: str, n_phase: int, mvar: float | None,
                    c: float = 0.0) -> int:
        """The B1 branch of ``noise_id.identify_alpha(x, m, "freq", var_stat)`` (fewer than
        LAG1_MIN_POINTS points at m), clipped to the statistic's range; -99 where it fails."""
        lo, hi = alpha_range(var_stat)
        try:
            alpha = self.b1_alpha(ch, analysis_terms(var_stat, self.m, n_phase), mvar, c)
        except StatsError:
            return ALPHA_UNKNOWN
        return int(min(max(alpha, lo), hi))

    # -- persistence ------------------------------------------------------------------
    def state(self) -> dict[str, np.ndarray]:
        return {
            "sums": self.sums,
            "comp": self.comp,
            "tail": self.tail,
            "gtail": self.gtail,
            "tail_n": np.array([self.tail_n]),
            "shift": self.shift,
            "shift_set": self.shift_set,
        }

    def load(self, arrays: dict[str, np.ndarray]) -> None:
        self.sums = arrays["sums"].copy()
        self.comp = arrays["comp"].copy()
        self.tail = arrays["tail"].copy()
        self.gtail = arrays["gtail"].copy()
        self.tail_n = int(arrays["tail_n"][0])
        self.shift = arrays["shift"].copy()
        self.shift_set = arrays["shift_set"].copy()
