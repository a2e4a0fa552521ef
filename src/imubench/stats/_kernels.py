"""Compiled (numba) inner loops of the batch statistics: one pass over the data, no temporaries.

Each function is the loop form of a formula documented in the module that calls it
(``allan``, ``total``, ``theo``, ``noise_id``); they are kept here so that the numerical
modules stay readable and the JIT cost is paid once (``cache=True`` stores the machine code
beside this file, so tests and later runs load it instead of compiling).

Gaps: ``gp`` is :attr:`PhaseData.gap_prefix` (an empty array when there are none) and
``goff`` its ``gap_end_offset``; a term over phase points a..b is used only when
``gp[b + goff] - gp[a] == 0``.

Sums use reassociation (``fastmath`` without the no-NaN/no-inf assumptions) so the compiler
keeps several partial sums in SIMD lanes, which is also better conditioned than one running
sum; the result agrees with a pairwise sum to a few ulps of the total.
"""

from __future__ import annotations

import numpy as np
from numba import njit

_FM = {"reassoc", "contract", "nsz", "arcp"}
PREFIX_REFRESH = 64  # subseq_meansq_sum: exact local prefix every this many starts
LAG1_CHUNK = 2048  # series points formed at a time by lag1_r1_diff (a 16 kB scratch)


@njit(cache=True, fastmath=_FM, nogil=True)
def sumsq_diff(
    x: np.ndarray, m: int, step: int, count: int, order: int, gp: np.ndarray, goff: int
) -> tuple[float, int]:
    """Sum over k < count of D_k^2, D_k the order-2 or order-3 difference at lag m.

    order 2: x[a] - 2 x[a+m] + x[a+2m] (Allan, SP 1065 eqs. (7), (11));
    order 3: x[a] - 3 x[a+m] + 3 x[a+2m] - x[a+3m] (Hadamard, eqs. (18), (19));
    a = k * step. Returns (sum of squares, number of gap-free terms).
    """
    s = 0.0
    valid = 0
    span = order * m
    if gp.size == 0:
        if step == 1:  # contiguous views: the compiler vectorises the loop (about 4x)
            x0, x1, x2 = x[:count], x[m : m + count], x[2 * m : 2 * m + count]
            if order == 2:
                for a in range(count):
                    d = x0[a] - 2.0 * x1[a] + x2[a]
                    s += d * d
            else:
                x3 = x[3 * m : 3 * m + count]
                for a in range(count):
                    d = x0[a] - 3.0 * x1[a] + 3.0 * x2[a] - x3[a]
                    s += d * d
        elif order == 2:
            for k in range(count):
                a = k * step
                d = x[a] - 2.0 * x[a + m] + x[a + 2 * m]
                s += d * d
        else:
            for k in range(count):
                a = k * step
                d = x[a] - 3.0 * x[a + m] + 3.0 * x[a + 2 * m] - x[a + 3 * m]
                s += d * d
        return s, count
    for k in range(count):
        a = k * step
        if gp[a + span + goff] - gp[a] != 0:
            continue
        if order == 2:
            d = x[a] - 2.0 * x[a + m] + x[a + 2 * m]
        else:
            d = x[a] - 3.0 * x[a + m] + 3.0 * x[a + 2 * m] - x[a + 3 * m]
        s += d * d
        valid += 1
    return s, valid


@njit(cache=True, fastmath=_FM, nogil=True)
def _d2(x: np.ndarray, m: int, i: int) -> float:
    return x[i + 2 * m] - 2.0 * x[i + m] + x[i]


@njit(cache=True, fastmath=_FM, nogil=True)
def _d3(x: np.ndarray, m: int, j: int) -> float:
    """w_{j+1} - w_j of :func:`mvar_sum`: d_{j+m} - d_j, a third difference at lag m."""
    return x[j + 3 * m] - 3.0 * x[j + 2 * m] + 3.0 * x[j + m] - x[j]


