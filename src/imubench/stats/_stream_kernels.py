"""Compiled (numba) inner loops of the streaming engine (:mod:`imubench.stats.streaming`).

One call updates every averaging factor of one decimation level, for every channel, from
the level's history buffers, adding straight into the engine's accumulator tables: no
per-chunk term arrays, no dtype copies. The formulas are the module docstring's of
``streaming`` (NIST SP 1065 eqs. 10, 11, 14, 17 on the cumulative rate sum X):

* ``D_i = X_i - 2 X_{i-q} + X_{i-2q}`` (AVAR / OAVAR terms),
* ``H_i = X_i - 3 X_{i-q} + 3 X_{i-2q} - X_{i-3q}`` (HVAR / OHVAR terms),
* ``E_b = sum_{r=0}^{q-1} d_{b-r}`` with d the second differences of the block sums
  (MVAR terms; at stride 1 the block sums are X and d = D), formed as a moving sum
  ``E_b = E_{b-1} + d_b - d_{b-q}`` within one call (E at the call's first b is summed
  from its q terms); each d is evaluated the same way when it enters and when it leaves,
  so a float history's rounding of d does not accumulate along the chunk.

Exactness: integer histories (raw counts) form every term in int64 (exact), square it in
float64 and add blocks of at most ``BLOCK`` squares with a plain (SIMD-reassociated) sum;
each block sum is added to the table with Neumaier compensation (Neumaier 1974) in a
function compiled *without* fastmath, so the compensation is not optimised away. A
block's rounding is at most BLOCK * 2^-53 relative (typically sqrt(BLOCK) * 2^-53), the
running total's a few ulps whatever the number of chunks. Float histories use the same
sums.

Tables (rows = (statistic, m) accumulators, columns = channels): ``sum2``/``comp``
(float64 sum of squares and its compensation), ``cnt`` (terms used) and ``skip``
(terms skipped because their window holds a gap), all C-ordered (rows, channels).

Gaps: ``g`` is the level's cumulative gap count G at the same indices as X (an array of
zero rows when no gap was ever seen); a term spanning indices i - span .. i is used only
when ``G_i == G_{i-span}``. G never decreases, so runs of terms that all hold a gap, or
none, are found by O(1) tests or a bisection; only the terms near a gap's edges are
tested one by one.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit

_FM = {"reassoc", "contract", "nsz", "arcp"}
#: squares summed plainly before one compensated addition to the table
BLOCK = 4096
#: families of the level kernel, columns of its ``rows`` table
FAM_OAVAR, FAM_AVAR, FAM_OHVAR, FAM_HVAR = range(4)


@njit(cache=True, nogil=True)
def _neumaier_add(sum2: np.ndarray, comp: np.ndarray, row: int, ch: int, v: float) -> None:
    """sum2[row, ch] += v with the Neumaier compensation kept in comp (no fastmath)."""
    s = sum2[row, ch]
    t = s + v
    if abs(s) >= abs(v):
        comp[row, ch] += (s - t) + v
    else:
        comp[row, ch] += (v - t) + s
    sum2[row, ch] = t


@njit(cache=True, fastmath=_FM, nogil=True)
def _block_sumsq(xc: np.ndarray, a: int, b: int, q: int, step: int,
                 order: int) -> float:
    """Sum of squares of the order-2 (D) or order-3 (H) differences at lag q ending at
    buffer rows a, a+step, ... < b (no gaps)."""
    s = 0.0
    if step == 1:  # contiguous views: the compiler vectorises the loop
        if order == 2:
            x0, x1, x2 = xc[a:b], xc[a - q:b - q], xc[a - 2 * q:b - 2 * q]
            for k in range(b - a):
                d = float(x0[k] - 2 * x1[k] + x2[k])
                s += d * d
        else:
            x0, x1 = xc[a:b], xc[a - q:b - q]
            x2, x3 = xc[a - 2 * q:b - 2 * q], xc[a - 3 * q:b - 3 * q]
            for k in range(b - a):
                d = float(x0[k] - 3 * x1[k] + 3 * x2[k] - x3[k])
                s += d * d
        return s
    for i in range(a, b, step):
        if order == 2:
            d = float(xc[i] - 2 * xc[i - q] + xc[i - 2 * q])
        else:
            d = float(xc[i] - 3 * xc[i - q] + 3 * xc[i - 2 * q] - xc[i - 3 * q])
        s += d * d
    return s


@njit(cache=True, fastmath=_FM, nogil=True)
def _block_sumsq_g(xc: np.ndarray, gc: np.ndarray, a: int, b: int, q: int, step: int,
                   order: int, goff: int, stride: int) -> tuple[float, int]:
    """``_block_sumsq`` with gaps: gc[i + goff] is G at buffer row i of xc, whose indices
    are ``stride`` samples apart.

    G never decreases, so O(1) tests settle most blocks: no gap from the first term's
    window start to the last term (``G_last == G_{a-span}``: every term is used, summed
    as ``_block_sumsq`` does); or no term used, when a gap lies in every term's window
    (``G_a > G_{last-span}``) or every sample after index a-1 up to the last term is a
    gap (``G_last - G_{a-1} = stride (last - a + 1)``: each term holds one at its end).
    Only a block near a gap edge is tested term by term; before this, a record with one
    gap paid that test on every later term (5x the time per sample at 617 averaging
    factors, eight statistics)."""
    span = order * q
    last = a + (b - 1 - a) // step * step
    if gc[last + goff] == gc[a + goff - span]:
        return _block_sumsq(xc, a, b, q, step, order), (last - a) // step + 1
    if (gc[a + goff] > gc[last + goff - span]
            or gc[last + goff] - gc[a + goff - 1] == stride * (last - a + 1)):
        return 0.0, 0
    s = 0.0
    n = 0
    for i in range(a, b, step):
        if gc[i + goff] != gc[i + goff - span]:
            continue
        if order == 2:
            d = float(xc[i] - 2 * xc[i - q] + xc[i - 2 * q])
        else:
            d = float(xc[i] - 3 * xc[i - q] + 3 * xc[i - 2 * q] - xc[i - 3 * q])
        s += d * d
        n += 1
    return s, n


@njit(cache=True, nogil=True)
def level_sums(x: np.ndarray, x0: int, g: np.ndarray, g0: int, i_old: int, i_new: int,
               qs: np.ndarray, rows: np.ndarray, sum2: np.ndarray, comp: np.ndarray,
               cnt: np.ndarray, skip: np.ndarray, stride: int) -> None:
    """Add the AVAR/OAVAR/HVAR/OHVAR terms at level indices i_old..i_new-1.

    ``x`` (buffer rows, channels; Fortran order) holds X at level indices x0, x0+1, ...
    (``stride`` samples apart);
    ``g`` likewise from g0 (zero rows: no gap seen). ``qs[j]`` is the j-th m over the
    level's stride; ``rows[j, FAM_*]`` the table row of that family at that m (-1: not
    wanted). Non-overlapping families use the indices that are multiples of q.
    """
    nch = x.shape[1]
    has_g = g.shape[0] > 0
    for j in range(qs.size):
        q = qs[j]
        for fam in range(4):
            row = rows[j, fam]
            if row < 0:
                continue
            order = 2 if fam <= FAM_AVAR else 3
            overlapping = fam % 2 == 0  # FAM_OAVAR or FAM_OHVAR
            lo = max(i_old, order * q)
            step = 1
            if not overlapping:
                lo = -(-lo // q) * q
                step = q
            if lo >= i_new:
                continue
            total = (i_new - 1 - lo) // step + 1
            for ch in range(nch):
                xc = x[:, ch]
                used = 0
                a = lo
                while a < i_new:
                    b = min(a + BLOCK * step, i_new)
                    if has_g:
                        s, n = _block_sumsq_g(xc, g[:, ch], a - x0, b - x0, q, step, order,
                                              x0 - g0, stride)
                    else:
                        s = _block_sumsq(xc, a - x0, b - x0, q, step, order)
                        n = (b - 1 - a) // step + 1
                    _neumaier_add(sum2, comp, row, ch, s)
                    used += n
                    a = b
                cnt[row, ch] += used
                skip[row, ch] += total - used


@njit(cache=True, fastmath=_FM, nogil=True)
def _sumsq(v: np.ndarray, a: int, b: int) -> float:
    """Sum of v[a:b]**2 (vectorised)."""
    s = 0.0
    for k in range(a, b):
        s += v[k] * v[k]
    return s


@njit(cache=True, nogil=True)
def _add_blocks(v: np.ndarray, n: int, rows: np.ndarray, ch: int, sum2: np.ndarray,
                comp: np.ndarray, cnt: np.ndarray) -> None:
    """Add sum(v[:n]**2) (in blocks of BLOCK) and n terms to every row >= 0 of ``rows``."""
    a = 0
    while a < n:
        b = min(a + BLOCK, n)
        s = _sumsq(v, a, b)
        for row in rows:
            if row >= 0:
                _neumaier_add(sum2, comp, row, ch, s)
        a = b
    for row in rows:
        if row >= 0:
            cnt[row, ch] += n


@njit(cache=True, nogil=True)
def _move_sumsq(x0: np.ndarray, x1: np.ndarray, x2: np.ndarray, x3: np.ndarray, e: Any,
                a: int, b: int) -> tuple[Any, float]:
    """Move E over k = a..b-1 (``E += d_k - d_{k-q}``, the lagged views x0..x3) and sum
    the squares of the moved values: (E after, sum). Four partial sums hide the add
    latency; no fastmath, so E's own additions keep their order."""
    s0 = s1 = s2 = s3 = 0.0
    k = a
    while k + 4 <= b:
        e += (x0[k] - 2 * x1[k] + x2[k]) - (x1[k] - 2 * x2[k] + x3[k])
        v = float(e)
        s0 += v * v
        e += (x0[k + 1] - 2 * x1[k + 1] + x2[k + 1]) - (x1[k + 1] - 2 * x2[k + 1] + x3[k + 1])
        v = float(e)
        s1 += v * v
        e += (x0[k + 2] - 2 * x1[k + 2] + x2[k + 2]) - (x1[k + 2] - 2 * x2[k + 2] + x3[k + 2])
        v = float(e)
        s2 += v * v
        e += (x0[k + 3] - 2 * x1[k + 3] + x2[k + 3]) - (x1[k + 3] - 2 * x2[k + 3] + x3[k + 3])
        v = float(e)
        s3 += v * v
        k += 4
    while k < b:
        e += (x0[k] - 2 * x1[k] + x2[k]) - (x1[k] - 2 * x2[k] + x3[k])
        v = float(e)
        s0 += v * v
        k += 1
    return e, (s0 + s1) + (s2 + s3)


