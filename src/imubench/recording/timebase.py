"""Sample rate and sample indices of a recording that carries only time stamps.

One rule for every reader (the CSV/text reader, ROS 2 bags, MCAP):

1. ``--rate`` when given;
2. else the file's own rate (``# odr_hz`` metadata, a native header);
3. else, with a sample-index column and times, the least-squares slope of t against the
   index; with a sample-index column alone, ``--rate`` is required;
4. else from the times alone: a first line (step and the time of index 0) gives
   provisional indices ``round((t - t0) / step)`` of the first 4000 rows, the
   least-squares line of t against them a better one, which indexes 1.5x as many rows,
   and so on to the whole record: the rate is the least-squares slope over all of it.
   (Indexing everything with a first estimate at once would slip a period every
   1 / (relative error) samples.) The first line's step is the period on which the
   first 4000 stamps are most in phase (the periodogram of a point process: jitter up to
   half a period and any number of missing samples leave the true period's phase
   coherence intact), its origin the stamps' circular mean phase on it
   (:func:`_first_line`). A median step is biased by the rounding of printed times
   (104 Hz printed to 6 decimals: median step 0.009615 s -> 104.004 Hz) and, with
   jittered stamps (a logger stamping when it reads, +-0.45 periods), off by ~1 %; the
   line is not, and its fitted time of index 0 keeps every stamp within half a step of
   its sample as long as the jitter stays below half a period.

Time stamps that go backwards or land on an earlier sample than the row before (a
damaged row, a logger's glitch) are not trusted: the longest run of rows whose indices
increase (longest increasing subsequence) is kept, and the other rows are reported as
damaged, so a single bad time stamp costs one row, never the rest of the record.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from imubench.errors import RecordingError
from imubench.recording.options import TIME_UNITS_S

PLAUSIBLE_RATE_HZ = (7.0, 7_000.0)
"""Sample rates (lower bound excluded) a time unit is chosen for, when the header does
not give it: the ODRs of the LSM6DS family (12.5 Hz to 6.66 kHz) and most IMU loggers
(10 Hz to 4 kHz); bounds away from round rates, so that printed times rounded either way
land on the same side. The range spans a factor of 1000 with one end open, so at most
one of s, ms, us, ns fits a given spacing."""
SLOW_LOGGER_HZ = 1.0
"""A spacing that reads as milliseconds in :data:`PLAUSIBLE_RATE_HZ` but as at least this
rate in seconds (steps of 1/7 to 1 unit: 1-7 Hz in s, 1-7 kHz in ms) is ambiguous: a
slow logger in seconds and a fast one in milliseconds write the same numbers, so it is
refused (``--time-unit``) rather than guessed."""
BOOT_COUNTER_HZ = 4.0
"""Stamps the size of Unix times that read below this rate while another unit reads
plausibly are refused as ambiguous (a counter since boot?). A logger at 4 Hz or more with
Unix seconds is read as such; ms since boot at 4 kHz or more is not caught."""
EPOCH_S = (1.0e9, 4.1e9)
"""Unix times in seconds of 2001-2099: time stamps of this size (or 1e3, 1e6, 1e9 times
it) are absolute, and their magnitude gives the unit (s, ms, us, ns)."""
MJD_RANGE = (40_000.0, 100_000.0)
"""Modified Julian Dates (days) of 1968-2132: a time tag column in this range is MJD."""
SECONDS_PER_DAY = 86_400.0
DATENUM_RANGE = (693_962.0, 767_011.0)
"""MATLAB serial date numbers (days since year 0) of 1900-2099: refused with the fix (a
datenum written with 15 significant digits is stamped to 86 us only)."""
DATENUM_OF_UNIX_EPOCH = 719_529.0
"""MATLAB's ``datenum(1970, 1, 1)``."""
MJD_OF_UNIX_EPOCH = 40_587.0
"""The Modified Julian Date of 1970-01-01 00:00 UTC."""


def utc_now() -> str:
    """Now as ISO 8601 UTC to the millisecond: a live recording's ``start_utc`` (whole
    seconds put it up to a second before the first sample, and a Stable32 export's MJD
    tags with it)."""
    import datetime as _dt

    return _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"


def start_utc(unix_s: float) -> str | None:
    """ISO 8601 UTC of a Unix time in seconds of 2001-2099 (:data:`EPOCH_S`); None for a
    time that counts from anything else (a start that is not known)."""
    import datetime as _dt

    if not EPOCH_S[0] <= unix_s <= EPOCH_S[1]:
        return None
    return _dt.datetime.fromtimestamp(unix_s, _dt.UTC).strftime("%Y-%m-%dT%H:%M:%S.%fZ")

