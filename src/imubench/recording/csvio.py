"""CSV interchange: header ``t,gx,gy,gz,ax,ay,az,temp`` (any subset of channel columns).

Units: ``t`` seconds since the start, ``gx gy gz`` dps, ``ax ay az`` g, ``temp`` degC.
Lines starting with ``#`` before the header carry metadata as ``# key: <JSON value>``
(``odr_hz``, ``chip``, ... as in the native header). Lines ``# gap at_index=N lost=M
reason=TEXT`` anywhere record an explicit gap. An empty field is a missing value (NaN).
The output data rate is the ``odr_hz`` metadata when present, else ``1 / median(diff(t))``.
Sample indices come from an optional ``index`` column (imubench writes it), else are
``round((t - t[0]) * odr_hz)``, so a jump in ``t`` is a gap.
Files ending in ``.gz`` are gzip-compressed.
"""

from __future__ import annotations

import gzip
import io
import json
import math
import re
from pathlib import Path
from typing import IO, Any

import numpy as np

from imubench.batch import CHANNELS, Batch, Gap, explain_holes
from imubench.errors import RecordingError

COLUMNS: tuple[str, ...] = ("t", *CHANNELS, "temp")
INDEX_COLUMN = "index"
"""Optional extra column: the sample index (ODR periods since start). imubench writes it
because a real sensor's clock runs off nominal, so ``t * odr_hz`` drifts from the index."""
_GAP = re.compile(r"#\s*gap\s+at_index=(-?\d+)\s+lost=(\d+)(?:\s+reason=(.*))?")


def _open_text(path: Path, mode: str) -> IO[str]:
    if path.suffix == ".gz":
        return gzip.open(path, mode + "t", encoding="utf-8", newline="")  # type: ignore[return-value]
    return open(path, mode, encoding="utf-8", newline="")


class CsvWriter:
    """Writes Batches as CSV rows (values as printed with 9 significant digits)."""

    def __init__(self, path: str | Path, metadata: dict[str, Any], **_: Any) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if self.path.exists():
            raise RecordingError(f"{self.path}: exists already; recordings are never overwritten")
        self.metadata = dict(metadata)
        self.samples = 0
        self.gaps = 0
        self.lost_samples = 0
        self._last_index: int | None = None
        self._fh = _open_text(self.path, "w")
        for key in sorted(self.metadata):
            self._fh.write(f"# {key}: {json.dumps(self.metadata[key], default=str)}\n")
        self._fh.write(",".join((*COLUMNS, INDEX_COLUMN)) + "\n")

    def write(self, batch: Batch) -> None:
        """Append rows; every hole gets ``# gap`` lines (one per declared reason, see
        :func:`~imubench.batch.explain_holes`) before the sample after it."""
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
        table = np.column_stack([batch.t_s, batch.values, batch.temp_c, batch.index])
        last = int(batch.index[-1])
        for at in [a for a in holes if a <= int(batch.index[0]) or a > last]:
            for g in holes.pop(at):
                self._gap_line(buf, g.at, g.lost, g.reason)
        for idx, row in zip(batch.index, table, strict=True):
            if holes and int(idx) in holes:
                for g in holes.pop(int(idx)):
                    self._gap_line(buf, g.at, g.lost, g.reason)
            buf.write(",".join("" if math.isnan(v) else f"{v:.9g}" for v in row) + "\n")
        self._fh.write(buf.getvalue())
        self._fh.flush()
        self.samples += len(batch)
        self._last_index = int(batch.index[-1])

    def _gap_line(self, fh: IO[str], at: int, lost: int, reason: str) -> None:
        fh.write(f"# gap at_index={at} lost={lost} reason={reason}\n")
        self.gaps += 1
        self.lost_samples += lost

    def write_gap(self, at_index: int, lost: int, reason: str) -> None:
        self._gap_line(self._fh, at_index, lost, reason)

    def close(self) -> None:
        if not self._fh.closed:
            self._fh.close()

    def __enter__(self) -> CsvWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_csv(path: str | Path) -> tuple[dict[str, Any], Batch, list[Gap]]:
    """Parse a CSV recording; errors name the file, line and column."""
    path = Path(path)
    meta: dict[str, Any] = {}
    gaps: list[Gap] = []
    header: list[str] | None = None
    rows: list[list[float]] = []
    try:
        fh = _open_text(path, "r")
    except OSError as exc:
        raise RecordingError(f"{path}: cannot open: {exc.strerror}") from None
    with fh:
        for lineno, line in enumerate(fh, 1):
            line = line.strip()
            if not line:
                continue
            if line.startswith("#"):
                gap = _GAP.match(line)
                if gap:
                    gaps.append(Gap(int(gap[1]), int(gap[2]), (gap[3] or "").strip()))
                elif header is None and ":" in line:
                    key, _, value = line[1:].partition(":")
                    try:
                        meta[key.strip()] = json.loads(value)
                    except json.JSONDecodeError:
                        meta[key.strip()] = value.strip()
                continue
            fields = [f.strip() for f in line.split(",")]
            if header is None:
                header = fields
                unknown = [c for c in header if c not in (*COLUMNS, INDEX_COLUMN)]
                if unknown or "t" not in header or len(set(header)) != len(header):
                    raise RecordingError(
                        f"{path}:{lineno}: bad CSV header {line!r}: columns must be t plus "
                        f"a subset of {','.join(COLUMNS[1:])}, each once"
                    )
                continue
            if len(fields) != len(header):
                raise RecordingError(
                    f"{path}:{lineno}: {len(fields)} fields, header has {len(header)}"
                )
            row = []
            for col, text in zip(header, fields, strict=True):
                if text == "":
                    row.append(math.nan)
                    continue
                try:
                    row.append(float(text))
                except ValueError:
                    raise RecordingError(
                        f"{path}:{lineno}: column {col!r}: {text!r} is not a number"
                    ) from None
            rows.append(row)
    if header is None:
        raise RecordingError(f"{path}: no CSV header line (expected t,gx,gy,gz,ax,ay,az,temp)")
    table = np.array(rows, dtype=np.float64).reshape(len(rows), len(header))
    columns = {name: table[:, i] for i, name in enumerate(header)}
    t = columns["t"]
    odr = meta.get("odr_hz")
    if odr is None:
        if len(t) < 2:
            raise RecordingError(f"{path}: cannot infer the rate from one row; add '# odr_hz: N'")
        odr = float(1.0 / np.median(np.diff(t)))
        meta["odr_hz"] = odr
    n = len(t)
    if INDEX_COLUMN in columns:
        index = columns[INDEX_COLUMN].astype(np.int64)
    else:
        index = np.rint((t - t[0]) * float(odr)).astype(np.int64) if n else np.zeros(0, np.int64)
    if n > 1 and np.any(np.diff(index) <= 0):
        bad = int(np.nonzero(np.diff(index) <= 0)[0][0]) + 1
        raise RecordingError(
            f"{path}: data row {bad + 1}: t={t[bad]!r} does not fall on a later sample "
            f"period than the row before at odr_hz={odr}; fix 't' or the odr_hz metadata"
        )
    values = np.full((n, len(CHANNELS)), np.nan)
    for i, name in enumerate(CHANNELS):
        if name in columns:
            values[:, i] = columns[name]
    temp = columns.get("temp", np.full(n, np.nan))
    meta.setdefault("channels", [c for c in CHANNELS if c in columns])
    batch = Batch(index=index, t_s=t, values=values, temp_c=temp)
    return meta, batch, gaps