@njit(cache=True, nogil=True)
def mvar_sums(bs: np.ndarray, bs0: int, ga: np.ndarray, ga0: int, ge: np.ndarray, ge0: int,
              b_old: int, b_new: int, q: int, unit_stride: bool, rows: np.ndarray,
              noise_row: int, sum2: np.ndarray, comp: np.ndarray, cnt: np.ndarray,
              skip: np.ndarray, scratch: np.ndarray, e_prev: np.ndarray, age: np.ndarray,
              max_age: int, stride: int) -> None:
    """Add the MVAR terms E_b, b = max(b_old, 3q-1)..b_new-1, to the table rows ``rows``
    (MDEV, TDEV; -1 skipped) and, with the noise-ID gap rule, to ``noise_row`` (-1: none).

    ``bs``: block sums (stride 1: X) from block index bs0; ``ga``: G at the block starts
    (from ga0), ``ge``: G at the block ends (from ge0), both zero rows without gaps.
    Term b spans blocks b-3q+1..b; it is skipped when a gap lies in them
    (``G_end[b] != G_start[b-3q+1]``); the noise-ID rule at stride 1 also rejects the
    sample just before the window (``G_end[b] != G_start[b-3q]``, G_{-1} = 0).
    E moves along (module docstring) from ``e_prev`` (per channel: E at b_old - 1, the
    last term of the previous call) or, when ``age[0]`` < 0 (nothing kept, e.g. after
    load_state), no term was formed before, or ``max_age`` >= 0 and more than
    ``max_age`` moves were made since, from a fresh sum of its q second differences
    (integer histories are exact and never need it: max_age -1). ``age[0]`` counts
    the moves since that anchor; both are updated. The terms are written to
    ``scratch`` (float64, >= the number of terms) and their squares summed in blocks.

    G never decreases, so (as in ``_block_sumsq_g``) O(1) tests find a call whose terms
    all hold a gap in every channel (:func:`_no_term_used`): their squares are not formed,
    and E is only moved along, or summed afresh by the next call (``age[0]`` = -1) where
    that is due anyway or costs fewer than the ``total`` moves; and from the first term
    whose window holds no gap up to the last block (:func:`_clean_from`), a channel moves
    E as a record without gaps does: only the terms near a gap's edge are tested.
    """
    lo = max(b_old, 3 * q - 1)
    if lo >= b_new:
        return
    nch = bs.shape[1]
    total = b_new - lo
    all_rows = np.empty(rows.size + 1, np.int64)
    all_rows[:rows.size] = rows
    all_rows[rows.size] = noise_row
    anchor = age[0] < 0 or b_old <= 3 * q - 1 or (0 <= max_age < age[0] + total)
    if ga.shape[0] > 0 and _no_term_used(ga, ga0, ge, ge0, lo, b_new, q, stride):
        for ch in range(nch):
            for row in all_rows:
                if row >= 0:
                    skip[row, ch] += total
        if anchor or q <= total:
            age[0] = -1
            return
        i = lo - bs0
        for ch in range(nch):
            c = bs[:, ch]
            e = e_prev[ch]
            for k in range(i, i + total):
                e += (c[k] - 2 * c[k - q] + c[k - 2 * q]) - (c[k - q] - 2 * c[k - 2 * q]
                                                             + c[k - 3 * q])
            e_prev[ch] = e
        age[0] += total
        return
    # a term's gap rule compares G_end[b] with G_start[b - 3q + woff]
    woff = 0 if unit_stride and noise_row >= 0 else 1
    k0 = 1 if anchor else 0  # terms already formed before the moving loop
    for ch in range(nch):
        c = bs[:, ch]
        if anchor:
            e = c[0] - c[0]  # zero of the history's type (int64 exact, or float64)
            for r in range(q):
                i = lo - r - bs0
                e += c[i] - 2 * c[i - q] + c[i - 2 * q]
            scratch[0] = float(e)
        else:
            e = e_prev[ch]
        i = lo + k0 - bs0  # buffer row of the first moved term (history from i - 3q on)
        n = total - k0
        # views at lags 0, q, 2q, 3q: non-negative indices (no wrap-around tests)
        x0, x1 = c[i:i + n], c[i - q:i - q + n]
        x2, x3 = c[i - 2 * q:i - 2 * q + n], c[i - 3 * q:i - 3 * q + n]
        # terms lo..clean-1 are tested one by one, clean..b_new-1 hold no gap
        clean = lo if ga.shape[0] == 0 else _clean_from(ga, ga0, ge, ge0, lo, b_new, q, woff,
                                                         ch)
        n_tested = max(0, clean - lo - k0)  # moved terms among those tested
        for k in range(n_tested):
            # d_b and d_{b-q} evaluated as when they entered E (module docstring)
            e += (x0[k] - 2 * x1[k] + x2[k]) - (x1[k] - 2 * x2[k] + x3[k])
            scratch[k0 + k] = float(e)
        if clean > lo:
            _add_mvar_terms(scratch, lo, clean - lo, q, unit_stride, ga, ga0, ge, ge0,
                            all_rows, ch, sum2, comp, cnt, skip)
        if clean < b_new:
            # no gap: squares summed as E moves (no term array)
            first = float(e) * float(e) if anchor and clean == lo else 0.0
            a = n_tested
            while True:
                b = min(a + BLOCK, n)
                e, s = _move_sumsq(x0, x1, x2, x3, e, a, b)
                for row in all_rows:
                    if row >= 0:
                        _neumaier_add(sum2, comp, int(row), ch,
                                      s + first if a == n_tested else s)
                if b >= n:
                    break
                a = b
            for row in all_rows:
                if row >= 0:
                    cnt[row, ch] += b_new - clean
        e_prev[ch] = e
    age[0] = total - 1 if anchor else age[0] + total