FIRST_FIT_ROWS = 4000
"""Rows indexed by the first line (:func:`_first_line`) before the first refinement."""
GROWTH = 1.5
"""Each refinement indexes this many times as many rows. With stamps jittered by up to
+-0.45 steps, a slope fitted on m rows (sd 0.9 / m^1.5 steps per row) moves the stamps of
the next 0.5 m rows by at most 3 sd x 1.0 m, 0.043 steps at m = 4000: within the 0.05
left between the jitter and half a step."""
PERIOD_SEARCH = 0.05
"""The period is searched within this fraction of the median spacing (which jittered
stamps put within ~1.5 % after 1000 rows)."""
PHASE_NOISE = 3.0
"""The best period's phase coherence must exceed this over sqrt(stamps), else the
median spacing is used: stamps with no period have a coherence of ~1/sqrt(stamps) and
its largest over the search grid is ~2.8/sqrt(stamps); uniform jitter of 0.45 periods
leaves 0.11 of a perfect grid's 1, jitter of 0.49 periods 0.02."""
SHARED_STAMPS = 0.005
"""Share of consecutive rows with the same stamp beyond which the stamps are taken as
rounded coarser than the sample period (rows that share a stamp cannot be told apart by
it), not as the odd repeated line."""
PAUSE_STEPS = 1000
"""A step longer than this many median spacings splits the stamps the period is searched
on, which are the longest stretch between such steps: the search grid is as fine as one
period over the stamps' span, so a pause of an hour among the first stamps made it 26 s
and a wrong digit in a day number hung it."""
COARSE_ROWS = 2000
"""Stamps of the coarse search of the period (its peak then ~1/2000 wide, searched at 20
points per width); the fine search uses all the first rows near it."""


@dataclass(frozen=True)
class Timebase:
    """Rate, integer sample indices and the rows kept, with how the rate was found."""

    rate_hz: float
    index: np.ndarray
    """int64 sample indices of the kept rows (increasing)."""
    keep: np.ndarray
    """bool mask over the input rows: False for rows dropped as damaged."""
    how: str

    @classmethod
    def in_order(cls, rate_hz: float, n: int, how: str) -> Timebase:
        """``n`` rows, one sample each in the order given, at ``rate_hz`` (no time
        column, or ``--columns t=-``)."""
        return cls(rate_hz, np.arange(n, dtype=np.int64), np.ones(n, bool), how)


def time_unit_from_spacing(t: np.ndarray, where: str) -> tuple[str, float]:
    """(unit, seconds per unit) of a time column: days when the values are Modified
    Julian Dates, the unit of an absolute Unix time by its magnitude (:data:`EPOCH_S`),
    else the one unit in which the median step gives a rate in
    :data:`PLAUSIBLE_RATE_HZ`. RecordingError (with the fix) when none does, and when
    seconds and milliseconds both read plausibly (:data:`SLOW_LOGGER_HZ`)."""
    step = _median_step(t, where)
    finite = t[np.isfinite(t)]
    if len(finite) and MJD_RANGE[0] <= float(np.median(finite)) <= MJD_RANGE[1] and (
            step < 1.0):
        return "d", SECONDS_PER_DAY
    lo, hi = PLAUSIBLE_RATE_HZ
    fits = [(u, s) for u, s in TIME_UNITS_S.items() if lo < 1.0 / (step * s) <= hi]
    if len(finite):
        level = float(np.median(np.abs(finite)))
        for unit, scale in TIME_UNITS_S.items():
            if EPOCH_S[0] <= level * scale <= EPOCH_S[1]:
                if 1.0 / (step * scale) < BOOT_COUNTER_HZ and len(fits) == 1:
                    # an uptime counter (ms since boot: 1.3e9 after 15 days) has the size of
                    # Unix seconds; read as such, 100 Hz became 0.1 Hz and 2 kHz 2 Hz (below
                    # an IMU's rate, while another unit gives a plausible one)
                    raise RecordingError(
                        f"{where}: the time column's values (~{level:.3g}) read as Unix "
                        f"times in {unit} give {1.0 / (step * scale):.4g} Hz; in "
                        f"{fits[0][0]} (a counter since boot?) {1.0 / (step * fits[0][1]):.4g}"
                        " Hz; give --time-unit s|ms|us|ns or --rate HZ")
                return unit, scale
    if len(fits) != 1:
        datenum = ""
        if len(finite) and DATENUM_RANGE[0] <= float(np.median(finite)) <= DATENUM_RANGE[1]:
            datenum = (f"; the values (~{float(np.median(finite)):.9g}) look like MATLAB "
                       f"date numbers (days; {1.0 / (step * SECONDS_PER_DAY):.4g} Hz): "
                       "write seconds instead ((datenum - "
                       f"{DATENUM_OF_UNIX_EPOCH:.0f}) * 86400 are Unix seconds)")
        raise RecordingError(
            f"{where}: cannot tell the unit of the time column (median step {step:.6g}); "
            "give --time-unit s|ms|us|ns or --rate HZ" + datenum
        )
    if fits[0][0] == "ms" and 1.0 / step >= SLOW_LOGGER_HZ:
        raise RecordingError(
            f"{where}: the time column's median step {step:.6g} is {1.0 / step:.4g} Hz in "
            f"seconds or {1e3 / step:.4g} Hz in milliseconds; give --time-unit s|ms or "
            "--rate HZ"
        )
    return fits[0]


def increasing_step(t: np.ndarray) -> float | None:
    """Median of the steps between finite stamps that increase (None when none does)."""
    steps = np.diff(t[np.isfinite(t)])
    d = steps[steps > 0]
    return float(np.median(d)) if len(d) else None


