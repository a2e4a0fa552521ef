"""Export of one channel to a Stable32 / allantools data file (``.dat``).

Stable32 and allantools read a data file as plain text: ``#`` comment lines, then one
value per line (frequency data; here a rate in dps or an acceleration in g), or a time
tag and a value per line, the tag a Modified Julian Date in days. The Stable32
distribution's own ``PHASE.DAT`` is written this way (``#`` lines, then one value per
line), and allantools' test reader skips ``#`` lines and reads one float per line. What
imubench writes:

* ``#`` comment lines first: a title, then ``# key: <JSON>`` lines (``channel``, ``unit``,
  ``odr_hz``, ``tau0_s``, ``samples``, ``lost_samples``, ``source``, ``start_utc``):
  Stable32 and allantools skip them; imubench's reader takes the rate and the channel
  from them, so the file reads back as what it was.
* A recording without lost samples: one value per line (the shortest decimal that reads
  back to the same float64), tau0 = 1 / ``odr_hz``.
* A recording with lost samples: two columns, the MJD time tag (days, 12 decimals: 86 ns)
  and the value; a lost sample has no line, so its hole is in the tags (Stable32 fills
  gaps from time tags; a one-column file cannot show a hole without a sentinel value).
  The tags count from ``start_utc`` when the recording states it, else from MJD 51544
  (2000-01-01, stated in the header).
"""

from __future__ import annotations

import datetime as _dt
import json
from pathlib import Path
from typing import IO, TYPE_CHECKING

import numpy as np

from imubench.batch import UNITS
from imubench.errors import RecordingError
from imubench.recording.commit import need_parent
from imubench.recording.timebase import MJD_OF_UNIX_EPOCH, SECONDS_PER_DAY
from imubench.recording.timebase import start_utc as iso_utc

if TYPE_CHECKING:
    from imubench.recording import Recording

MJD_EPOCH = _dt.datetime(1858, 11, 17, tzinfo=_dt.UTC)
"""MJD 0."""
FALLBACK_MJD = 51544.0
"""2000-01-01 00:00 UTC: the first tag of a recording that states no start time."""


def _start_mjd(start_utc: object) -> float | None:
    if not isinstance(start_utc, str):
        return None
    try:
        t = _dt.datetime.fromisoformat(start_utc.replace("Z", "+00:00"))
    except ValueError:
        return None
    if t.tzinfo is None:
        t = t.replace(tzinfo=_dt.UTC)
    return (t - MJD_EPOCH).total_seconds() / SECONDS_PER_DAY


def write_stable32(rec: Recording, channel: str, path: str | Path) -> str:
    """Write ``channel`` of ``rec`` to ``path`` (module docstring); never overwrites.
    Returns what was written, one line for the terminal."""
    path = Path(path)
    if channel not in UNITS:
        raise RecordingError(f"{path}: --channel {channel!r}: one of {', '.join(UNITS)}")
    if channel not in rec.channels:
        raise RecordingError(f"{rec.path}: no data in channel {channel}; it has "
                             f"{', '.join(rec.channels)}")
    if path.exists():
        raise RecordingError(f"{path}: exists already; recordings are never overwritten")
    series = rec.channel(channel)
    have = np.isfinite(series)
    # holes inside, and the gaps declared before the first or after the last sample
    lost = int((~have).sum()) + rec.lost_samples - (len(series) - len(rec))
    rate = rec.rate_hz
    meta: dict[str, object] = {
        "channel": channel, "unit": UNITS[channel], "odr_hz": rate, "tau0_s": 1.0 / rate,
        "samples": int(have.sum()), "lost_samples": lost, "source": str(rec.path),
    }
    cal = rec.metadata.get("calibration")
    if isinstance(cal, dict) and cal.get("applied"):
        meta["calibration"] = {k: cal.get(k) for k in ("applied", "path", "sha256")}
    if rec.damage:
        meta["damage"] = rec.damage
    # the recording's start, else its first stamp when the stamps are Unix seconds (a
    # CSV of Unix or ISO times: the .dat said "states no start", tags from 2000-01-01)
    stated = rec.metadata.get("start_utc") or (iso_utc(float(rec.t_s[0])) if len(rec)
                                               else None)
    start = _start_mjd(stated)
    first = int(rec.index[0]) if len(rec) else 0
    if start is not None:
        meta["start_utc"] = stated
        if first and rec.metadata.get("start_utc"):  # the first line's time (a reader
            # starts there); a start read off the first stamp is that line's already
            meta["start_utc"] = iso_utc((start - MJD_OF_UNIX_EPOCH) * SECONDS_PER_DAY
                                        + first / rate) or meta["start_utc"]
    layout = "one value per line"
    if lost:
        layout = "MJD time tag (days) and value per line; lost samples have no line"
        if start is None:
            meta["time_tag_epoch"] = "MJD 51544 (2000-01-01): the recording states no start"
            start = FALLBACK_MJD
    need_parent(path)
    with open(path, "x", encoding="ascii", newline="\n") as fh:
        fh.write(f"# imubench Stable32 data file: frequency data ({channel} in "
                 f"{UNITS[channel]}), {layout}\n")
        for key, value in meta.items():
            fh.write(f"# {key}: {json.dumps(value)}\n")
        _write_values(fh, series, have, rate, start if lost else None, first)
    return (f"{path}: Stable32 data file of {channel} ({UNITS[channel]}), {int(have.sum())} "
            f"values, tau0 {1.0 / rate:.6g} s, {layout}")


def _write_values(fh: IO[str], series: np.ndarray, have: np.ndarray, rate_hz: float,
                  start_mjd: float | None, first_index: int, block: int = 65536) -> None:
    """The values of ``series`` (its element 0 is sample ``first_index``), one per line,
    with their MJD time tags from ``start_mjd`` (sample 0) when given."""
    k = np.nonzero(have)[0]
    for s in range(0, len(k), block):
        part = k[s:s + block]
        values = series[part].tolist()
        if start_mjd is None:
            fh.write("".join(f"{v!r}\n" for v in values))
        else:
            tags = (start_mjd + (first_index + part) / rate_hz / SECONDS_PER_DAY).tolist()
            fh.write("".join(f"{t:.12f} {v!r}\n" for t, v in zip(tags, values, strict=True)))