@njit(cache=True, nogil=True)
def _clean_from(ga: np.ndarray, ga0: int, ge: np.ndarray, ge0: int, lo: int, b_new: int,
                q: int, woff: int, ch: int) -> int:
    """The first term b in lo..b_new-1 from which no term of channel ch holds a gap, by
    bisection (G never decreases): ``G_start[b - 3q + woff] == G_end[b_new - 1]``, with
    G_start = 0 before the record; b_new when the last term holds one."""
    g_last = ge[b_new - 1 - ge0, ch]
    a, b = lo, b_new
    while a < b:
        mid = (a + b) // 2
        j = mid - 3 * q + woff
        if (ga[j - ga0, ch] if j >= 0 else 0) == g_last:
            b = mid
        else:
            a = mid + 1
    return a


@njit(cache=True, nogil=True)
def _no_term_used(ga: np.ndarray, ga0: int, ge: np.ndarray, ge0: int, lo: int, b_new: int,
                  q: int, stride: int) -> bool:
    """Whether every MVAR term b = lo..b_new-1 holds a gap (``G_end[b] >
    G_start[b-3q+1]``, so the noise-ID rule's too) in every channel: a gap lies in the
    last term's window before the first term's end (``G_start[b_new-3q] < G_end[lo]``),
    or every sample of the blocks is a gap. At stride 1 a block is the sample at G_start
    (G at lo-1 is compared); otherwise the samples after a block's first one suffice."""
    for ch in range(ga.shape[1]):
        if ga[b_new - 3 * q - ga0, ch] < ge[lo - ge0, ch]:
            continue
        if stride == 1:
            if ga[b_new - 1 - ga0, ch] - ga[lo - 1 - ga0, ch] != b_new - lo:
                return False
        elif ge[b_new - 1 - ge0, ch] - ga[lo - ga0, ch] != stride * (b_new - lo) - 1:
            return False
    return True