def _median_step(t: np.ndarray, where: str) -> float:
    """:func:`increasing_step`; RecordingError (with the fix) when no stamp increases or
    when most stamps repeat (median step 0: stamps written with too few digits, e.g.
    epoch seconds cut to 9 significant digits, so that no rate can be read from them)."""
    step = increasing_step(t)
    if step is None:
        raise RecordingError(f"{where}: the time column never increases; give --rate HZ "
                             "and --columns t=- to read the rows in order")
    if float(np.median(np.diff(t[np.isfinite(t)]))) <= 0:
        raise RecordingError(
            f"{where}: most time stamps repeat the one before (median step 0; written with "
            f"too few digits?); give --rate HZ and --columns t=- to read the rows in order")
    return step


def increasing_rows(index: np.ndarray) -> np.ndarray:
    """Mask of a longest strictly increasing subsequence of ``index`` (all True when it
    increases already): the rows kept when some time stamps are damaged."""
    n = len(index)
    keep = np.ones(n, dtype=bool)
    if n < 2 or bool(np.all(np.diff(index) > 0)):
        return keep
    tails: list[int] = []  # smallest tail value of an increasing run of each length
    tail_at: list[int] = []
    prev = np.full(n, -1, dtype=np.int64)
    for i, v in enumerate(index.tolist()):
        k = bisect.bisect_left(tails, v)
        if k == len(tails):
            tails.append(v)
            tail_at.append(i)
        else:
            tails[k] = v
            tail_at[k] = i
        prev[i] = tail_at[k - 1] if k else -1
    keep[:] = False
    i = tail_at[-1] if tail_at else -1
    while i >= 0:
        keep[i] = True
        i = int(prev[i])
    return keep


STRAY_ROWS = 3
"""At most this many rows at either end of a recording may be stray (:func:`stray_ends`)."""
STRAY_FACTOR = 10.0
"""A hole this many times longer than the rest of the recording makes the rows beyond it
stray."""