@njit(cache=True, fastmath=_FM, nogil=True)
def mvar_sum(x: np.ndarray, m: int, gp: np.ndarray, goff: int) -> tuple[float, int]:
    """sum_j w_j^2, w_j = sum_{i=j}^{j+m-1} x[i+2m] - 2 x[i+m] + x[i], j = 0..N-3m
    (SP 1065 eq. (15)).

    w slides by one term per j: w_{j+1} = w_j + (x[j+3m] - 3 x[j+2m] + 3 x[j+m] - x[j]),
    so each tau costs one pass; rounding grows like sqrt(N) ulps of a second difference,
    far below what a prefix sum of the phase would lose. The j range is cut into four
    segments slid side by side (independent dependency chains), each starting from its
    own exactly summed window.
    """
    n = x.size
    count = n - 3 * m + 1
    if gp.size != 0 or count < 64:
        w = 0.0
        for i in range(m):
            w += _d2(x, m, i)
        s = 0.0
        valid = 0
        for j in range(count):
            if gp.size == 0 or gp[j + 3 * m - 1 + goff] - gp[j] == 0:
                s += w * w
                valid += 1
            if j + 1 < count:
                w += _d3(x, m, j)
        return s, valid
    seg = count // 4
    w0 = 0.0
    w1 = 0.0
    w2 = 0.0
    w3 = 0.0
    for i in range(m):
        w0 += _d2(x, m, i)
        w1 += _d2(x, m, seg + i)
        w2 += _d2(x, m, 2 * seg + i)
        w3 += _d2(x, m, 3 * seg + i)
    s = 0.0
    for t in range(seg - 1):
        s += w0 * w0 + w1 * w1 + w2 * w2 + w3 * w3
        w0 += _d3(x, m, t)
        w1 += _d3(x, m, seg + t)
        w2 += _d3(x, m, 2 * seg + t)
        w3 += _d3(x, m, 3 * seg + t)
    s += w0 * w0 + w1 * w1 + w2 * w2 + w3 * w3
    for j in range(4 * seg - 1, count - 1):  # tail of the last segment
        w3 += _d3(x, m, j)
        s += w3 * w3
    return s, count


@njit(cache=True, fastmath=_FM, nogil=True)
def totvar_sum(xe: np.ndarray, n: int, m: int, gp: np.ndarray, goff: int) -> tuple[float, int]:
    """sum_{i=1}^{N-2} (x*[i-m] - 2 x*[i] + x*[i+m])^2 on TOTVAR's reflected phase x*
    (x[0] at index N-2 of ``xe``); with gaps, terms whose span clipped to 0..N-1 has one
    are skipped."""
    o = n - 2
    s = 0.0
    if gp.size == 0:
        c = n - 2
        x0 = xe[o + 1 - m : o + 1 - m + c]
        x1 = xe[o + 1 : o + 1 + c]
        x2 = xe[o + 1 + m : o + 1 + m + c]
        for i in range(c):
            d = x0[i] - 2.0 * x1[i] + x2[i]
            s += d * d
        return s, c
    valid = 0
    for i in range(1, n - 1):
        a = max(0, i - m)
        b = min(n - 1, i + m)
        if gp[b + goff] - gp[a] != 0:
            continue
        d = xe[o + i - m] - 2.0 * xe[o + i] + xe[o + i + m]
        s += d * d
        valid += 1
    return s, valid