@njit(cache=True, nogil=True)
def _add_mvar_terms(e: np.ndarray, lo: int, total: int, q: int, unit_stride: bool,
                    ga: np.ndarray, ga0: int, ge: np.ndarray, ge0: int, all_rows: np.ndarray,
                    ch: int, sum2: np.ndarray, comp: np.ndarray, cnt: np.ndarray,
                    skip: np.ndarray) -> None:
    """Add the squares of the MVAR terms e[:total] (E_b, b = lo..) of channel ch with the
    gap rules of :func:`mvar_sums`; ``all_rows``: MDEV, TDEV rows then the noise row."""
    if ga.shape[0] == 0:
        _add_blocks(e, total, all_rows, ch, sum2, comp, cnt)
        return
    rows = all_rows[:-1]
    noise_row = all_rows[-1]
    s = 0.0
    sn = 0.0
    used = 0
    used_n = 0
    for k in range(total):
        b = lo + k
        v2 = e[k] * e[k]
        g_end = ge[b - ge0, ch]
        ok = g_end == ga[b - 3 * q + 1 - ga0, ch]
        if unit_stride:
            before = ga[b - 3 * q - ga0, ch] if b - 3 * q >= 0 else 0
            ok_n = g_end == before
        else:
            ok_n = ok
        if ok:
            s += v2
            used += 1
        if ok_n:
            sn += v2
            used_n += 1
        if (k + 1) % BLOCK == 0 or k == total - 1:
            for row in rows:
                if row >= 0:
                    _neumaier_add(sum2, comp, row, ch, s)
            if noise_row >= 0:
                _neumaier_add(sum2, comp, noise_row, ch, sn)
            s = 0.0
            sn = 0.0
    for row in rows:
        if row >= 0:
            cnt[row, ch] += used
            skip[row, ch] += total - used
    if noise_row >= 0:
        cnt[noise_row, ch] += used_n
        skip[noise_row, ch] += total - used_n