def stray_ends(index: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """``keep`` less at most :data:`STRAY_ROWS` rows at either end separated from the rest
    by a hole more than :data:`STRAY_FACTOR` times the rest's span: a last stamp with a
    wrong digit (an MJD 1000 days on, a Unix time 1e6 s on) is no sample after a pause
    hundreds of times the record; read as one, the record became a 1e8-sample hole
    (5 GB, 21 s for 3000 rows) and every tau up to it was computed on nothing."""
    rows = np.nonzero(keep)[0]
    if rows.size <= 4 * STRAY_ROWS:
        return keep
    idx = index[rows]
    out = keep.copy()
    for k in range(STRAY_ROWS, 0, -1):  # the most rows first: a pair after the hole
        rest = idx[-k - 1] - idx[0] + 1
        if idx[-k] - idx[-k - 1] > STRAY_FACTOR * rest:
            out[rows[-k:]] = False
            break
    for k in range(STRAY_ROWS, 0, -1):
        rest = idx[-1] - idx[k] + 1
        if idx[k] - idx[k - 1] > STRAY_FACTOR * rest:
            out[rows[:k]] = False
            break
    return out


def _indices(t_s: np.ndarray, t0: float, step_s: float) -> tuple[np.ndarray, np.ndarray]:
    """``round((t - t0) / step)`` as int64, and a mask of the rows whose stamp is within
    2^62 sample periods (a damaged stamp beyond is a row to drop, not an index)."""
    with np.errstate(invalid="ignore"):
        x = np.rint((t_s - t0) / step_s)
        ok = np.abs(x) < 2.0**62  # False for NaN (an empty stamp) too
    return np.where(ok, x, 0.0).astype(np.int64), ok


def _kept(index: np.ndarray, ok: np.ndarray, where: str) -> np.ndarray:
    """:func:`increasing_rows` over the rows that are ``ok`` only."""
    keep = np.zeros(len(index), dtype=bool)
    rows = np.nonzero(ok)[0]
    keep[rows[increasing_rows(index[rows])]] = True
    keep = stray_ends(index, keep)
    if not keep.any():
        raise RecordingError(f"{where}: no row has a usable time stamp; give --rate HZ")
    return keep


def _slope(x: np.ndarray, y: np.ndarray) -> float:
    """Least-squares slope of y against x (centred, for large time stamps)."""
    xc = x - x.mean()
    return float(np.dot(xc, y - y.mean()) / np.dot(xc, xc))


def _line(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Least-squares (slope, value at x = 0) of y against x."""
    b = _slope(x, y)
    return b, float(y.mean() - b * x.mean())


def _grid_origin(t_s: np.ndarray, step_s: float) -> float:
    """The time of a sample of the grid of period ``step_s`` on which the (finite)
    stamps lie: the first stamp moved by the circular mean of every stamp's phase on that
    grid, so that jittered stamps (a logger stamping when it reads) and holes do not move
    it, as the first stamp alone would by its own jitter."""
    t0 = float(t_s[0])
    phase = 2.0 * np.pi * ((t_s - t0) / step_s)
    return t0 + step_s * float(np.arctan2(np.sin(phase).mean(), np.cos(phase).mean())
                               / (2.0 * np.pi))


def _first_line(t_s: np.ndarray, m: int, where: str) -> tuple[float, float, str]:
    """(step, time of index 0, a note) to index the first ``m`` rows by (module
    docstring, 4.); the note is :func:`_rounded_period`'s.

    The step is the period on which the stamps are most in phase: the maximum of
    ``|mean(exp(2 pi i t / P))|`` over P within :data:`PERIOD_SEARCH` of the median
    spacing, first on the first :data:`COARSE_ROWS` stamps, then on all ``m`` near that
    (the periodogram of a point process: stamps jittered by up to half a period stay in
    phase, and missing samples take nothing from it, however many). The time of index 0
    is on that grid (:func:`_grid_origin`). Rows whose stamps are out of time order (a
    damaged stamp) take no part."""
    t = t_s[:m]
    rows = np.nonzero(np.isfinite(t))[0]
    rows = rows[increasing_rows(t[rows])]  # a stamp out of time order is no sample time
    if len(rows) < 3:
        return _median_step(t_s, where), float(np.median(t_s[np.isfinite(t_s)][:5])), ""
    u = t[rows] - t[rows][0]
    step = float(np.median(np.diff(u)))
    if not step > 0:
        return _median_step(t_s, where), float(np.median(t_s[np.isfinite(t_s)][:5])), ""
    median = step
    pause = np.nonzero(np.diff(u) > PAUSE_STEPS * median)[0]
    if pause.size:  # the longest stretch of stamps between long pauses
        bounds = np.concatenate(([0], pause + 1, [u.size]))
        k = int(np.argmax(np.diff(bounds)))
        rows = rows[bounds[k]:bounds[k + 1]]
        u = t[rows] - t[rows][0]
    step, note = _rounded_period(t[rows[0]:rows[-1] + 1], u, median, where)
    for part in (u[:COARSE_ROWS], u):
        periods = max(part[-1] / step, 1.0)  # the peak is ~1 / periods wide (relative)
        span = PERIOD_SEARCH if part is not u or part.size <= COARSE_ROWS else 4.0 / periods
        grid = step * (1.0 + np.linspace(-span, span, int(20 * span * periods) + 3))
        step, coherence = _most_in_phase(part, grid)
        if coherence < PHASE_NOISE / np.sqrt(part.size):
            # no period stands out of the noise (jitter near half a period on few rows):
            # the median spacing, as before this search, and the first stamps
            return median, float(np.median(t[rows][:5])), ""
    return step, _grid_origin(t[rows], step), note


def _on_resolution(steps: np.ndarray, r: float) -> bool:
    """Whether every step is a whole number (0, 1, 2, ...) of ``r`` (to 0.1 %: stamps
    written with a few decimals)."""
    q = steps / r
    return bool(np.all(np.abs(q - np.rint(q)) < 1e-3))


def _resolution(steps: np.ndarray, median: float) -> float | None:
    """The resolution the stamps are rounded to: the largest ``median / k`` (k = 1..10)
    of which every step is a whole number (steps of 2 and 3 ms: 1 ms); None if none."""
    for k in range(1, 11):
        if _on_resolution(steps, median / k):
            return median / k
    return None


def _rounded_period(t: np.ndarray, u: np.ndarray, median: float, where: str
                    ) -> tuple[float, str]:
    """The step to search the period near: ``median``, or the mean spacing of stamps
    rounded to a resolution as coarse as the sample period (with a note saying so).

    Stamps rounded to a resolution (every step a whole number of it: an Arduino's
    ``millis()``, seconds printed with 2 decimals) whose mean spacing is more than
    :data:`PERIOD_SEARCH` longer are a sampling period the resolution cannot show (833 Hz
    in whole milliseconds: steps 1, 1, 1, 1, 2 ms), when the stamps are in phase on that
    mean spacing (:data:`PHASE_NOISE`); the median read them as 1000 Hz with every sixth
    sample a hole. A grid whose holes fall at random is in phase on no such period and
    keeps its median. Holes in a regular pattern (every tenth sample) look exactly like
    rounding and are read as the longer period: the note says so. Stamps rounded coarser
    than the period (rows share stamps: 104 Hz printed to 10 ms) cannot be indexed by
    them and are refused with the fix."""
    tf = t[np.isfinite(t)]
    steps = np.diff(tf)
    r = _resolution(steps, median) if len(steps) >= 3 and np.all(steps >= 0) else None
    if r is None:
        return median, ""
    mean = float(tf[-1] - tf[0]) / len(steps)
    if np.count_nonzero(steps == 0) > SHARED_STAMPS * len(steps):
        raise RecordingError(
            f"{where}: the time stamps are rounded to {r:.4g} s, as "
            f"coarse as the sample period ({mean:.6g} s on average): rows share a stamp and "
            "cannot be told apart by it; give --rate HZ and --columns t=- to read the rows "
            "in order without the time column")
    if mean <= median * (1.0 + PERIOD_SEARCH):
        return median, ""
    grid = mean * (1.0 + np.linspace(-PERIOD_SEARCH, PERIOD_SEARCH, 201))
    period, coherence = _most_in_phase(u[:COARSE_ROWS], grid)
    if coherence < PHASE_NOISE / np.sqrt(min(u.size, COARSE_ROWS)):
        return median, ""
    return period, (f"the stamps are rounded to {r:.4g} s, as coarse as the "
                    "sample period: the rate is read from their mean spacing; holes are not "
                    "seen at that resolution, and samples dropped in a regular pattern "
                    "would read as a lower rate (give --rate HZ if so)")


def _most_in_phase(u: np.ndarray, grid: np.ndarray) -> tuple[float, float]:
    """(the period in ``grid`` on which the times ``u`` are most in phase, refined by a
    parabola through the best point and its neighbours; that phase coherence)."""
    power = np.empty(grid.size)
    for lo in range(0, grid.size, 64):  # blocks keep the (periods x stamps) array small
        phase = np.exp(2j * np.pi * np.outer(1.0 / grid[lo:lo + 64], u))
        power[lo:lo + 64] = np.abs(phase.mean(axis=1))
    k = int(np.argmax(power))
    if 0 < k < grid.size - 1:
        y0, y1, y2 = power[k - 1], power[k], power[k + 1]
        den = y0 - 2 * y1 + y2
        if den < 0:
            return float(grid[k] + 0.5 * (y0 - y2) / den * (grid[1] - grid[0])), float(y1)
    return float(grid[k]), float(power[k])


def timebase_from_times(t_s: np.ndarray, where: str, rate_hz: float | None = None) -> Timebase:
    """Rate and indices of rows with time stamps ``t_s`` (seconds, any origin).

    With ``rate_hz`` (given or from metadata) the indices are ``round((t - t0) *
    rate)``, ``t0`` on the stamps' grid (:func:`_grid_origin`); otherwise the rate is
    the least-squares slope (module docstring).
    """
    finite = np.isfinite(t_s)
    if len(t_s) and not finite.any():
        raise RecordingError(f"{where}: the time column has no numeric value; give "
                             "--rate HZ and --columns t=- (no time column)")
    n = len(t_s)
    if n == 0:
        return Timebase(rate_hz or 0.0, np.zeros(0, np.int64), np.ones(0, bool),
                        "no samples")
    if rate_hz is None and n < 3:
        raise RecordingError(f"{where}: {n} row(s) are too few to infer the rate; give "
                             "--rate HZ")
    if rate_hz is not None:
        index, ok = _indices(t_s, _grid_origin(t_s[finite], 1.0 / rate_hz), 1.0 / rate_hz)
        keep = _kept(index, ok, where)
        index = index[keep]
        return Timebase(rate_hz, index - index[0], keep, "given")
    m = min(n, FIRST_FIT_ROWS)
    step, t0, note = _first_line(t_s, m, where)
    while True:  # fit a prefix, then GROWTH x longer ones, so rounding never slips
        index, ok = _indices(t_s[:m], t0, step)
        keep = _kept(index, ok, where)
        x = index[keep].astype(np.float64)
        if len(x) < 3 or np.ptp(x) == 0:
            raise RecordingError(f"{where}: too few distinct time stamps to infer the rate; "
                                 "give --rate HZ")
        step, shift = _line(x, t_s[:m][keep] - t0)
        if not step > 0:
            raise RecordingError(f"{where}: the time column does not increase; give "
                                 "--rate HZ")
        t0 += shift
        if m == n:
            break
        m = min(n, int(GROWTH * m))
    index, ok = _indices(t_s, t0, step)
    keep = _kept(index, ok, where)
    kept = index[keep]
    return Timebase(1.0 / step, kept - kept[0], keep,
                    "from t (least squares" + (f"; {note})" if note else ")"))


GIVEN_RATE_TOLERANCE = 0.1
"""Largest relative departure of a rate the user or the file states from the rate of the
recording's own time stamps (an ODR's tolerance); beyond it the file is refused, since
which of the two is wrong cannot be told."""
INDEX_DISAGREE_SHARE = 0.01
"""An index column that contradicts the time stamps at more than this share of the rows
(and more than one) is refused rather than read around."""
RESTART_RUN = 10
"""An index that goes back and then counts up for this many rows, all below where it
was, is a counter that wraps or restarts (an 8-bit one lost 1744 of 2000 rows as
"damaged"); a row or two out of order (swapped lines, a damaged digit, a repeated line)
is not, and costs those rows only."""


HOST_JITTER_S = 0.05
"""Allowance for stamps taken from a host clock at each read (imubench's own CSV at a high
ODR without the chip's timestamps anchors each FIFO chunk at the host time of its
newest sample): an index and stamps that disagree by less are not refused."""


def _row_name(lines: np.ndarray | None, row: int) -> str:
    return f"line {int(lines[row])}" if lines is not None else f"row {row + 1}"


def _consistent_with_times(index: np.ndarray, t_s: np.ndarray, keep: np.ndarray,
                           where: str, lines: np.ndarray | None) -> np.ndarray:
    """``keep`` less the rows whose index contradicts the time stamps of the rows around
    it (one wrong digit in an index: a 90 000-sample hole), or RecordingError when the
    two columns disagree over a stretch (a counter of rows written beside stamps with a
    1 s hole: read as 97 Hz with nothing lost). Between consecutive rows the stamps must
    advance by the index step times the median period, within 3 periods (jitter), 0.1 %
    of the step (a clock running off the sample rate) and :data:`HOST_JITTER_S`."""
    rows = np.nonzero(keep & np.isfinite(t_s))[0]
    if rows.size < 3:
        return keep
    idx, t = index[rows].astype(np.float64), t_s[rows]
    period = float(np.median(np.diff(t) / np.diff(idx)))
    if not period > 0:
        return keep

    def off(dt: np.ndarray, di: np.ndarray) -> np.ndarray:  # stamps against the index
        return np.abs(dt - period * di) > 3 * period + 1e-3 * period * di + HOST_JITTER_S

    def agree(a: int, b: int) -> bool:  # positions in rows
        return not bool(off(t[b] - t[a], idx[b] - idx[a]))

    bad = np.nonzero(off(np.diff(t), np.diff(idx)))[0].tolist()  # one pass, not per row
    if not bad:
        return keep
    drop: set[int] = set()
    for k in bad:
        if k in drop or k + 1 in drop:
            continue
        # the row after the interval, or the one before, is the odd one out when the rows
        # around it agree (the first and last rows have one side only)
        if k + 1 == rows.size - 1 or (k + 2 < rows.size and agree(k, k + 2)):
            drop.add(k + 1)
        elif k == 0 or agree(k - 1, k + 1):
            drop.add(k)
        else:
            first = rows[k + 1]
            raise RecordingError(
                f"{where}: the index column and the time column disagree at "
                f"{_row_name(lines, int(first))}: t advances {t[k + 1] - t[k]:.6g} s while "
                f"the index advances {idx[k + 1] - idx[k]:.0f} samples "
                f"({period * (idx[k + 1] - idx[k]):.6g} s at the period the file gives "
                "elsewhere); a counter of rows written is no sample index: leave one of "
                "them out (--columns)")
    if len(drop) > max(1, INDEX_DISAGREE_SHARE * rows.size):
        raise RecordingError(
            f"{where}: the index column and the time column disagree at {len(drop)} rows "
            f"(first at {_row_name(lines, int(rows[min(drop)]))}); leave one of them out "
            "(--columns)")
    out = keep.copy()
    out[rows[sorted(drop)]] = False
    return out


RATE_WINDOW_ROWS = 2000
"""Rows of a run of stamps over which :func:`rate_change` measures the local period by
least squares."""
RATE_MEDIAN_ROWS = 101
"""Intervals per block of which :func:`rate_change` takes the median as the local one."""
RUN_STEP_TOLERANCE = 0.5
"""Largest departure (in local periods) of an interval between consecutive stamps within
a run of :func:`rate_change`: stamps jittered by up to a quarter period stay in runs, and
a missing sample (two periods) is never taken for one period. (At 3/4, stamps jittered by
0.3 period with 1 % of the samples missing read as a rate change: holes counted as one
period bent the local periods.)"""
RUN_HOLE_TOLERANCE = 0.2
"""An interval within this (in local periods) of a whole number of 2 or more is a run's
hole of that many periods less one."""
COUNTED_CHANGE = 0.4
"""A change of period by this much (relative) or more is placed by the intervals that are
not one period of their side's rate (:func:`_change_row`); a smaller one by least
squares on the stamps."""
RATE_CHANGE_Z = 10.0
"""z of the difference of the local periods before and after the best split that
:func:`rate_change` needs (the largest of ~1000 splits of a steady clock stays near 4)."""
RATE_CHANGE_SLIP = 1.0
"""Samples that indexing at one rate must slip over the record (from the local periods)
before a change of period is reported: less is read as one rate without a fake hole."""


@dataclass(frozen=True)
class RateChange:
    """The stamps' period changes within the record: ``before_hz`` up to row ``row``
    (0-based, of the stamps given), ``after_hz`` from it; ``slip`` samples is how far
    indexing at one rate drifts from the stamps over the record; ``drift``: the period
    changes gradually (a trend fits the local periods better than one step), ``row``
    is then where the trend crosses the mean period."""

    row: int
    before_hz: float
    after_hz: float
    slip: float
    drift: bool = False


def _windows(t: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                        np.ndarray]:
    """(first stamp, period, its standard error, cumulative sample count) of the windows of
    :func:`rate_change`: :data:`RATE_WINDOW_ROWS` stamps of a run (consecutive rows whose
    intervals are one local period within :data:`RUN_STEP_TOLERANCE`, or a whole number
    of them within :data:`RUN_HOLE_TOLERANCE`), the period the least-squares slope of t
    against the samples counted. The local period is the median interval of blocks of
    :data:`RATE_MEDIAN_ROWS`, so a run follows a rate that changes."""
    dt = np.diff(t)
    blocks = -(-dt.size // RATE_MEDIAN_ROWS)
    padded = np.full(blocks * RATE_MEDIAN_ROWS, np.nan)
    padded[:dt.size] = dt
    with np.errstate(all="ignore"):
        med = np.repeat(np.nanmedian(padded.reshape(blocks, RATE_MEDIAN_ROWS), axis=1),
                        RATE_MEDIAN_ROWS)[:dt.size]
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(med > 0, dt / med, np.nan)
    r = np.nan_to_num(r, nan=0.0)
    whole = np.rint(r)
    single = np.abs(r - 1.0) < RUN_STEP_TOLERANCE
    hole = (whole >= 2) & (np.abs(r - whole) < RUN_HOLE_TOLERANCE) & ~single
    ok = (np.diff(rows) == 1) & (single | hole)
    count = np.concatenate(([0.0], np.cumsum(np.where(single, 1.0, np.where(hole, whole,
                                                                           0.0)))))
    breaks = np.flatnonzero(~ok)
    starts = np.concatenate(([0], breaks + 1))
    ends = np.concatenate((breaks + 1, [t.size]))
    long = np.flatnonzero(ends - starts >= RATE_WINDOW_ROWS)
    firsts = [np.arange(starts[k], ends[k] - RATE_WINDOW_ROWS + 1, RATE_WINDOW_ROWS)
              for k in long]
    first = np.concatenate(firsts) if firsts else np.zeros(0, np.int64)
    if first.size == 0:
        return first, np.zeros(0), np.zeros(0), count
    at = first[:, None] + np.arange(RATE_WINDOW_ROWS)[None, :]
    x = count[at] - count[first][:, None]
    y = t[at] - t[first][:, None]
    xc = x - x.mean(axis=1, keepdims=True)
    yc = y - y.mean(axis=1, keepdims=True)
    sxx = np.sum(xc * xc, axis=1)
    period = np.sum(xc * yc, axis=1) / sxx
    resid = yc - period[:, None] * xc
    se = np.sqrt(np.sum(resid * resid, axis=1) / (RATE_WINDOW_ROWS - 2) / sxx)
    return first, period, se, count


def _change_row(t: np.ndarray, count: np.ndarray, lo: int, hi: int, before_s: float,
                after_s: float) -> int:
    """The first stamp in ``t[lo:hi]`` after the period ``after_s`` replaced ``before_s``.

    A change by less than :data:`COUNTED_CHANGE` (relative): least squares over the
    hinge (stamps on the first line up to it, on the second after; the counted samples
    ``count`` as abscissa), in one pass of suffix sums. A larger one: the hinge that
    leaves the fewest intervals that are not one period of their side's rate (at half
    the rate every interval after the change is two periods of the first; stamps alone
    cannot tell that from every other sample missing, the run of regular intervals
    does)."""
    if abs(after_s / before_s - 1.0) >= COUNTED_CHANGE:
        dt = np.diff(t[lo:hi])
        # a quarter period: at half the rate an interval of the first is exactly half of
        # the second's, on the run tolerance's edge
        off1 = np.abs(dt / before_s - 1.0) >= 0.5 * RUN_STEP_TOLERANCE
        off2 = np.abs(dt / after_s - 1.0) >= 0.5 * RUN_STEP_TOLERANCE
        # hinge k: intervals before it judged by the first rate, from it by the second
        cost = (np.concatenate(([0], np.cumsum(off1)))
                + np.concatenate((np.cumsum(off2[::-1])[::-1], [0])))
        return lo + int(np.argmin(cost)) + 1  # interval k ends at stamp k + 1
    c = count[lo:hi] - count[lo]
    lead = max(min(RATE_WINDOW_ROWS // 4, (hi - lo) // 4), 1)
    u = t[lo:hi] - before_s * c
    u = u - np.median(u[:lead])  # on the first line: 0 up to the change, then a ramp
    d = after_s - before_s
    n = np.arange(c.size, 0, -1, dtype=np.float64)  # stamps from each one on

    def suffix(v: np.ndarray) -> np.ndarray:
        return np.cumsum(v[::-1])[::-1]

    s_uu, s_u, s_uc = suffix(u * u), suffix(u), suffix(u * c)
    s_c, s_cc = suffix(c), suffix(c * c)
    # SSE(k) = sum_{x<k} u^2 + sum_{x>=k} (u - d (c - c_k))^2, k the first stamp after
    after = s_uu - 2 * d * (s_uc - c * s_u) + d * d * (s_cc - 2 * c * s_c + n * c * c)
    sse = float(s_uu[0]) - s_uu + after
    return lo + int(np.argmin(sse)) + 1  # the hinge stamp is on both lines


def rate_change(t_s: np.ndarray, rate_hz: float) -> RateChange | None:
    """Whether time stamps hold more than one sample rate (a logger whose clock changed,
    two sessions at different ODRs written as one file, a clock that drifts), or None.

    Indexed at one rate, a record whose period changes by 2 % half-way is read with a
    one-sample hole every 50 samples where the rate is lower (588 samples "missing" from
    30 000 at 102 Hz after 104 Hz), a row dropped as "damaged" every 50 where it is higher
    (566 good rows skipped at 106 Hz), and every other sample missing at half the rate.
    The local period is the least-squares slope over windows of runs of stamps
    (:func:`_windows`: jitter does not accumulate in a slope; holes in stamps without much
    jitter are counted). A change is reported when the local periods make indexing at one
    rate slip by :data:`RATE_CHANGE_SLIP` sample or more over the record and, at the best
    split of the windows in time, the mean periods before and after differ by
    :data:`RATE_CHANGE_Z` standard errors (widened by the windows' own scatter about
    them). The change is placed to the stamp (:func:`_change_row`); a linear trend of the
    periods that fits them better than the step is reported as a drift. Stamps jittered
    by a quarter period or more make no long runs, and are not checked.
    """
    step = 1.0 / rate_hz
    rows = np.flatnonzero(np.isfinite(t_s))
    if rows.size < 2 * RATE_WINDOW_ROWS:
        return None
    t = t_s[rows]
    first, period, se, count = _windows(t, rows)
    if period.size < 2:
        return None
    k_w = period / step - 1.0  # relative departure of each window's period
    wt = 1.0 / np.maximum(se / step, 1e-12) ** 2
    samples = (count[first + RATE_WINDOW_ROWS - 1] - count[first]) + 1.0
    slip_w = np.cumsum(k_w * samples)
    slip = float(np.ptp(np.concatenate(([0.0], slip_w))))
    if slip < RATE_CHANGE_SLIP:
        return None
    c_w, c_wk = np.cumsum(wt), np.cumsum(wt * k_w)
    w1, w2 = c_w[:-1], c_w[-1] - c_w[:-1]
    m1, m2 = c_wk[:-1] / w1, (c_wk[-1] - c_wk[:-1]) / w2
    z_all = np.abs(m1 - m2) / np.sqrt(1.0 / w1 + 1.0 / w2)
    j = int(np.argmax(z_all)) + 1  # windows [0, j) before, [j, n) after
    before, after = float(m1[j - 1]), float(m2[j - 1])
    resid = np.concatenate((k_w[:j] - before, k_w[j:] - after))
    dof = max(k_w.size - 2, 1)
    step_chi2 = float(resid**2 @ wt)
    if float(z_all[j - 1]) / max(math.sqrt(step_chi2 / dof), 1.0) < RATE_CHANGE_Z:
        return None
    centre = t[first + RATE_WINDOW_ROWS // 2]
    trend = np.polyfit(centre, k_w, 1, w=np.sqrt(wt))
    trend_chi2 = float((k_w - np.polyval(trend, centre)) ** 2 @ wt)
    if trend_chi2 < step_chi2:  # a drift: from the first window's period to the last's
        ends = np.polyval(trend, centre[[0, -1]])
        mid = int(first[int(np.argmin(np.abs(np.polyval(trend, centre) - k_w.mean())))])
        return RateChange(int(rows[mid]), rate_hz / (1.0 + float(ends[0])),
                          rate_hz / (1.0 + float(ends[1])), slip, drift=True)
    lo = int(first[max(j - 2, 0)])
    hi = int(min(first[min(j + 1, first.size - 1)] + RATE_WINDOW_ROWS, t.size))
    row = _change_row(t, count, lo, hi, step * (1.0 + before), step * (1.0 + after))
    return RateChange(int(rows[row]), rate_hz / (1.0 + before), rate_hz / (1.0 + after),
                      slip)


def check_one_rate(t_s: np.ndarray, rate_hz: float, where: Callable[[int], str]) -> None:
    """RecordingError when the stamps hold two sample rates (:func:`rate_change`);
    ``where(row)`` names the row the new rate starts at (for a drift: where the periods
    cross their mean) in the reader's terms (a file's line, a bag's message)."""
    change = rate_change(t_s, rate_hz)
    if change is not None:
        raise RecordingError(_rate_change_message(change, where(change.row)))


