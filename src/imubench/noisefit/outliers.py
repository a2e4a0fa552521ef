"""Impulsive outliers in a channel? A check before trusting its white-noise level.

The noise terms of :mod:`.fit` are Gaussian; glitches (single-sample spikes) add their
variance to every short-tau Allan point, and the fit reports them as white noise
(measured: the Xsens MTi-G record in the reference data, ~5 % impulsive samples, fits a
white level 2.8 times the one of its glitch-free samples). The check uses the first
differences d_k = y_k - y_(k-1), which remove every slow term (flicker, random walk,
drift, temperature): their robust standard deviation s = 1.4826 MAD (the normal
consistency factor of the median absolute deviation, Rousseeuw & Croux 1993, JASA 88,
1273-1283) and the share of differences beyond :data:`Z_LIMIT` s from their median. A
Gaussian series puts 2e-9 of its differences there; the warning needs both
:data:`MIN_SHARE` and :data:`MIN_COUNT`.

Held samples come first (:func:`held_runs`): a sensor or logger that repeats its output
between updates (the Samsung S5 record: 20 % of its gyro samples, each value held for a
median of 9) makes most differences 0, which shrinks the robust spread, and puts the change of a
whole run in the difference after it; the outlier test then reads heavy tails that are
not there (5.4-6 % "impulsive" on all six S5 channels, std/robust 2.75, where the
differences without the holds are Gaussian-like: 0.08 % beyond 6 sigma, std/robust
1.34). Such a record gets the held-samples warning instead.
"""

from __future__ import annotations

import numpy as np

Z_LIMIT = 6.0
"""Robust z beyond which a first difference is impulsive."""
MIN_SHARE = 1e-4
"""Share of impulsive differences above which a warning is given."""
MIN_COUNT = 10
"""... and at least this many of them."""
HELD_SHARE = 0.05
"""Share of repeated samples from which a record may be holding its output."""
HELD_CHANGE = 0.01
"""A sample repeats the previous one when their difference is at most this share of the
differences' 75th percentile in size (Gaussian differences: ~0.9 % of them, in runs of
one; the S5's held samples change by ~1e-6 rad/s against a typical 3e-4)."""
HELD_RUN = 4
"""... when a value is held for a median of at least this many samples (a run of
HELD_RUN - 1 repeats after it: a quantised noise whose differences are 0 with probability
q has geometric runs of median 1 repeat for q < 0.5 and 2 up to q = 0.7)."""
COARSE_ONE_STEP = 0.9
"""A record whose changes lie on one grid (every non-zero difference a whole multiple of
the smallest) and are one grid step in at least this share is rounded far coarser than
its noise, not held: an outside reviewer's white noise rounded at 3-4 LSB per sigma
repeated 76-91 % of its samples in geometric runs of median 5-15."""


def _coarse_rounding(d: np.ndarray) -> bool:
    """The non-zero differences ``d`` are one step of a common grid (:data:`COARSE_ONE_STEP`)."""
    nz = np.abs(d[d != 0.0])
    if nz.size < 10:
        return True
    steps = nz / float(nz.min())
    on_grid = bool(np.all(np.abs(steps - np.round(steps)) <= 1e-3 * steps))
    return on_grid and float(np.mean(np.round(steps) == 1.0)) >= COARSE_ONE_STEP


def held_runs(y: np.ndarray) -> tuple[float, float] | None:
    """(share of samples that repeat the previous one (:data:`HELD_CHANGE`), median
    number of samples a value is held for, counting its first) when both reach
    :data:`HELD_SHARE` and :data:`HELD_RUN` and the changes are not one step of a coarse
    rounding grid (:func:`_coarse_rounding`), else None."""
    d = np.diff(np.asarray(y, dtype=float))
    d = d[np.isfinite(d)]
    if d.size < 100:
        return None
    zero = np.abs(d) <= HELD_CHANGE * float(np.percentile(np.abs(d), 75))
    share = float(zero.mean())
    if share < HELD_SHARE or _coarse_rounding(d):
        return None
    edges = np.diff(np.concatenate(([0], zero.astype(np.int8), [0])))
    lengths = np.nonzero(edges == -1)[0] - np.nonzero(edges == 1)[0]
    held = float(np.median(lengths)) + 1.0
    return (share, held) if held >= HELD_RUN else None


def impulsive_share(y: np.ndarray) -> tuple[float, int, float] | None:
    """(share of impulsive first differences, their count, std / robust std of the
    differences), or None when fewer than 100 differences are finite or the robust
    spread is 0 (a constant or almost constant record)."""
    d = np.diff(np.asarray(y, dtype=float))
    d = d[np.isfinite(d)]
    if d.size < 100:
        return None
    med = float(np.median(d))
    s = 1.4826 * float(np.median(np.abs(d - med)))
    if not s > 0:
        return None
    count = int(np.count_nonzero(np.abs(d - med) > Z_LIMIT * s))
    return count / d.size, count, float(np.std(d)) / s


def outlier_warning(channel: str, y: np.ndarray) -> str | None:
    """A warning, in words, when the channel holds its output over several samples or
    holds impulsive outliers (module docstring)."""
    held = held_runs(y)
    if held is not None:
        share, run = held
        return (f"{channel}: held samples: {100 * share:.2g} % of the samples repeat the "
                f"previous one (within {100 * HELD_CHANGE:g} % of a typical change), each "
                f"value held for a median of {run:g} samples: a sensor or logger that holds "
                "its output "
                "between updates (the record's real sample "
                "rate is then lower than stated, and the short-tau Allan points and the "
                "white level lie low) or a resolution far coarser than the noise; the "
                "outlier check is not made (the change of a whole run falls in one "
                "difference)")
    found = impulsive_share(y)
    if found is None:
        return None
    share, count, ratio = found
    if share <= MIN_SHARE or count < MIN_COUNT:
        return None
    return (f"{channel}: impulsive outliers or heavy-tailed noise: {count} first "
            f"differences ({100 * share:.2g} %) lie beyond {Z_LIMIT:g} robust standard "
            f"deviations (Gaussian noise puts ~2e-7 % there), a lower bound on the share "
            f"of bad samples (dense or clustered glitches widen the robust spread too: the "
            f"Xsens MTi-G record's 5.4 % read as 0.1 %); the differences' standard "
            f"deviation is {ratio:.3g}x their robust one, so the white level fitted here "
            f"can be up to {ratio:.3g}x that of the clean samples (the Gaussian noise terms "
            "absorb them); imubench gap tests sparse impulses as the 'outliers' effect")