_FM_NOISE = {"reassoc", "contract", "nsz"}  # no arcp: x / m rounds as numpy's does


@njit(cache=True, fastmath=_FM_NOISE, nogil=True)
def _moments(z: np.ndarray, j0: int, n: int, out: np.ndarray, d: int, ch: int) -> None:
    """The seven u sums (``streaming_noise`` indices 0..6) of the new elements z[j0:n]
    of one difference order, pairs with their predecessors included (``_add_finite``)."""
    s = 0.0
    s2 = 0.0
    w = z[j0:n]
    for j in range(w.size):
        s += w[j]
        s2 += w[j] * w[j]
    lag = 0.0
    k = n - j0
    out[d, 0, ch] = k
    out[d, 1, ch] = s
    out[d, 2, ch] = s2
    if j0 == 0:  # pairs (w_i, w_{i+1}) inside the new elements
        if k > 1:
            a, b = z[:n - 1], z[1:n]
            for j in range(n - 1):
                lag += a[j] * b[j]
            out[d, 3, ch] = k - 1
            out[d, 4, ch] = s - z[n - 1]
            out[d, 5, ch] = s - z[0]
            out[d, 6, ch] = lag
    else:  # every new element pairs with its predecessor
        a = z[j0 - 1:n - 1]
        for j in range(k):
            lag += a[j] * w[j]
        out[d, 3, ch] = k
        out[d, 4, ch] = s - z[n - 1] + z[j0 - 1]
        out[d, 5, ch] = s
        out[d, 6, ch] = lag