def _rate_change_message(change: RateChange, where: str) -> str:
    """The error for a record whose stamps hold two rates (``where`` names the row)."""
    if change.drift:
        return (f"{where}: the sample rate drifts within the file: the time stamps give "
                f"{change.before_hz:.6g} Hz at its start and {change.after_hz:.6g} Hz at "
                f"its end; read at one rate they would slip {change.slip:.0f} sample(s) "
                "over the record (holes that are no lost samples, good rows dropped as "
                "damaged). Read the rows in order at one rate with --rate HZ --columns "
                "t=- (holes in the stamps are then not seen)")
    return (f"{where}: the sample rate changes here: the time stamps give "
            f"{change.before_hz:.6g} Hz before and {change.after_hz:.6g} Hz from here; "
            f"read at one rate they would slip {change.slip:.0f} sample(s) over the "
            "record (holes that are no lost samples, good rows dropped as damaged). "
            "Split the file here, or read the rows in order at one rate with --rate HZ "
            "--columns t=- (holes in the stamps are then not seen)")


def timebase_from_index(index: np.ndarray, t_s: np.ndarray | None, where: str,
                        rate_hz: float | None = None,
                        lines: np.ndarray | None = None) -> Timebase:
    """Rate of rows with a sample-index column: given, else the least-squares slope of
    the times against the index. Rows whose index does not increase are dropped, and
    rows whose index contradicts the time stamps around them
    (:func:`_consistent_with_times`); a counter that wraps or restarts
    (:data:`RESTART_RUN`) is refused. ``lines``: the file's line number of each
    row, for messages."""
    index = np.asarray(index, dtype=np.int64)
    keep = increasing_rows(index)
    for b in np.nonzero(np.diff(index) < 0)[0].tolist():
        run = index[b + 1:b + 1 + RESTART_RUN]
        before = index[b - 1] if b else index[b]  # below the row before too: not one
        if (run.size == RESTART_RUN and bool(np.all(np.diff(run) > 0))  # high outlier
                and run[-1] < index[b] and run[0] <= before):
            raise RecordingError(
                f"{where}: the index column goes back at {_row_name(lines, b + 1)} "
                f"({index[b]} -> {index[b + 1]}) and counts up again from there: a counter "
                "that wraps or restarts is no sample index; leave it out (--columns "
                "without it) to index the rows by their time stamps")
    if t_s is not None:
        keep = _consistent_with_times(index, t_s, keep, where, lines)
    keep = stray_ends(index, keep)
    kept = index[keep]
    if rate_hz is not None:
        return Timebase(rate_hz, kept, keep, "given")
    if t_s is None or len(kept) < 2 or np.ptp(kept) == 0:
        raise RecordingError(f"{where}: a sample index but no times to infer the rate "
                             "from; give --rate HZ")
    step = _slope(kept.astype(np.float64), t_s[keep])
    if not step > 0:
        raise RecordingError(f"{where}: the time column does not increase with the index; "
                             "give --rate HZ")
    return Timebase(1.0 / step, kept, keep, "from t against the index (least squares)")