@njit(cache=True, fastmath=_FM, nogil=True)
def _local_prefix(series: np.ndarray, s: int, n3: int, v: np.ndarray) -> None:
    """v[t] = sum_{u<t} (series[s+u] - series[s]), t = 0..n3, as four independent running
    sums (one per quarter, side by side) joined by their end values."""
    x0 = series[s]
    q = n3 // 4
    v[0] = 0.0
    if q < 8:
        for t in range(n3):
            v[t + 1] = v[t] + (series[s + t] - x0)
        return
    a0 = 0.0
    a1 = 0.0
    a2 = 0.0
    a3 = 0.0
    for t in range(q):
        a0 += series[s + t] - x0
        a1 += series[s + q + t] - x0
        a2 += series[s + 2 * q + t] - x0
        a3 += series[s + 3 * q + t] - x0
        v[t + 1] = a0
        v[q + t + 1] = a1
        v[2 * q + t + 1] = a2
        v[3 * q + t + 1] = a3
    for t in range(4 * q, n3):
        a3 += series[s + t] - x0
        v[t + 1] = a3
    o1 = v[q]
    o2 = o1 + v[2 * q]
    o3 = o2 + v[3 * q]
    for t in range(q + 1, 2 * q + 1):
        v[t] += o1
    for t in range(2 * q + 1, 3 * q + 1):
        v[t] += o2
    for t in range(3 * q + 1, n3 + 1):
        v[t] += o3


@njit(cache=True, fastmath=_FM, nogil=True)
def subseq_meansq_sum(series: np.ndarray, m: int, starts: np.ndarray) -> float:
    """sum over starts of mean_j z_j^2 / m^2 for MTOT / HTOT (see ``total._subseq_meansq_sum``).

    Per start s, v = series[s:s+3m] - series[s] (a constant cancels in z) with local prefix
    V, slope b = (mean of last h1 - mean of first h1) / h2 with h1 = floor(3m/2),
    h2 = ceil(3m/2); e = [rev v, v, rev v] - b * rel (rel the reflected index 0..3m-1) has
    the prefix C[k] = V[3m] - V[3m-k] (region A, k <= 3m), V[3m] + V[k-3m] (B, k <= 6m),
    3 V[3m] - V[9m-k] (C, k <= 9m), minus b R[k] (R the prefix of rel); then
    z_j = C[j+3m] - 3 C[j+2m] + 3 C[j+m] - C[j], j = 0..6m-1, and the start adds
    sum_j z_j^2 / (6m m^2). For j in [p m, (p+1) m) the term C[j + q m] lies in region
    (p+q) // 3, so each of the six sub-ranges is a branch-free loop over forward views
    (V and its reverse); the ramp part b * g_j, g_j the same difference of R, is shared.
    Half the z are evaluated: e is even about 3m - 1/2 and 6m - 1/2 and z applies a
    symmetric filter (window sums with weights 1, -2, 1), so z_j = z_{3m-j} and
    z_j = z_{9m-j}; each half period j' = 0 .. floor(3m/2) (j = j' and 3m + j') counts
    twice except j' = 0 (z_0 = z_{3m}, z_{3m} = z_{6m}) and j' = 3m/2 (its own mirror).
    O(m) per start, vectorised: V of start s + 1 comes from V of start s by the exact
    identity V_{s+1}[t] = V_s[t+1] - t (series[s+1] - series[s]) (one vectorised pass
    instead of a serial running sum), recomputed from scratch every
    :data:`PREFIX_REFRESH` starts and after a skipped start so rounding cannot build up.
    """
    n3 = 3 * m
    h1 = n3 // 2
    h2 = n3 - h1
    r = np.empty(3 * n3 + 1)  # prefix sum of rel on the 9m grid
    r[0] = 0.0
    for k in range(3 * n3):
        if k < n3:
            rel = n3 - 1 - k
        elif k < 2 * n3:
            rel = k - n3
        else:
            rel = 3 * n3 - 1 - k
        r[k + 1] = r[k] + rel
    g = np.empty(2 * n3)
    for j in range(2 * n3):
        g[j] = r[j + n3] - 3.0 * r[j + 2 * m] + 3.0 * r[j + m] - r[j]
    vv = np.empty((2, n3 + 1))  # row 0: V; row 1: its reverse, vv[1, t] = V[3m - t]
    v = vv[0]
    total = 0.0
    prev = -2
    for idx in range(starts.size):
        s = starts[idx]
        rv = vv[1]
        if s != prev + 1 or idx % PREFIX_REFRESH == 0:
            _local_prefix(series, s, n3, v)
            for t in range(n3 + 1):
                rv[t] = v[n3 - t]
        else:  # slide: V_s[t] = V_{s-1}[t+1] - t (series[s] - series[s-1]), exact identity
            dlt = series[s] - series[s - 1]
            for t in range(n3):
                nv = v[t + 1] - t * dlt
                v[t] = nv
                rv[n3 - t] = nv
            v[n3] = v[n3 - 1] + (series[s + n3 - 1] - series[s])
            rv[0] = v[n3]
        prev = s
        b = ((vv[0, n3] - vv[0, h2]) - vv[0, h1]) / (h1 * h2)
        v3 = vv[0, n3]
        acc = 0.0  # sum over the half periods j' = 0 .. floor(3m/2) (see docstring)
        ends = 0.0  # their weight-1 points: j' = 0 and, for even m, j' = 3m/2
        for p in (0, 1, 3, 4):
            c0, s0, w0 = _term(vv, v3, n3, m, p, 0, -1.0)
            c1, s1, w1 = _term(vv, v3, n3, m, p, 1, 3.0)
            c2, s2, w2 = _term(vv, v3, n3, m, p, 2, -3.0)
            c3, s3, w3 = _term(vv, v3, n3, m, p, 3, 1.0)
            const = c0 + c1 + c2 + c3
            gp_ = g[p * m : (p + 1) * m]
            hi = m if p % 3 == 0 else m // 2 + 1
            for i in range(hi):
                z = const + s0 * w0[i] + s1 * w1[i] + s2 * w2[i] + s3 * w3[i] - b * gp_[i]
                acc += z * z
            if p % 3 == 0 or m % 2 == 0:
                i = 0 if p % 3 == 0 else m // 2
                z = const + s0 * w0[i] + s1 * w1[i] + s2 * w2[i] + s3 * w3[i] - b * gp_[i]
                ends += z * z
        total += (2.0 * acc - ends) / (6.0 * m * m * m)
    return total