@njit(cache=True, nogil=True)
def noise_sums_finite(x: np.ndarray, i0: int, m: int, tail: np.ndarray, cnt: int,
                      orders: int, shift: np.ndarray, out: np.ndarray,
                      scratch: np.ndarray) -> None:
    """Noise-ID sums of the phase values x[i0::m] (no gap, nothing unknown) appended to
    the last ``cnt`` values of ``tail``: per difference order d < orders the u sums of
    ``RunningNoiseSums._add_finite`` into ``out[d, :7, ch]`` (out zeroed by the caller).

    The m-averages ``z_j = (v_{j+1} - v_j) / m`` (order 0 less ``shift``), then their
    successive differences, are formed in ``scratch`` (>= cnt + len(x[i0::m]) values),
    one channel at a time: no strided copy, no per-order temporaries.
    """
    nch = x.shape[1]
    k_new = (x.shape[0] - 1 - i0) // m + 1
    total = cnt + k_new
    t0 = tail.shape[0] - cnt
    z = scratch
    for ch in range(nch):
        prev = tail[t0, ch]
        for j in range(cnt - 1):  # within the tail
            z[j] = (tail[t0 + j + 1, ch] - prev) / m
            prev = tail[t0 + j + 1, ch]
        xs = x[i0:, ch][::m]
        for j in range(k_new):  # new values
            v = float(xs[j])
            z[cnt - 1 + j] = (v - prev) / m
            prev = v
        n = total - 1
        for d in range(orders):
            if d:
                zl, zr = z[:n - 1], z[1:n]
                for j in range(n - 1):
                    zl[j] = zr[j] - zl[j]
                n -= 1
            if n <= 0:
                break
            j0 = max(0, cnt - d - 1)
            if d == 0:
                for j in range(n):
                    z[j] -= shift[ch]
            _moments(z, j0, n, out, d, ch)
