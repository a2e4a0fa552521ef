"""CSV interchange written by imubench: header ``t,gx,gy,gz,ax,ay,az,temp,index``.

Units: ``t`` seconds (since the start; a converted file keeps its source's origin),
``gx gy gz`` dps, ``ax ay az`` g, ``temp`` degC,
``index`` the sample index (ODR periods since the start). Lines starting with ``#``
before the header carry metadata as ``# key: <JSON value>`` (``odr_hz``, ``chip``, ... as
in the native header; ``# units:`` the columns' units, :data:`COLUMN_UNITS`). Lines
``# gap at_index=N lost=M reason=TEXT`` record a declared gap before the sample after
them. An empty field is a missing value (NaN). Files ending
in ``.gz`` are gzip-compressed.

Number formats (what a round trip keeps): ``t`` is written exactly, as the shortest text
that reads back as the same float64 (Python's ``repr``; up to 17 significant digits), so
absolute epoch stamps that a converted file keeps (EuRoC, ROS exports: ~1.7e9 s) keep all
the precision the reader holds (float64: 0.24 us at 1.7e9 s), and a 30-day log at 1 kHz
(2.6e6 s: 0.5 ns) keeps sub-sample resolution. ``index`` is an exact integer. The values
(``gx`` .. ``az``, ``temp``) are written with 9 significant digits: exact for float32
samples, and for float64 values from elsewhere a relative error below 5e-9, far finer
than the resolution of a MEMS sensor (a 24-bit converter's step is 6e-8 of full scale).

Reading (of these files and of CSV from elsewhere):
:mod:`imubench.recording.textin`.
"""

from __future__ import annotations

import contextlib
import gzip
import io
import json
import logging
import math
import os
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

import numpy as np

from imubench.batch import CHANNELS, UNITS, Batch, Gap, explain_holes
from imubench.errors import RecordingError
from imubench.recording.commit import cut_back, need_parent
from imubench.recording.timebase import utc_now

COLUMNS: tuple[str, ...] = ("t", *CHANNELS, "temp")
COLUMN_UNITS: dict[str, str] = {"t": "s", **UNITS, "index": "samples"}
"""The ``# units:`` metadata line of every CSV imubench writes."""
INDEX_COLUMN = "index"
"""Optional extra column: the sample index (ODR periods since start). imubench writes it
because a real sensor's clock runs off nominal, so ``t * odr_hz`` drifts from the index."""

log = logging.getLogger("imubench.recording")


def _open_text(path: Path, mode: str) -> IO[str]:
    if path.suffix.lower() == ".gz":
        return gzip.open(path, mode + "t", encoding="utf-8", newline="")  # type: ignore[return-value]
    return open(path, mode, encoding="utf-8", newline="")


def _time_text(t: float) -> str:
    """``t`` exactly: the shortest text that reads back as the same float64 (``repr``);
    empty for NaN."""
    return "" if math.isnan(t) else repr(t)


class CsvWriter:
    """Writes Batches as CSV rows (number formats: the module docstring)."""

    def __init__(self, path: str | Path, metadata: dict[str, Any], **_: Any) -> None:
        self.path = Path(path)
        need_parent(self.path)
        if self.path.exists():
            raise RecordingError(f"{self.path}: exists already; recordings are never overwritten")
        self.metadata = dict(metadata)
        self.metadata["units"] = COLUMN_UNITS  # the header says what the columns are in
        cal = self.metadata.get("calibration")
        if isinstance(cal, dict) and cal.get("applied"):
            log.warning("%s: a CSV holds the calibrated values only (it has no raw-count "
                        "columns): keep an .imbr or .h5 recording to go back to what the "
                        "chip said", self.path)
        # a live recording starts now, as a native one (convert states the source's)
        self.metadata.setdefault("start_utc", utc_now())
        self.samples = 0
        self.gaps = 0
        self.lost_samples = 0
        self._last_index: int | None = None
        self._fh = _open_text(self.path, "w")
        for key in sorted(self.metadata):
            self._fh.write(f"# {key}: {json.dumps(self.metadata[key], default=str)}\n")
        self._fh.write(",".join((*COLUMNS, INDEX_COLUMN)) + "\n")
        self._fh.flush()
        self._committed = os.fstat(self._fh.fileno()).st_size

    def write(self, batch: Batch) -> None:
        """Append rows; every hole gets ``# gap`` lines (one per declared reason, see
        :func:`~imubench.batch.explain_holes`) before the sample after it. A batch that
        cannot be written whole is taken back (:func:`~imubench.recording.commit.cut_back`;
        in a ``.gz`` file the cut leaves a stream without its end, which readers report)."""
        with self._all_or_nothing():
            self._write(batch)

    @contextlib.contextmanager
    def _all_or_nothing(self) -> Iterator[None]:
        """Commit what the block writes, or take it all back (counters and bytes)."""
        if self._fh.closed:
            raise RecordingError(f"{self.path}: writer is closed")
        counts = (self.samples, self.gaps, self.lost_samples, self._last_index)
        try:
            yield
        except OSError:
            self.samples, self.gaps, self.lost_samples, self._last_index = counts
            cut_back(self.path, self._fh, self._committed)
            raise
        self._committed = os.fstat(self._fh.fileno()).st_size

    def _write(self, batch: Batch) -> None:
        holes: dict[int, list[Gap]] = {}
        for gap in explain_holes(batch, self._last_index):
            holes.setdefault(gap.at, []).append(gap)
        buf = io.StringIO()
        if not len(batch):
            for gaps in holes.values():
                for g in gaps:
                    self._gap_line(buf, g.at, g.lost, g.reason)
            self._fh.write(buf.getvalue())
            self._fh.flush()
            return
        table = np.column_stack([batch.values, batch.temp_c])
        last = int(batch.index[-1])
        for at in [a for a in holes if a <= int(batch.index[0]) or a > last]:
            for g in holes.pop(at):
                self._gap_line(buf, g.at, g.lost, g.reason)
        for idx, t, row in zip(batch.index.tolist(), batch.t_s.tolist(), table, strict=True):
            if holes and idx in holes:
                for g in holes.pop(idx):
                    self._gap_line(buf, g.at, g.lost, g.reason)
            buf.write(_time_text(t) + ","
                      + ",".join("" if math.isnan(v) else f"{v:.9g}" for v in row)
                      + f",{idx}\n")
        self._fh.write(buf.getvalue())
        self._fh.flush()
        self.samples += len(batch)
        self._last_index = int(batch.index[-1])

    def _gap_line(self, fh: IO[str], at: int, lost: int, reason: str) -> None:
        fh.write(f"# gap at_index={at} lost={lost} reason={reason}\n")
        self.gaps += 1
        self.lost_samples += lost

    def write_gap(self, at_index: int, lost: int, reason: str) -> None:
        with self._all_or_nothing():
            self._gap_line(self._fh, at_index, lost, reason)
            self._fh.flush()

    def close(self) -> None:
        if not self._fh.closed:
            self._fh.close()

    def __enter__(self) -> CsvWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