@njit(cache=True, fastmath=_FM, nogil=True)
def _term(
    vv: np.ndarray, v3: float, n3: int, m: int, p: int, q: int, coef: float
) -> tuple[float, float, np.ndarray]:
    """coef * C[j + q m] for j in [p m, (p+1) m) as (constant, sign, view of V or rev V)."""
    k0 = (p + q) * m
    reg = (p + q) // 3
    if reg == 0:  # C[k] = V[3m] - V[3m - k]
        return coef * v3, -coef, vv[1, k0 : k0 + m]
    if reg == 1:  # C[k] = V[3m] + V[k - 3m]
        return coef * v3, coef, vv[0, k0 - n3 : k0 - n3 + m]
    return coef * 3.0 * v3, -coef, vv[1, k0 - 2 * n3 : k0 - 2 * n3 + m]  # 3 V[3m] - V[9m-k]


@njit(cache=True, fastmath=_FM, nogil=True)
def theo1_direct(x: np.ndarray, ms: np.ndarray, a_lo: int, ok: np.ndarray) -> np.ndarray:
    """Per m in ``ms``: sum_{a=a_lo}^{m/2} (1/a) sum_i (x_i - x_{i+a} + x_{i+m} - x_{i+m-a})^2
    over rows i = 0..N-m-1 (SP 1065 eq. (31) with a = m/2 - d). ``ok`` is empty (all rows)
    or, with a single m, one flag per row (False: the span i..i+m has a gap). Squares of
    exact differences: no cancellation."""
    out = np.zeros(ms.size)
    for k in range(ms.size):
        m = ms[k]
        rows = x.size - m
        total = 0.0
        for a in range(a_lo, m // 2 + 1):
            s = 0.0
            x0, xa = x[:rows], x[a : a + rows]
            xm, xma = x[m : m + rows], x[m - a : m - a + rows]
            if ok.size == 0:
                for i in range(rows):
                    e = x0[i] - xa[i] + xm[i] - xma[i]
                    s += e * e
            else:
                for i in range(rows):
                    if ok[i]:
                        e = x0[i] - xa[i] + xm[i] - xma[i]
                        s += e * e
            total += s / a
        out[k] = total
    return out


@njit(cache=True, fastmath=_FM, nogil=True)
def lag1_r1(z: np.ndarray) -> tuple[float, int]:
    """(r1 without the (n-1)/n factor, n) of the finite values of z, two passes, NaN pairs
    skipped (Riley & Greenhall 2004, eq. 2)."""
    n = 0
    s = 0.0
    for v in z:
        if v == v:
            s += v
            n += 1
    if n == 0:
        return np.nan, 0
    num, den = _lag1_pair_sums(z, z.size, z.size, s / n, 0.0, 0.0)
    if den == 0.0:
        return np.nan, n
    return num / den, n


@njit(cache=True, fastmath=_FM, nogil=True)
def _lag1_pair_sums(buf: np.ndarray, cnt: int, ext: int, mean: float, num: float,
                    den: float) -> tuple[float, float]:
    """NaN-aware sums of :func:`lag1_r1` over points 0..cnt-1 of ``buf`` (``ext`` points
    valid, so pairs (j, j+1) with j + 1 < ext), added in order to the running ``num``
    (sum a_j a_{j+1}) and ``den`` (sum a_j^2), a = buf - mean; pairs or points with a NaN
    skipped."""
    for j in range(cnt):
        a = buf[j] - mean
        if a == a:
            den += a * a
            if j + 1 < ext:
                b = buf[j + 1] - mean
                if b == b:
                    num += a * b
    return num, den


@njit(cache=True, fastmath=_FM, nogil=True)
def diff_rows_windows(x: np.ndarray, a0: int, buf: np.ndarray, sel: np.ndarray) -> np.ndarray:
    """Fill row j of ``buf`` with D_a = x[:N-a] - x[a:] (a = a0 + j, zero beyond N - a) and
    return w[j, k] = (sum_{i<N-m} D_a(i)^2 + sum_{i=m-a}^{N-a-1} D_a(i)^2) / a for
    m = sel[k] (sorted, all >= 2a): the two window sums of Theo1's expanded square
    (``theo._theo1_fft_blocks``), each the total minus a short head or tail sum."""
    nb = buf.shape[0]
    n = x.size
    out = np.empty((nb, sel.size))
    for j in range(nb):
        a = a0 + j
        row = buf[j]
        tot = 0.0
        for i in range(n - a):
            d = x[i] - x[i + a]
            row[i] = d
            tot += d * d
        row[n - a :] = 0.0
        head = 0.0
        tail = 0.0
        h = 0
        for k in range(sel.size):
            lim = sel[k] - a  # head and tail lengths m - a
            while h < lim:
                head += row[h] * row[h]
                t = row[n - a - 1 - h]
                tail += t * t
                h += 1
            out[j, k] = ((tot - tail) + (tot - head)) / a
    return out


@njit(cache=True, fastmath=_FM, nogil=True)
def shifted_power_sum(
    f: np.ndarray, a0: int, wr: np.ndarray, wi: np.ndarray, er: np.ndarray, ei: np.ndarray,
    out: np.ndarray,
) -> None:
    """out[k] = sum_j |f[j, k]|^2 / a_j * exp(-2 pi i k a_j / P), a_j = a0 + j.

    The spectrum of sum_j R_j(l - a_j) / a_j, R_j the autocorrelation whose spectrum is
    |f[j]|^2 (``theo._theo1_fft_blocks``). (er, ei) hold exp(-2 pi i k a0 / P) on entry
    and are advanced by (wr, wi) = exp(-2 pi i k / P) once per j, so consecutive blocks
    continue the rotation (rounding drift ~ sqrt(a) ulps of a unit phasor)."""
    nb, nk = f.shape
    for k in range(nk):
        cr = er[k]
        ci = ei[k]
        sr = 0.0
        si = 0.0
        for j in range(nb):
            z = f[j, k]
            pw = (z.real * z.real + z.imag * z.imag) / (a0 + j)
            sr += pw * cr
            si += pw * ci
            cr, ci = cr * wr[k] - ci * wi[k], cr * wi[k] + ci * wr[k]
        er[k] = cr
        ei[k] = ci
        out[k] = complex(sr, si)


@njit(cache=True, fastmath=_FM, nogil=True)
def _z0(x: np.ndarray, m: int, freq: bool, k: int) -> float:
    """Point k of the series at tau: x[k m] (phase) or (x[(k+1) m] - x[k m]) / m (freq)."""
    if freq:
        return (x[(k + 1) * m] - x[k * m]) / m
    return x[k * m]


@njit(cache=True, fastmath=_FM, nogil=True)
def points_at_tau(x: np.ndarray, m: int, freq: bool, limit: int) -> int:
    """Finite points of the series at tau (phase decimated by m, or freq averages by m),
    counted until ``limit`` is reached (the caller only asks whether there are enough)."""
    k0 = (x.size - 1) // m + 1
    n = 0
    for k in range(k0 - 1 if freq else k0):
        v = _z0(x, m, freq, k)
        n += v - v == 0.0  # False for NaN and +-inf
        if n >= limit:
            break
    return n


@njit(cache=True, fastmath=_FM, nogil=True)
def _fill_chunk(
    x: np.ndarray, m: int, freq: bool, d: int, k0: int, cnt: int, buf: np.ndarray
) -> None:
    """buf[:cnt] = points k0 .. k0+cnt-1 of the d-times differenced series at tau, by
    in-place differencing in the order of repeated ``np.diff`` (the same values, bit for
    bit)."""
    for j in range(cnt + d):
        buf[j] = _z0(x, m, freq, k0 + j)
    for level in range(d):
        for j in range(cnt + d - level - 1):
            buf[j] = buf[j + 1] - buf[j]


@njit(cache=True, fastmath=_FM, nogil=True)
def lag1_r1_diff(x: np.ndarray, m: int, freq: bool, d: int) -> tuple[float, int]:
    """:func:`lag1_r1` of the series at tau differenced d times, formed from the phase
    chunk by chunk (strided reads into a fixed scratch, no N-sized temporaries): the lag-1
    noise identification of ``noise_id.lag1_alpha`` in two fused passes per order d."""
    k0 = (x.size - 1) // m + 1
    kz = (k0 - 1 if freq else k0) - d
    if kz <= 0:
        return np.nan, 0
    buf = np.empty(LAG1_CHUNK + 4)
    n = 0
    s = 0.0
    for c0 in range(0, kz, LAG1_CHUNK):
        cnt = min(LAG1_CHUNK, kz - c0)
        _fill_chunk(x, m, freq, d, c0, cnt, buf)
        for j in range(cnt):
            v = buf[j]
            ok = v == v
            s += v if ok else 0.0
            n += ok
    if n == 0:
        return np.nan, 0
    mean = s / n
    num = 0.0
    den = 0.0
    for c0 in range(0, kz, LAG1_CHUNK):
        cnt = min(LAG1_CHUNK, kz - c0)
        ext = min(cnt + 1, kz - c0)  # one point of overlap for the last pair of the chunk
        _fill_chunk(x, m, freq, d, c0, ext, buf)
        if n == kz:  # no gaps: branch-free sums
            for j in range(cnt):
                a = buf[j] - mean
                den += a * a
            for j in range(ext - 1):
                num += (buf[j] - mean) * (buf[j + 1] - mean)
        else:
            num, den = _lag1_pair_sums(buf, cnt, ext, mean, num, den)
    if den == 0.0:
        return np.nan, n
    return num / den, n
