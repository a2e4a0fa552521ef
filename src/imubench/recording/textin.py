"""Reading delimited text recordings: imubench's CSV, other loggers' CSV, ROS and EuRoC
exports, Stable32 / allantools one- and two-column files (``.gz`` for all).

* Delimiter: comma, semicolon (a decimal comma is then read as a point), tab, or runs of
  spaces, from the header (or first data) line.
* Header: the first line that is not a comment, or a ``#`` line whose fields are column
  names (EuRoC writes ``#timestamp [ns],...``). ``# key: value`` lines before it are
  metadata (imubench writes ``# odr_hz: 104``; the rate and unit keys other tools write
  are read too, :mod:`imubench.recording.textmeta`), ``# gap at_index=N lost=M
  reason=TEXT`` lines anywhere are declared gaps (one that cannot be read is refused;
  one that the samples read contradict is cut to them, with a warning:
  :func:`_checked_gaps`). Columns: :mod:`imubench.recording.columns`.
* imubench's CSV with no data lines (its header and rate stated) is a recording of no
  samples (:func:`_empty_own_csv`), as a native file of no samples is.
* Encoding: UTF-8 (with or without a byte-order mark), UTF-16 with its mark, else
  Windows-1252, said in the notes.
* Numbers: Fortran's ``1.5D-03`` exponents are read; a headerless file of one column with
  decimal commas (``0,0123``: two comma-separated fields whose second is digits only) is
  read as one column, said in the notes.
* No header (all numbers): one column is the values; two columns are (time tag, value),
  as Stable32 and allantools write them; more need ``--columns`` by number. The values
  are channel ``gx``, or the channel a ``# channel: "ax"`` line names (imubench's
  Stable32 export, :mod:`imubench.recording.stable32`, writes it).
* Rate and indices: :mod:`imubench.recording.timebase`; units:
  :mod:`imubench.recording.options`.
* A data line that cannot be read (wrong number of fields, not a number: a truncated
  last line, a flipped byte) is skipped and counted, and so is a row whose time stamp
  falls on an earlier sample than the rows around it; the caller reports them. A file
  in which most lines cannot be read is refused.
"""

from __future__ import annotations

import csv
import gzip
import json
import math
import re
import zlib
from array import array
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

from imubench.batch import CHANNELS, Batch, Gap, true_runs
from imubench.errors import RecordingError
from imubench.recording.columns import (
    OWN_NAMES,
    TIME_UNIT_WORDS,
    Column,
    capital_t,
    is_euroc,
    is_ros_export,
    map_columns,
    near_alias,
    normalise,
    unit_word,
)
from imubench.recording.options import (
    ACCEL_UNITS_G,
    GYRO_UNITS_DPS,
    NO_TIME_COLUMN,
    TIME_UNITS_S,
    InputOptions,
)
from imubench.recording.textmeta import (
    SNIFF_BYTES,
    rate_line,
    split_key_unit,
    stated_rate,
    stated_unit,
    text_encoding,
)
from imubench.recording.timebase import (
    GIVEN_RATE_TOLERANCE,
    MJD_OF_UNIX_EPOCH,
    SECONDS_PER_DAY,
    Timebase,
    check_one_rate,
    increasing_step,
    start_utc,
    time_unit_from_spacing,
    timebase_from_index,
    timebase_from_times,
)

GAP_LINE = re.compile(r"#\s*gap\s+\w+\s*=")
"""A ``# gap`` line: ``gap`` and a ``key=`` after it (a comment that starts with the word
is not one); its fields are :data:`GAP_FIELDS`, or the file is refused."""
GAP_FIELDS = re.compile(r"#\s*gap\s+at_index=(\S*)\s+lost=(\S*)(?:\s+reason=(.*))?$")
GAP_FORM = "# gap at_index=N lost=M reason=TEXT"
MOSTLY_BAD = 0.5
"""A file whose data lines are more than this share unreadable is not a table."""


@dataclass
class TextRead:
    """What the text reader found: metadata, the samples, declared gaps, damage, notes."""

    meta: dict[str, Any]
    batch: Batch
    gaps: list[Gap]
    bad_lines: list[int] = field(default_factory=list)
    """Line numbers of data lines skipped (unreadable, out of time order, or a
    stray stamp at an end: :func:`imubench.recording.timebase.stray_ends`)."""
    notes: list[str] = field(default_factory=list)
    """How the file was read, for the user (format, columns, rate, units)."""
    inferred: bool = False
    """True when the notes say something the user must know: a foreign format or a rate
    not stated by the file or ``--rate``."""
    item: str = "data line"
    """What ``bad_lines`` number: data lines, or messages of a bag."""
    rate_stated: bool = False
    """The rate is the one the file states (``# odr_hz``), not read off its time column:
    the time stamps may then show the chip's clock off it
    (:func:`imubench.recording.measured_rate`)."""
    warnings: list[str] = field(default_factory=list)
    """What the caller must warn of whatever the notes' level: ``# gap`` lines that the
    samples read contradict (:func:`_checked_gaps`)."""


def file_encoding(path: Path) -> str:
    """The text encoding of the file (:func:`imubench.recording.textmeta.text_encoding`
    on its first bytes, decompressed for ``.gz``)."""
    gz = path.name.lower().endswith(".gz")
    with gzip.open(path, "rb") if gz else open(path, "rb") as fh:
        return text_encoding(fh.read(SNIFF_BYTES))


def open_text(path: Path, encoding: str) -> IO[str]:
    """The file as text in ``encoding`` (gzip when it ends in ``.gz``); undecodable bytes
    become U+FFFD so a damaged byte costs its line, not the file. A UTF-8 byte-order mark
    (Excel, Windows loggers) is dropped (``utf-8-sig``): read as text, it stuck to the
    first column's name and hid that column (a ``timestamp`` first: "no time column"; a
    ``gyro_x`` first: gx missing)."""
    if path.name.lower().endswith(".gz"):
        return gzip.open(path, "rt", encoding=encoding, errors="replace", newline="")
    return open(path, encoding=encoding, errors="replace", newline="")


def _delimiter(line: str) -> str | None:
    """``,``, ``;``, tab, or None (whitespace). A ``;`` or tab between numbers with
    decimal commas is the delimiter however many commas there are (``0,00;0,50;30,00``
    was split at its commas, a headerless export refused)."""
    counts = {d: line.count(d) for d in (";", "\t", ",")}
    for d in (";", "\t"):
        if counts[d] and all(_is_number(f.strip().strip('"').replace(",", "."))
                             for f in line.split(d)):
            return d
    best = max(counts, key=lambda d: counts[d])
    return best if counts[best] else None


def _split(line: str, delim: str | None) -> list[str]:
    """The fields of a line as the first pass reads numbers (:func:`_texts`,
    :func:`_numbers_of` without a settled decimal mark)."""
    return _numbers_of(_texts(line, delim), delim, None)


def _texts(line: str, delim: str | None) -> list[str]:
    """The fields of a line as written, each stripped of blanks and of the double quotes a
    spreadsheet puts around it."""
    if delim is None:
        words: list[str] = []
        for f in line.split():  # 'gyro_x [deg/s]': a unit after a space is its column's
            if words and f[:1] in "[(" and not _is_number(f):
                words[-1] += " " + f
            else:
                words.append(f.strip('"'))
        return words
    return [f.strip().strip('"').strip() for f in _parts(line, delim)]


def _numbers_of(fields: list[str], delim: str | None, mark: str | None) -> list[str]:
    """The fields (:func:`_texts`) with their separators as numbers read them: in a file
    separated by ``;`` or tabs a comma is a decimal comma (a locale's export). ``mark``:
    the file's decimal mark when its numbers had to settle it (:func:`_decimal_mark`):
    ``comma`` (points are thousands separators) or ``point`` (commas are)."""
    if mark == "comma":
        return [f.replace(".", "").replace(",", ".") if _NUMBER_CHARS.match(f) else f
                for f in fields]
    if mark == "point":
        return [f.replace(",", "") if _NUMBER_CHARS.match(f) else f for f in fields]
    if delim is None:
        return fields
    if delim in (";", "\t"):
        return [f.replace(".", "").replace(",", ".") if _THOUSANDS_POINT.match(f)
                else f.replace(",", ".") for f in fields]
    kinds = [_comma_kind(f) for f in fields]
    return [f.replace(",", "") if k == "thousands" else f.replace(",", ".") if k else f
            for f, k in zip(fields, kinds, strict=True)]


def _parts(line: str, delim: str) -> list[str]:
    """The fields of a delimited line as written (quotes read as a CSV reader does)."""
    return next(csv.reader([line], delimiter=delim)) if '"' in line else line.split(delim)


_THOUSANDS_POINT = re.compile(r"^[-+]?\d{1,3}(\.\d{3})+,\d*$")
"""``-1.234,567``: thousands points and a decimal comma (a ``;`` or tab export)."""
_THOUSANDS_COMMA = re.compile(r"^[-+]?\d{1,3}(,\d{3})+(\.\d*)?$")
"""``"1,234.5"``: thousands commas in a quoted field of a comma-separated file (read
split at the comma, the line was damaged: every value of 1000 and over was dropped)."""
_ONE_COMMA = re.compile(r"^[-+]?(\d+),(\d+)$")
"""A quoted number with one comma and no point: ``"0,010"``, ``"1,480"``, ``"1,5"``."""
_NUMBER_CHARS = re.compile(r"^[-+]?[\d.,]*\d[\d.,]*([eE][-+]?\d+)?$")
"""A number written with digits, points and commas (and an exponent)."""


def _comma_kind(text: str) -> str | None:
    """How the first pass reads a comma-separated file's (quoted) field with a comma in a
    number: ``thousands`` (``1,234.5``, ``1,234,567``) or a decimal comma (``decimal``,
    anything else with one comma: ``0,010``, ``1,480``), or None (no such number); the
    file's numbers then settle which it is (:func:`_decimal_mark`)."""
    if _THOUSANDS_COMMA.match(text) and ("." in text or text.count(",") > 1):
        return "thousands"
    return "decimal" if _ONE_COMMA.match(text) else None


def mark_evidence(text: str) -> str | None:
    """What a number says of its file's decimal mark: ``comma`` or ``point`` where only
    that mark reads it (``0,010``, ``1,5``, ``7,88E-03``, ``1.234,5``, ``1.234.567``; or
    ``0.010``, ``12.46``, ``1,234.5``, ``1,234,567``), ``either_comma`` / ``either_point``
    where one separator and three digits after it read both ways (``1,480``: 1.48 or
    1480; ``1.480``), None where it has no separator."""
    if not _NUMBER_CHARS.match(text):
        return None
    mant = re.split("[eE]", text)[0].lstrip("+-")
    commas, points = mant.count(","), mant.count(".")
    if not commas and not points:
        return None
    if commas and points:  # the last one is the decimal mark, the other groups by 3
        mark, group = ("comma", ".") if mant.rfind(",") > mant.rfind(".") else ("point", ",")
        whole = mant.rsplit("," if mark == "comma" else ".", 1)[0]
        return mark if _GROUPED[group].match(whole) else None
    if commas > 1 or points > 1:  # grouping repeated: the other is the decimal mark
        group = "," if commas else "."
        return ("point" if commas else "comma") if _GROUPED[group].match(mant) else None
    sep = "," if commas else "."
    lead, frac = mant.split(sep)
    exponent = len(mant) < len(text.lstrip("+-"))
    decisive = (exponent or len(frac) != 3 or not lead or lead.startswith("0")
                or len(lead) > 3)
    name = "comma" if sep == "," else "point"
    return name if decisive else f"either_{name}"


_GROUPED = {sep: re.compile(rf"^\d{{1,3}}(\{sep}\d{{3}})*$") for sep in ",."}
"""Digits grouped by three with ``,`` or ``.`` (``1,234,567``; not a date ``01.05.2024``, a
version ``1.2.3`` or an address ``192.168.1.10``, which say nothing of the mark)."""
MARK_FIX = "save it with '.' as the decimal mark and without thousands separators"
"""The fix a refused mixture of decimal marks is given."""


def _take_marks(raw: _Raw, texts: list[str], lineno: int) -> None:
    """Record in :attr:`_Raw.marks` what the line's fields (:func:`_texts`) say of the
    decimal mark (:func:`mark_evidence`), the first of each kind. Once a mark is settled
    only the other separator can add (a contradiction, or a number that then reads
    otherwise): a field whose last separator is the settled mark (``1,234.5`` once the
    point is) says it again and is passed over (a 500 000-line quoted US export read 2.7x
    slower, a semicolon export 2.5x, when every field was looked at)."""
    settled = ("," if "comma" in raw.marks else "." if "point" in raw.marks else None)
    other = ".," if settled is None else "." if settled == "," else ","
    if not any(c in text for text in texts for c in other):
        return
    for text in texts:
        if settled is None:
            if "," not in text and "." not in text:
                continue
        elif text.rfind(settled) > text.rfind("." if settled == "," else ","):
            continue
        kind = mark_evidence(text)
        if kind is not None and kind not in raw.marks:
            raw.marks[kind] = (lineno, text)


def _decimal_mark(raw: _Raw, where: str) -> str | None:
    """The decimal mark the file's numbers settle (:func:`mark_evidence`, first line of
    each kind in :attr:`_Raw.marks`): ``comma`` or ``point``, or None where they say
    nothing beyond the first pass's reading. RecordingError where they contradict each
    other (both marks decisive; ``1,480``-like numbers with a comma, which read either
    way, and none that decides, except in a ``;`` or tab export without ``1.480``-like
    numbers, where such a comma is the locale's decimal comma: a US ``;`` export's
    ``1,010`` ms beside ``1.480`` was read as 1.01 ms and 1480 dps). A German spreadsheet
    told to separate by commas writes ``"0,010","1,480"`` (read as thousands: 1000x too
    large); a decimal-comma
    file with thousands points (``"1.010"`` ms) was read at 100 kHz; a US file's
    ``"1,000"`` beside ``12.46`` is a thousands comma (outside reviewers' files)."""
    ev = raw.marks
    if "comma" in ev and "point" in ev:
        (lc, tc), (lp, tp) = ev["comma"], ev["point"]
        raise RecordingError(
            f"{where}: its numbers use both ',' (line {lc}: {tc!r}) and '.' (line {lp}: "
            f"{tp!r}) as the decimal mark; {MARK_FIX}")
    if "comma" in ev:
        return "comma"
    if "point" in ev:
        return "point"
    if "either_comma" in ev and "either_point" not in ev and raw.delim in (";", "\t"):
        return "comma"  # a comma in a ';' or tab export is a locale's decimal comma
    if "either_comma" in ev:
        line, text = ev["either_comma"]
        both = (f" and {ev['either_point'][1]!r} (line {ev['either_point'][0]})"
                if "either_point" in ev else "")
        raise RecordingError(
            f"{where}: its numbers with a separator have three digits after it (line "
            f"{line}: {text!r}{both}), which reads as a decimal comma "
            f"({text.replace(',', '.')}) or a thousands separator ({text.replace(',', '')}); "
            f"nothing in the file tells which: {MARK_FIX}")
    return None


def _rescan_mark(raw: _Raw, mark: str | None) -> bool:
    """Whether the first pass read some number otherwise than ``mark`` says (the file is
    then read again with it)."""
    if mark is None:
        return False
    commas = any("," in text for _, text in raw.marks.values())
    if raw.delim is None:  # the first pass reads no comma in a whitespace-separated file
        return mark == "comma" or commas
    if raw.delim == ",":  # quoted: one comma was read as decimal, ``1.234,5`` as no number
        return mark == "comma" or "either_comma" in raw.marks
    # ';' or tab: every comma was read as decimal, every point too but in ``1.234,5``
    return "either_point" in raw.marks if mark == "comma" else commas


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return bool(FORTRAN_NUMBER.match(text))
    return True


def _looks_like_header(fields: list[str]) -> bool:
    return len(fields) >= 2 and sum(not _is_number(f) for f in fields) >= len(fields) / 2


FORTRAN_NUMBER = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)[dD][-+]?\d+$")
"""A number with Fortran's double-precision exponent (``1.5D-03``)."""
DIGITS = re.compile(r"^\d+$")
"""The part after a decimal comma, read as a second field (``0,0123`` -> ``0``, ``0123``)."""

ISO_TIME = re.compile(r"^(\d{4}-\d{2}-\d{2}[T ]\d{2}:\d{2}:\d{2}(?:\.\d+)?)"
                      r"(Z|[+-]\d{2}:?\d{2})?$")
"""A date and time as loggers and pandas write them (ISO 8601: UTC when no zone, ``Z``,
or an offset ``+02:00`` / ``+0200``, as pandas writes a time-zone-aware index)."""
DOTTED_TIME = re.compile(r"^(\d{1,2})\.(\d{1,2})\.(\d{4})[T ](\d{1,2}):(\d{2}):(\d{2}(?:\.\d+)?)$")
"""A date with dots, day first, and a time (``01.05.2024 12:00:00.010``: the form of
DIN 5008 and of European loggers' and Excel's exports), read as UTC like :data:`ISO_TIME`.
Dotted dates are day first wherever they are written; slashed ones (``05/01/2024``) are
month first in the US and day first elsewhere, so they are refused (:func:`_time_hint`)."""
DATE_LIKE = re.compile(r"\d[./-]\d{1,2}[./-]\d|\d:\d{2}")
"""A cell that holds a date or a clock time in some form (for the message)."""


SPARSE_SHARE = 0.5
"""A channel missing on at least this share of the lines is left out (or, all of them
being so, the file refused): interleaved gyro and accelerometer lines read as half-empty
channels gave every deviation NaN with exit status 0."""
MISSING_CELLS = frozenset({"", "nan", "NaN", "NAN", "-", "n/a", "N/A", "NA", "null", "None"})
"""Cells that mark a missing value: a lost sample of that channel only (a ``NaN`` in an
unused accelerometer column on every other line dropped those lines from the gyro, which
then read at half its rate)."""


def _utc_seconds(iso: str) -> float:
    """Unix seconds of an ISO 8601 date and time without a zone, read as UTC."""
    return float(np.datetime64(iso, "ns").astype(np.int64)) * 1e-9


def _number(text: str) -> float:
    """The field's value: NaN for a missing one (:data:`MISSING_CELLS`: a hole); an ISO
    8601 date and time (``2024-05-01 12:00:00.010``, UTC) as Unix seconds; ValueError for
    text that is no finite number (an ``inf`` cell is a damaged one, not a value that
    every command later refuses without saying where)."""
    if text in MISSING_CELLS:
        return math.nan
    try:
        value = float(text)
    except ValueError:
        if FORTRAN_NUMBER.match(text):
            value = float(text.replace("D", "E").replace("d", "e"))
        elif m := DOTTED_TIME.match(text):
            day, month, year, hour, minute, second = m.groups()
            return _utc_seconds(
                f"{year}-{int(month):02d}-{int(day):02d}T{int(hour):02d}:{minute}:{second}")
        elif m := ISO_TIME.match(text):
            utc = _utc_seconds(m.group(1))
            zone = m.group(2) or "Z"
            if zone != "Z":  # local time = UTC + offset
                sign = -1.0 if zone[0] == "-" else 1.0
                digits = zone[1:].replace(":", "")
                utc -= sign * (int(digits[:2]) * 3600 + int(digits[2:]) * 60)
            return utc
        else:
            raise
    if not math.isfinite(value):
        raise ValueError(text)
    return value


ROW_BLOCK = 65_536
"""Rows gathered as Python lists before they become one float64 block."""


@dataclass
class _Raw:
    meta: dict[str, Any] = field(default_factory=dict)
    gaps: list[Gap] = field(default_factory=list)
    gap_lines: list[int] = field(default_factory=list)
    """The line of each of ``gaps``."""
    header: list[str] | None = None
    header_line: int = 0
    delim: str | None = None
    pending: list[list[float]] = field(default_factory=list)
    """Rows read since the last block (:data:`ROW_BLOCK` at most)."""
    blocks: list[np.ndarray] = field(default_factory=list)
    """Earlier rows as float64 blocks: 8 bytes a value, where a Python list of floats
    takes ~40 (a 3 M-row, 300 MB CSV peaked at 1.8 GB)."""
    n_rows: int = 0
    row_lines: array[int] = field(default_factory=lambda: array("q"))
    row_fail: dict[int, list[int]] = field(default_factory=dict)
    """Row -> columns that were not numbers (NaN in the row): the row is damaged if a
    column it needs is among them (a ROS export's ``frame_id`` is text, and unused)."""
    bad_lines: list[int] = field(default_factory=list)
    width: int = 0
    comment_header: bool = False
    """The header came from a ``#`` line (EuRoC): dropped if the data do not fit it."""
    digits_after_comma: bool = True
    """Every comma-separated data row so far has two fields, the second digits only (a
    decimal comma's fraction: ``0,0123``)."""
    leading_zero_after_comma: bool = False
    """One of them starts with 0 (``0123``), which no integer column writes."""
    decimal_comma: bool = False
    """The file was read with every comma as a decimal point (one column)."""
    marks: dict[str, tuple[int, str]] = field(default_factory=dict)
    """Per kind of decimal-mark evidence (:func:`mark_evidence`), its first line and
    text."""
    mark: str | None = None
    """The decimal mark the file is read with (:func:`_decimal_mark`; None: the first
    pass's reading)."""
    first_short: tuple[int, int] | None = None
    """The first data line whose number of fields is not the header's: (line, fields)."""
    encoding: str = "utf-8-sig"
    comments: list[str] = field(default_factory=list)
    """The first comment lines above the data (named when no rate was found in them)."""

    def add(self, row: list[float], lineno: int) -> None:
        """Append a data row read from line ``lineno``."""
        self.pending.append(row)
        self.row_lines.append(lineno)
        self.n_rows += 1
        if len(self.pending) == ROW_BLOCK:
            self.blocks.append(np.asarray(self.pending, dtype=np.float64))
            self.pending = []

    def table(self) -> np.ndarray:
        """Every row as one float64 array (rows x width)."""
        if self.pending:
            self.blocks.append(np.asarray(self.pending, dtype=np.float64))
            self.pending = []
        if len(self.blocks) > 1:
            self.blocks = [np.concatenate(self.blocks)]
        return self.blocks[0] if self.blocks else np.zeros((0, self.width))


def _scan(path: Path, decimal_comma: bool = False, mark: str | None = None) -> _Raw:
    raw = _Raw(decimal_comma=decimal_comma, mark=mark)
    try:
        raw.encoding = file_encoding(path)
        fh = open_text(path, raw.encoding)
        with fh:
            for lineno, line in enumerate(fh, 1):
                line = line.strip()
                if decimal_comma and not line.startswith(("#", "%")):
                    line = line.replace(",", ".")
                _take_line(raw, line, lineno, path)
    except EOFError as exc:  # gzip: the stream ends early (a writer that crashed)
        if not raw.n_rows:
            raise RecordingError(f"{path}: cannot read: {exc}") from None
        raw.bad_lines.append(-1)  # the rest of the compressed stream is lost
    except (gzip.BadGzipFile, zlib.error) as exc:
        # corrupt, not cut short: deflate decodes damaged bits into wrong text without
        # noticing until the CRC at the end (one flipped bit kept 276 rows with wrong
        # values or indices), so no row decoded from it can be trusted
        raise RecordingError(
            f"{path}: the compressed data are corrupt ({exc}); no row decoded from them "
            "can be trusted: use an intact copy") from None
    except OSError as exc:
        if not raw.n_rows:
            raise RecordingError(f"{path}: cannot read: {exc}") from None
        raw.bad_lines.append(-1)  # the rest of the file could not be read
    return raw


def _gap(line: str, where: str) -> Gap:
    """The gap a ``# gap`` line declares; RecordingError naming ``where`` (file:line) and
    the field when it is malformed: a gap line with a negative, zero or unreadable count
    was skipped as a comment, its hole then declared by nobody, without a word."""
    fields = GAP_FIELDS.match(line)
    if fields is None:
        raise RecordingError(f"{where}: a gap line must read '{GAP_FORM}', not {line!r}")
    try:
        at = int(fields[1])
    except ValueError:
        raise RecordingError(f"{where}: gap line field at_index is {fields[1]!r}, not a "
                             "sample index (a whole number)") from None
    try:
        lost = int(fields[2])
    except ValueError:
        lost = 0
    if lost <= 0:
        raise RecordingError(f"{where}: gap line field lost is {fields[2]!r}, not a number "
                             "of samples (a whole number, 1 or more)")
    return Gap(at, lost, (fields[3] or "").strip())


def _empty_own_csv(raw: _Raw, options: InputOptions, where: str) -> TextRead | None:
    """A recording of no samples (its gaps, if any) when the file is imubench's own CSV,
    its header (``index`` among imubench's columns) and rate stated, without data lines;
    else None. imubench writes such a file for a recording of no samples (``convert`` of a
    native file cut after its header; a live recording stopped before its first sample),
    and a native or HDF5 file of no samples reads as one: the CSV was refused ("no
    readable data lines"), so a 0-sample recording did not round-trip."""
    if raw.n_rows or raw.bad_lines or raw.header is None:
        return None
    names = [c.name for c in map_columns(raw.header)]
    if "index" not in names or not all(n in OWN_NAMES for n in names):
        return None
    meta = dict(raw.meta)
    stated = stated_rate(meta, where)
    rate = options.rate_hz if options.rate_hz is not None else (
        stated[0] if stated is not None else None)
    if rate is None:
        return None
    meta["odr_hz"] = float(rate)
    meta.setdefault("channels", [c for c in CHANNELS if c in names])
    meta.setdefault("source_format", "imubench CSV")
    gaps, warnings = _checked_gaps(raw.gaps, raw.gap_lines, np.zeros(0, np.int64), where)
    note = (f"{where}: read as imubench CSV: no data lines, a recording of no samples"
            + (f" ({sum(g.lost for g in gaps)} lost in its gap lines)" if gaps else ""))
    return TextRead(meta, Batch.empty(), gaps, [], [note], True,
                    rate_stated=options.rate_hz is None, warnings=warnings)


def _checked_gaps(gaps: list[Gap], lines: list[int], index: np.ndarray,
                  where: str) -> tuple[list[Gap], list[str]]:
    """``gaps`` as the samples read allow them, and a warning for each ``# gap`` line they
    contradict: the index column is the truth of which samples exist, so a gap that
    declares lost a sample the file holds is cut to the run of missing samples just
    before its ``at_index`` (gone when there is none). Gaps sharing ``at_index`` are
    adjacent holes, the one listed first the earlier (:func:`~imubench.batch.gaps_before`):
    the earliest is cut first. Such a line was kept as it was: the recording's gaps then
    counted samples that its rows hold (``lost=5`` where the index column had no hole
    was read as '0 gaps' by ``convert`` and as 5 lost samples by the gaps, without a
    word)."""
    by_at: dict[int, list[int]] = {}
    for k, g in enumerate(gaps):
        by_at.setdefault(g.at, []).append(k)
    keep: dict[int, Gap] = {}
    warnings: list[str] = []
    for at, ks in by_at.items():
        total = sum(gaps[k].lost for k in ks)
        below = int(np.searchsorted(index, at))  # rows with an index below at
        room = total if below == 0 else min(total, at - int(index[below - 1]) - 1)
        need = max(room, 0)
        for k in reversed(ks):  # the gap nearest at keeps its samples first
            take = min(gaps[k].lost, need)
            need -= take
            if take:
                keep[k] = Gap(at, take, gaps[k].reason)
        if room < total:
            first, last = at - total, at - 1
            held = total - max(room, 0)
            also = ", ".join(str(lines[k]) for k in ks[1:])
            warnings.append(
                f"{where}:{lines[ks[0]]}: gap line at_index={at} "
                + (f"(with line(s) {also}, the same at_index) " if also else "")
                + f"declares samples {first}-{last} lost, but the file holds {held} of them: "
                "the index column is the truth, "
                + (f"read as {room} lost" if room > 0 else "the gap is not taken"))
    return [keep[k] for k in sorted(keep)], warnings


def _take_line(raw: _Raw, line: str, lineno: int, path: Path) -> None:
    if not line:
        return
    if line.startswith("#") or (line.startswith("%") and raw.header is None and not raw.n_rows):
        if GAP_LINE.match(line):
            raw.gaps.append(_gap(line, f"{path}:{lineno}"))
            raw.gap_lines.append(lineno)
            return
        if raw.header is None and not raw.n_rows:
            delim = _delimiter(line)
            # whitespace-separated: the '#' is no column ('# time gx gy gz' was "4
            # columns without a header"); if the data do not fit it, it was a comment
            fields = _split(line if delim is not None else line.lstrip("#%"), delim)
            if ":" not in line and _looks_like_header(fields) and sum(
                    c.channel is not None for c in map_columns(fields)) >= 2:
                raw.header, raw.header_line, raw.delim = fields, lineno, delim
                raw.width = len(fields)
                raw.comment_header = True
                return
            if len(raw.comments) < 3:
                raw.comments.append(line)
            if ":" in line and line.startswith("#"):
                key, _, value = line[1:].partition(":")
                key, unit = split_key_unit(key)
                try:
                    raw.meta[key] = json.loads(value) if not unit else f"{value} {unit}"
                except json.JSONDecodeError:
                    raw.meta[key] = value.strip() + (f" {unit}" if unit else "")
            else:
                found = rate_line(line[1:])
                if found is not None:
                    raw.meta[found[0]] = found[1]
        return
    if raw.comment_header and not raw.n_rows and not raw.bad_lines and len(
            _split(line, raw.delim)) != raw.width:
        raw.header, raw.comment_header, raw.width = None, False, 0  # it was a comment
    if raw.header is None and not raw.n_rows:
        raw.delim = _delimiter(line)
        fields = _split(line, raw.delim)
        if _looks_like_header(fields) or (len(fields) == 1 and not _is_number(fields[0])):
            raw.header, raw.header_line, raw.width = fields, lineno, len(fields)
            return
        raw.width = len(fields)
    texts = _texts(line, raw.delim)
    fields = _numbers_of(texts, raw.delim, raw.mark)
    if len(fields) == raw.width + 1 and fields[-1] == "" and raw.header is not None:
        fields.pop()  # a trailing separator on the data lines only
    if (raw.header is not None and not raw.n_rows and not raw.bad_lines
            and len(fields) == raw.width and any(f.strip() for f in fields)
            and all(_is_unit(f) for f in fields if f.strip())):
        # a units row under the header (`t,gx` then `s,rad/s`): each unit joins its
        # column's name, as if the header said `gx [rad/s]` (it was skipped as a damaged
        # line and its units ignored: rad/s read as dps)
        raw.header = [f"{h} [{u.strip().strip('[]()').strip()}]"
                      if u.strip() and not re.search(r"[\[(]", h) else h
                      for h, u in zip(raw.header, fields, strict=True)]
        return
    if len(fields) != raw.width:
        raw.bad_lines.append(lineno)
        if raw.first_short is None:
            raw.first_short = (lineno, len(fields))
        return
    if raw.mark is None and (raw.delim != "," or '"' in line):
        _take_marks(raw, texts, lineno)
    if raw.digits_after_comma:
        raw.digits_after_comma = (raw.header is None and raw.delim == "," and raw.width == 2
                                  and bool(DIGITS.match(fields[1])))
        raw.leading_zero_after_comma |= raw.digits_after_comma and fields[1][0] == "0"
    row = []
    for j, f in enumerate(fields):
        try:
            row.append(_number(f))
        except ValueError:
            row.append(math.nan)
            raw.row_fail.setdefault(raw.n_rows, []).append(j)
    raw.add(row, lineno)


_DECIMAL_COMMA_CELL = re.compile(r'(^|,)"?[-+]?\d+,\d+"?(,|$)')


def _unreadable_hint(path: Path, raw: _Raw) -> str:
    """What a file no line of which could be read probably is, for the message: UTF-16
    text without a byte-order mark (every other byte NUL), or decimal commas in a
    comma-separated file (``0,000,0,6272``: the fields cannot be told apart)."""
    try:
        with open_text(path, "latin-1") as fh:
            head = fh.read(4096)
    except OSError:
        return ""
    if head.count("\0") > len(head) // 4:
        return ("; the bytes alternate with NULs: UTF-16 text without a byte-order mark? "
                "save it as UTF-8")
    lines = [ln for ln in head.splitlines()[1:20] if ln.strip()]
    if raw.delim == "," and lines and all(_DECIMAL_COMMA_CELL.search(ln) for ln in lines):
        return ("; decimal commas in a comma-separated file? save it with ';' between "
                "fields (a comma in a number is then read as a decimal point) or with '.' "
                "as the decimal mark")
    return ""


def _first_unreadable(path: Path, raw: _Raw) -> str:
    """Where and why the first unreadable data line is so, for the message."""
    failed = [(raw.row_lines[i], js) for i, js in raw.row_fail.items()]
    first_bad = min(failed, default=None)
    short = raw.first_short
    if short is not None and (first_bad is None or short[0] < first_bad[0]):
        return (f"first: line {short[0]}, {short[1]} fields where the "
                f"{'header' if raw.header is not None else 'first line'} has {raw.width}")
    if first_bad is None:
        return "the file ends in damage"
    lineno, js = first_bad
    name = (f"{raw.header[js[0]].strip()!r}" if raw.header is not None
            else f"column {js[0] + 1}")
    return f"first: line {lineno}, {name} holds {_cell(path, raw, lineno, js[0])!r}, not a number"


def _cell(path: Path, raw: _Raw, lineno: int, k: int) -> str:
    """The text of field ``k`` of line ``lineno`` as written (:func:`_texts`: a ``;``
    file's decimal comma stays a comma), empty when it cannot be read again."""
    try:
        with open_text(path, raw.encoding) as fh:
            for i, line in enumerate(fh, 1):
                if i == lineno:
                    fields = _texts(line.strip(), raw.delim)
                    return fields[k].strip() if k < len(fields) else ""
    except (OSError, EOFError, gzip.BadGzipFile, zlib.error):
        pass
    return ""


def _time_hint(path: Path, raw: _Raw, lineno: int, failed: list[int], t_col: int | None
               ) -> str:
    """For the message that refuses a file whose time column is no number: the value, and
    the forms of a date and time imubench reads (a slashed date, ``05/01/2024``, is month
    first in the US and day first elsewhere: no reader can tell which)."""
    if t_col is None or t_col not in failed:
        return ""
    text = _cell(path, raw, lineno, t_col)
    if not DATE_LIKE.search(text):
        return f" (time: {text!r})" if text else ""
    return (f" (time: {text!r}); imubench reads dates and times as ISO 8601 "
            "(2024-05-01 12:00:00.010) or day first with dots (01.05.2024 12:00:00.010): "
            "convert the column, or read the rows in order at a rate you give with "
            "--rate HZ --columns t=-")


RAW_COUNT_UNITS = frozenset({"lsb", "lsbs", "counts", "count", "digits", "raw", "adc"})
"""Units-row words for raw sensor counts: the row is taken as units, and the column is
then refused as no gyro or accelerometer unit (``--units``), as a header ``gx [LSB]`` is.
Skipped as a damaged line, a ``s,LSB,LSB,LSB`` row let counts be read as dps (an outside
reviewer's file: white 0.458 and a bias of 57 "dps" for 0.004 and 0.5)."""


def _is_unit(text: str) -> bool:
    """Whether a cell of a units row names a unit: one imubench reads (gyro,
    accelerometer, time or temperature) or raw counts (:data:`RAW_COUNT_UNITS`)."""
    u = unit_word(text.strip().strip("[]()"))
    return (u in GYRO_UNITS_DPS or u in ACCEL_UNITS_G or u in TIME_UNIT_WORDS
            or u in TEMP_UNITS or u.lower() in _TEMP_WORDS or u.lower() in RAW_COUNT_UNITS)


def _pick(cols: list[Column], spec: str, where: str) -> int:
    """The column a ``--columns`` entry names: 1-based number or header text."""
    if spec.isdigit():
        k = int(spec) - 1
        if not 0 <= k < len(cols):
            raise RecordingError(f"{where}: --columns names column {spec}; the file has "
                                 f"{len(cols)}")
        return k
    for k, c in enumerate(cols):
        if spec in (c.text.strip(), c.name) or normalise(spec)[0] == c.name:
            return k  # the name as in the header, with or without its unit
    raise RecordingError(f"{where}: --columns names {spec!r}; the columns are "
                         f"{', '.join(c.text for c in cols)}")


def read_text(path: str | Path, options: InputOptions) -> TextRead:
    """Read a delimited text recording (module docstring); RecordingError (one line, with
    the fix) when it cannot be read at all."""
    path = Path(path)
    where = str(path)
    raw = _scan(path)
    if _decimal_commas(raw):
        raw = _scan(path, decimal_comma=True)
    mark = _decimal_mark(raw, where)
    evidence = raw.marks
    if _rescan_mark(raw, mark):
        raw = _scan(path, mark=mark)
    n_data = raw.n_rows + len([b for b in raw.bad_lines if b > 0])
    whole_bad = sum(1 for js in raw.row_fail.values() if len(js) == raw.width)
    no_rows = _empty_own_csv(raw, options, where)
    if no_rows is not None:
        return no_rows
    if not raw.n_rows:
        what = "no readable data lines" if raw.header is not None or raw.bad_lines else (
            "no data")
        raise RecordingError(f"{where}: {what}"
                             + (f" ({_first_unreadable(path, raw)})" if raw.bad_lines else "")
                             + "; expected a header such as "
                             "t,gx,gy,gz,ax,ay,az,temp and one sample per line"
                             + _unreadable_hint(path, raw))
    unreadable = len(raw.bad_lines) + whole_bad
    if unreadable > MOSTLY_BAD * n_data and unreadable > 10:
        raise RecordingError(f"{where}: {unreadable} of {n_data} data lines cannot be read "
                             f"({_first_unreadable(path, raw)}); not a recording"
                             + _unreadable_hint(path, raw))
    table = raw.table()
    notes: list[str] = []
    if raw.encoding != "utf-8-sig":
        notes.append(f"{where}: not UTF-8 text; read as {raw.encoding.upper()}")
    if raw.decimal_comma:
        notes.append(f"{where}: one column with decimal commas (0,0123 is 0.0123)")
    if raw.mark is not None:
        line, text = evidence.get(raw.mark) or evidence[f"either_{raw.mark}"]
        shown = (text.replace(".", "").replace(",", ".") if raw.mark == "comma"
                 else text.replace(",", ""))
        other = "points" if raw.mark == "comma" else "commas"
        notes.append(f"{where}: numbers read with a decimal {raw.mark} ({other} in them "
                     f"are thousands separators; line {line}: {text} is {shown})")
    if raw.header is not None:
        cols = map_columns(raw.header)
        fmt = ("ROS sensor_msgs/Imu export" if is_ros_export(raw.header)
               else "EuRoC/TUM-VI IMU CSV" if is_euroc(raw.header)
               else "imubench CSV" if all(c.name in OWN_NAMES for c in cols)
               else "CSV")
    else:
        cols = [Column(str(k + 1), str(k + 1), None, None) for k in range(raw.width)]
        fmt = "numeric table"
        value = raw.meta.get("channel")  # imubench's Stable32 export says which
        value = value if value in (*CHANNELS, "temp") else "gx"
        if raw.width == 1:
            cols[0] = Column("1", "1", value, None)
        elif raw.width == 2:
            cols = [Column("1", "1", "t", None), Column("2", "2", value, None)]
        fmt = ("one-column text (Stable32/allantools)" if raw.width == 1
               else "two-column text (time tag, value; Stable32/allantools)"
               if raw.width == 2 else fmt)
    where_col: dict[str, int] = {c.channel: k for k, c in enumerate(cols) if c.channel}
    for target, spec in options.columns.items():
        if target == "t" and spec == NO_TIME_COLUMN:
            where_col.pop("t", None)  # rows in order, at the rate given
            continue
        k = _pick(cols, spec, where)
        where_col = {ch: j for ch, j in where_col.items() if j != k and ch != target}
        where_col[target] = k
    if raw.header is None and raw.width > 2 and not options.columns:
        raise RecordingError(f"{where}: {raw.width} columns without a header; name them "
                             "with --columns t=1,gx=2,... (1-based numbers)")
    if not any(ch in where_col for ch in (*CHANNELS, "temp")):
        seen = ", ".join(c.text for c in cols)
        raise RecordingError(f"{where}: no channel found among the columns {seen}; map "
                             "them with --columns gx=NAME,...,az=NAME (and t=NAME)")
    used = set(where_col.values())
    failed = sorted(i for i, js in raw.row_fail.items() if used.intersection(js))
    if len(failed) > MOSTLY_BAD * len(table) and len(failed) > 10:
        # refused like lines of the wrong width: what is left is no record of the data
        # (98 % unreadable cells kept 48 of 3000 lines, read at 3.2 Hz, exit 0)
        first = raw.row_lines[failed[0]]
        bad_cols = sorted({cols[j].text.strip() for i in failed[:50]
                           for j in raw.row_fail[i] if j in used})
        j0 = next(j for j in raw.row_fail[failed[0]] if j in used)
        raise RecordingError(
            f"{where}:{first}: {len(failed)} of {len(table)} data lines hold a value that "
            f"is no number in a column read ({', '.join(bad_cols)}; first "
            f"{cols[j0].text.strip()!r}: {_cell(path, raw, first, j0)!r}); not a recording"
            + _time_hint(path, raw, first, raw.row_fail[failed[0]], where_col.get("t")))
    if failed:
        good = np.ones(len(table), dtype=bool)
        good[failed] = False
        raw.bad_lines.extend(raw.row_lines[i] for i in failed)
        table = table[good]
        raw.row_lines = array("q", np.asarray(raw.row_lines)[good].tolist())
        if not len(table):
            raise RecordingError(f"{where}: no readable data lines (first unreadable: line "
                                 f"{raw.bad_lines[0]})")
    k_t = where_col.get("t")
    if (k_t is not None and "temp" not in where_col and "t" not in options.columns
            and capital_t(cols[k_t].text) and len(table) > 2
            and np.mean(np.diff(table[:, k_t]) > 0) < 0.9):
        # a capital T that does not increase is a temperature, not the time (it was read
        # as the time: 5985 of 6000 lines dropped)
        where_col["temp"] = where_col.pop("t")
        cols[k_t] = Column(cols[k_t].text, cols[k_t].name, "temp", cols[k_t].unit)
    ros, euroc = (raw.header is not None and is_ros_export(raw.header),
                  raw.header is not None and is_euroc(raw.header))
    values = np.full((len(table), len(CHANNELS)), np.nan)
    used_units: dict[str, str] = {}
    assumed: list[str] = []  # channels whose unit nothing stated
    overridden: list[str] = []  # header units an option contradicts
    for i, ch in enumerate(CHANNELS):
        if ch not in where_col:
            continue
        col = cols[where_col[ch]]
        factor, unit = _channel_unit(ch, col, options, ros or euroc, raw.header is None,
                                     where)
        given = options.gyro_unit if ch.startswith("g") else options.accel_unit
        if given is not None and col.unit is not None and col.unit != given:
            overridden.append(f"column {col.text.strip()!r} says {col.unit}, read as {given} "
                              "(--units)")
        if raw.header is None and given is None:
            stated = stated_unit(raw.meta, ch, where)  # imubench's Stable32 export says
            if stated is not None:
                factor, unit = stated
            else:
                assumed.append(ch)
        elif (given is None and col.unit is None and not (ros or euroc)
              and "odr_hz" not in raw.meta):
            assumed.append(ch)  # imubench's names, but not its file: nothing states it
        values[:, i] = table[:, where_col[ch]] * factor
        used_units[ch] = unit
    empty = {ch: int(np.count_nonzero(np.isnan(values[:, CHANNELS.index(ch)])))
             for ch in used_units}
    sparse = [ch for ch, k in empty.items() if k >= SPARSE_SHARE * len(values)]
    if sparse and len(sparse) == len(empty):
        missing = np.isnan(values[:, [CHANNELS.index(ch) for ch in sparse]])
        interleaved = bool(np.all(missing.any(axis=1)) and not np.all(missing.all(axis=1)))
        raise RecordingError(
            f"{where}: every channel is missing on most lines ("
            + ", ".join(f"{ch} {empty[ch]} of {len(values)}" for ch in sparse) + ")"
            + ("; the sensors take turns line by line (gyro lines and accelerometer lines "
               "interleaved): write one file per sensor" if interleaved else
               "; not a recording"))
    for ch in sparse:  # a column mostly empty: left out, the others read whole
        values[:, CHANNELS.index(ch)] = np.nan
        used_units.pop(ch)
    if sparse:
        notes.append(f"{where}: {', '.join(sparse)} left out: no value on most lines ("
                     + ", ".join(f"{empty[ch]} of {len(values)}" for ch in sparse) + ")")
    if any(empty[ch] for ch in used_units):
        lines = np.asarray(raw.row_lines)
        notes.append(f"{where}: empty cells ("
                     + ", ".join(f"{ch} {empty[ch]}"
                                 + _runs_text(np.isnan(values[:, CHANNELS.index(ch)]), lines)
                                 for ch in used_units if empty[ch])
                     + "): read as that channel's lost samples, the others' kept")
    _check_gravity(values, used_units, options, where, assumed)
    temp = (_in_degc(table[:, where_col["temp"]], cols[where_col["temp"]], where)
            if "temp" in where_col else np.full(len(table), np.nan))

    meta = dict(raw.meta)
    t_raw = table[:, where_col["t"]] if "t" in where_col else None
    index_col = table[:, where_col["index"]] if "index" in where_col else None
    stated = stated_rate(meta, where)
    meta_rate = stated[0] if stated is not None else None
    rate = options.rate_hz if options.rate_hz is not None else meta_rate
    time_note = ""
    t_s = None
    if t_raw is not None and rate is None and index_col is None and len(t_raw) < 3:
        raise RecordingError(f"{where}: {len(t_raw)} row(s) are too few to infer the rate; "
                             "give --rate HZ")
    if t_raw is not None:
        unit_name, scale = _time_unit(cols[where_col["t"]], options, ros, t_raw, rate, where)
        t_s = t_raw * scale
        time_note = f"t in {unit_name}"
        if unit_name.startswith("days (MJD") and len(t_raw):  # dated: keep its start,
            # and count the seconds from it (MJD x 86400 are seconds since 1858)
            meta.setdefault("start_utc",
                            start_utc((float(t_raw[0]) - MJD_OF_UNIX_EPOCH) * SECONDS_PER_DAY))
            t_s = (t_raw - float(t_raw[0])) * scale
        if "the header says" in unit_name:
            overridden.append(f"t {unit_name}")
    if raw.header is None and raw.width == 2 and options.rate_hz is not None:
        t_s = None  # evenly spaced values at the given rate: the tags are not needed
        time_note = "time tags ignored (--rate)"
    tb: Timebase
    if index_col is not None:
        if not np.all(np.isfinite(index_col)):
            raise RecordingError(f"{where}: the index column has empty values")
        fraction = np.flatnonzero(index_col != np.round(index_col))
        if fraction.size:  # a sample counter is whole: 49.5 was rounded in silence
            k = int(fraction[0])
            raise RecordingError(
                f"{where}:{raw.row_lines[k]}: index {float(index_col[k]):g} is not a whole "
                f"sample number ({fraction.size} row(s) like it); the index column counts "
                "samples")
        stride = _index_stride(index_col)
        if stride > 1:  # every stride-th value of a counter: a decimated log
            notes.append(f"{where}: the index column steps by multiples of {stride} (a "
                         f"counter logged one sample in {stride}); read as index / {stride}")
            index_col = np.floor_divide(index_col - index_col[0], stride)
        tb = timebase_from_index(index_col, t_s, where, rate,
                                 np.asarray(raw.row_lines))
    elif t_s is not None:
        tb = timebase_from_times(t_s, where, rate)
        if options.rate_hz is not None:
            _check_given_rate(t_s, tb, where)
        elif stated is not None:
            own = _stamps_against_stated(t_s, tb, stated, where)
            if own is not None:
                notes.append(f"{where}: the file states {stated[0]:.6g} Hz (# {stated[1]}) "
                             f"but its time stamps give {own.rate_hz:.8g} Hz "
                             f"({100.0 * (own.rate_hz / stated[0] - 1.0):+.3g} %): read "
                             "at the stamps' rate (--rate overrides)")
                tb, stated = own, None
        lines = np.asarray(raw.row_lines)
        check_one_rate(t_s, tb.rate_hz, lambda row: f"{where}:{int(lines[row])}")
        _check_even_spacing(t_s, tb, where, lines)
        if rate is None and not TIME_RATE_HZ[0] <= tb.rate_hz <= TIME_RATE_HZ[1]:
            raise RecordingError(
                f"{where}: the time column gives {tb.rate_hz:.4g} Hz with t in "
                f"{unit_name.split(' (')[0]}, not a rate an IMU records at; check "
                "--time-unit s|ms|us|ns or give --rate HZ")
        if rate is None and unit_name == "s (header)" and tb.rate_hz < SLOW_IN_SECONDS_HZ:
            notes.append(f"{where}: t in s (header) gives {tb.rate_hz:.4g} Hz, slow for an "
                         f"IMU; if the column holds ms ({tb.rate_hz * 1e3:.4g} Hz), give "
                         "--time-unit ms")
    else:
        if rate is None and raw.header is None:
            rate = options.default_rate_hz  # a plain series: tau in samples
        if rate is None:
            others = [c.text.strip() for k, c in enumerate(cols)
                      if k not in where_col.values()]
            raise RecordingError(
                f"{where}: no time column and no rate; give --rate HZ"
                + (f", or name the time column with --columns t=NAME (columns not "
                   f"read: {', '.join(others)})" if others and raw.header is not None
                   else ""))
        tb = Timebase.in_order(rate, len(table),
                               "given" if options.rate_hz is not None or meta_rate is not None
                               else "assumed (tau in samples)")
        if options.rate_hz is None and meta_rate is None and raw.comments:
            notes.append(f"{where}: no rate in its comment lines ({raw.comments[0]!r} ...): "
                         f"read at {rate:g} Hz, tau in samples; give --rate HZ if they "
                         "state one")
    keep = tb.keep
    bad = sorted(raw.bad_lines + [raw.row_lines[i] for i in np.nonzero(~keep)[0]])
    if t_s is None:
        t_s = tb.index / tb.rate_hz
    how = ("--rate" if options.rate_hz is not None
           else f"# {stated[1]}" if stated is not None else tb.how)
    meta["odr_hz"] = float(tb.rate_hz)
    meta.setdefault("channels", [c for c in CHANNELS if c in where_col])
    meta.setdefault("source_format", fmt)
    shown = ", ".join(f"{ch}={cols[k].text.strip()}" for ch, k in where_col.items())
    unread = [c for k, c in enumerate(cols) if k not in where_col.values()]
    if unread and raw.header is not None and not (ros or euroc):  # their other fields
        # (orientation, covariances) are known and not the IMU's samples
        said = []
        for c in unread[:UNREAD_SHOWN]:
            near = near_alias(c.name, where_col)
            said.append(c.text.strip() + (f" (a misspelt {near}? name it with --columns "
                                          f"{near}={c.text.strip()})" if near else ""))
        more = len(unread) - UNREAD_SHOWN
        notes.append(f"{where}: column(s) not read, no channel of that name: "
                     + ", ".join(said) + (f" and {more} more" if more > 0 else ""))
    hole_note = _holes_text(tb.index, t_s[keep], np.asarray(raw.row_lines)[keep])
    if hole_note:
        notes.append(f"{where}: {hole_note}")
    units = ", ".join(f"{ch} {u}" for ch, u in used_units.items())
    notes.append(f"{where}: read as {fmt}: {shown}; rate {tb.rate_hz:.6g} Hz ({how})"
                 + (f"; {time_note}" if time_note else "")
                 + (f"; units {units}" if units else "")
                 + (f" (assumed for {', '.join(assumed)}: nothing in the file states them; "
                    "give --units GYRO,ACCEL if they differ)" if assumed else ""))
    if assumed:
        meta["units_assumed"] = assumed
    if overridden:
        notes.append(f"{where}: the options override the header: " + "; ".join(overridden))
    batch = Batch(index=tb.index, t_s=t_s[keep], values=values[keep], temp_c=temp[keep])
    plain = raw.width == 1 and raw.header is None
    inferred = len(notes) > 1 or not (  # more than "read as": something to know
        (fmt == "imubench CSV" and how in ("--rate", "# odr_hz"))
        or (plain and not (assumed and stated is not None)))
    # a plain series (Stable32's, allan's: values in no unit, tau in samples) is read
    # quietly; one whose file states a rate is an IMU's, and its assumed unit is said (a
    # rad/s series with '# rate_hz: 100' read as dps gave `fit` a white level 57x low,
    # ARW and all, with nothing on the screen)
    gaps, warnings = _checked_gaps(raw.gaps, raw.gap_lines, batch.index, where)
    warnings += _beyond_full_scale(meta, batch.values, np.asarray(raw.row_lines)[keep], where)
    return TextRead(meta, batch, gaps, bad, notes, inferred,
                    rate_stated=options.rate_hz is None and stated is not None
                    and "t" in where_col, warnings=warnings)


def _beyond_full_scale(meta: dict[str, Any], values: np.ndarray, lines: np.ndarray,
                       where: str) -> list[str]:
    """A warning per sensor whose values exceed what the file's sensor can output: its
    16-bit range (32768 LSB x the stated sensitivity; 286.7 dps at the LSM6DS's 250 dps
    full scale) or, without a sensitivity, 1.2 x the stated full scale (``fs_dps``,
    ``fs_g``), with 5 % for a calibration's gain. gx = 1e300 in a file that says 250 dps
    was read without a word."""
    out = []
    for key, sens_key, cols, unit in (("fs_dps", "gyro_sensitivity_dps", slice(0, 3), "dps"),
                                      ("fs_g", "accel_sensitivity_g", slice(3, 6), "g")):
        fs, sens = meta.get(key), meta.get(sens_key)
        if not isinstance(fs, (int, float)) or not fs > 0 or not len(values):
            continue
        cap = 32768.0 * sens if isinstance(sens, (int, float)) and sens > 0 else 1.2 * fs
        with np.errstate(invalid="ignore"):
            beyond = np.any(np.abs(values[:, cols]) > 1.05 * cap, axis=1)
        if np.any(beyond):
            k = int(np.argmax(beyond))
            out.append(f"{where}:{lines[k]}: {int(beyond.sum())} row(s) hold values beyond "
                       f"what the sensor can output ({cap:g} {unit} at the stated full "
                       f"scale {fs:g} {unit}): check the file's units and values")
    return out


UNREAD_SHOWN = 8
"""Header columns not read that a warning names (the rest are counted)."""


def _runs_text(missing: np.ndarray, lines: np.ndarray, shown: int = 3) -> str:
    """' on lines 2002-3001, 4000 and 2 more run(s)': where the True runs of ``missing``
    lie (the first ``shown``), by the file's line numbers ``lines`` (one per row)."""
    runs = true_runs(missing)
    spans = [f"{lines[a]}" if a == b else f"{lines[a]}-{lines[b]}" for a, b in runs[:shown]]
    more = len(runs) - shown
    return (f" on line{'s' if len(runs) > 1 or runs[0][1] > runs[0][0] else ''} "
            + ", ".join(spans) + (f" and {more} more run(s)" if more > 0 else ""))


def _holes_text(index: np.ndarray, t_s: np.ndarray, lines: np.ndarray, shown: int = 3) -> str:
    """'1 hole(s) in the time stamps, 10400 samples missing: before line 200002 (t 2023.08
    s, 10400 samples)': where the holes of the sample ``index`` lie, by the file's line
    numbers and time stamps of the rows after them (the largest ``shown``), or '' (an
    outside reviewer's 100 s jump was reported only as a hole count)."""
    step = np.diff(index)
    at = np.nonzero(step > 1)[0]
    if not at.size:
        return ""
    lost = step[at] - 1
    big = at[np.argsort(-lost, kind="stable")[:shown]]
    where = "; ".join(f"before line {lines[i + 1]} (t {t_s[i + 1]:.6g} s, {step[i] - 1} "
                      "samples)" for i in sorted(big))
    return (f"{at.size} hole(s) in the time stamps, {int(lost.sum())} samples missing: "
            + ("the largest " if at.size > shown else "") + where)


RESTART_PERIODS = 10.0
"""A step back in the time column longer than this many periods is a restart."""
UNEVEN_SHARE = 0.02
"""Share of rows that may fall on a sample already taken before the stamps are called
unevenly spaced (:func:`_check_even_spacing`)."""


def _check_even_spacing(t_s: np.ndarray, tb: Timebase, where: str,
                        lines: np.ndarray) -> None:
    """RecordingError when the stamps lie on no grid of one period: more than
    :data:`UNEVEN_SHARE` of the rows fall on a sample another row already holds. Stamps
    jittered around a grid keep every row; intervals that vary at random (a phone's
    sensor events, 10 +- 2 ms) wander off any grid, and were read with 9 % of the rows
    dropped as "damaged" and 5 % of the samples as holes, the Allan deviation computed
    on what was left."""
    finite = int(np.isfinite(t_s).sum())
    shared = finite - int(tb.keep.sum())
    if finite and shared > UNEVEN_SHARE * finite:
        back = np.nonzero(np.diff(t_s) < -RESTART_PERIODS / tb.rate_hz)[0]
        if back.size:  # a restart, not jitter: say where (half the file was "damage")
            i = int(back[0])
            raise RecordingError(
                f"{where}:{int(lines[i + 1])}: the time column goes back ({t_s[i]:.6g} -> "
                f"{t_s[i + 1]:.6g} s) and counts up again ({back.size} such step(s)): a "
                "logger that restarted, or files joined; split the file there")
        dt = np.diff(t_s[np.isfinite(t_s)])
        dt = dt[dt > 0]
        spread = float(np.std(dt) / np.median(dt)) if dt.size else math.nan
        finer = _finer_grid(t_s, tb.rate_hz)
        raise RecordingError(
            f"{where}: the time stamps are not evenly spaced: {shared} of {finite} rows "
            f"fall on a sample another row holds at {tb.rate_hz:.6g} Hz (intervals vary by "
            f"{100 * spread:.0f} %)"
            + (f"; they lie on a grid of {finer:.6g} Hz with most samples missing: give "
               f"--rate {finer:.6g} if that is the rate" if finer is not None else
               "; the Allan statistics need evenly spaced samples: resample them, or read "
               "the rows in order at a nominal rate with --rate HZ --columns t=-"))


def _finer_grid(t_s: np.ndarray, rate_hz: float) -> float | None:
    """``k x rate_hz`` (k = 2, 3, 4) when every stamp lies within a quarter period of that
    grid: stamps of a stream that lost more than half its samples at random, whose
    median spacing is two or three periods (read at half the rate, the odd steps fell
    between the samples)."""
    t = t_s[np.isfinite(t_s)]
    if t.size < 3:
        return None
    for k in (2, 3, 4):
        period = 1.0 / (k * rate_hz)
        phase = (t - t[0]) / period
        if np.all(np.abs(phase - np.round(phase)) < 0.25):
            slope = np.polyfit(np.round(phase), t, 1)[0]  # that grid's own period
            return float(1.0 / slope)
    return None


def _index_stride(index: np.ndarray) -> int:
    """The greatest common divisor of a sample-index column's increasing steps (1 for an
    index of consecutive samples). A log that writes every 10th value of a sample
    counter was read at 10x its rate with 90 % of the samples "lost", every Allan
    deviation NaN."""
    steps = np.diff(index)
    steps = steps[steps > 0]
    if not steps.size or not np.all(steps == np.round(steps)):
        return 1
    return int(np.gcd.reduce(steps.astype(np.int64)))


def _stamps_against_stated(t_s: np.ndarray, at_stated: Timebase,
                           stated: tuple[float, str], where: str) -> Timebase | None:
    """The time stamps' own timebase when they contradict the rate a ``# key: value``
    line states (as :func:`_check_given_rate` judges ``--rate``), else None: read at the
    stated rate, stamps 0.1 % off it slipped rows off their samples (311 fake holes in
    8000 rows at 100.1 Hz under ``# odr_hz: 104``, every ADEV from 1 s NaN). Up to
    :data:`GIVEN_RATE_TOLERANCE` off (an oscillator's tolerance) the stamps' rate is
    used; beyond, which of the two is wrong cannot be told, and the file is refused."""
    own = _contradicting_stamps(t_s, at_stated, where)
    if own is None:
        return None
    if abs(own.rate_hz / stated[0] - 1.0) > GIVEN_RATE_TOLERANCE:
        raise RecordingError(
            f"{where}: the file states {stated[0]:.6g} Hz (# {stated[1]}) but its time "
            f"stamps give {own.rate_hz:.6g} Hz; give --rate HZ with the right one")
    return own


def _contradicting_stamps(t_s: np.ndarray, given: Timebase, where: str) -> Timebase | None:
    """The time stamps' own timebase (least squares) when it contradicts ``given`` (the
    stamps read at a given or stated rate) by enough to move a stamp half a sample over
    the record, unless the given rate keeps more of the stamps; None otherwise, or when
    the stamps give no rate of their own (the given one decides)."""
    try:
        own = timebase_from_times(t_s, where)
    except RecordingError:
        return None
    span = int(own.index[-1]) if own.index.size else 0
    if (abs(own.rate_hz / given.rate_hz - 1.0) * span > 0.5
            and given.keep.sum() <= own.keep.sum()):
        return own
    return None


def _check_given_rate(t_s: np.ndarray, given: Timebase, where: str) -> None:
    """RecordingError when ``--rate`` (``given``: the stamps read at it) contradicts the
    time column's own rate (least squares, where it has one) by enough to move a stamp
    half a sample over the record, unless it reads more of the stamps than that rate:
    read at it, the rows would slip off their samples (stamps 100 Hz apart at --rate 50
    put every second row on the sample before it, half the file skipped as damaged; at
    --rate 100.5, 2000 rows left 10 holes)."""
    own = _contradicting_stamps(t_s, given, where)
    if own is not None:
        raise RecordingError(
            f"{where}: --rate {given.rate_hz:g} Hz contradicts the time column, which "
            f"gives {own.rate_hz:.8g} Hz (least squares; over its {int(own.index[-1]) + 1} "
            "samples the "
            "difference slips rows off their samples); drop --rate to read the file at its "
            "own rate")


def _decimal_commas(raw: _Raw) -> bool:
    """The headerless two-column comma file is one column with decimal commas: every
    second field is digits only and either one starts with 0 (``0,0123``) or the first
    fields never increase as time tags do (``12,5`` ``12,7`` ``11,9``)."""
    if not (raw.header is None and raw.n_rows and raw.digits_after_comma):
        return False
    first = raw.table()[:, 0]
    return raw.leading_zero_after_comma or bool(np.any(np.diff(first) <= 0))


def _channel_unit(ch: str, col: Column, options: InputOptions, si_format: bool,
                  headerless: bool, where: str) -> tuple[float, str]:
    """(factor to dps or g, unit name) of a gyro or accelerometer column."""
    gyro = ch.startswith("g")
    table = GYRO_UNITS_DPS if gyro else ACCEL_UNITS_G
    given = options.gyro_unit if gyro else options.accel_unit
    if given is not None:
        return table[given], given
    if col.unit is not None:
        if col.unit not in table:
            raise RecordingError(f"{where}: column {col.text.strip()!r} is in {col.unit!r}, "
                                 f"not {'a gyro' if gyro else 'an accelerometer'} unit "
                                 f"({', '.join(table)}); give --units")
        return table[col.unit], col.unit
    if si_format:
        unit = "rad/s" if gyro else "m/s2"
        return table[unit], unit
    if col.name in OWN_NAMES or headerless:
        unit = "dps" if gyro else "g"
        return 1.0, unit
    raise RecordingError(f"{where}: the unit of column {col.text.strip()!r} is not stated; "
                         "give --units GYRO,ACCEL (e.g. --units dps,g or --units rad/s,m/s2)")


def _check_gravity(values: np.ndarray, units: dict[str, str], options: InputOptions,
                   where: str, assumed: list[str]) -> None:
    """A static accelerometer reads about 1 g, whatever unit the file or ``--units``
    claims: a median |a| of 5-15 "g" is m/s^2 read as g, 500-1500 is mg read as g, and
    0.07-0.14 with a m/s^2 unit is g read as m/s^2 (refused with the fix). With one or
    two axes the largest axis's median |a| is a lower bound of |a| (no axis at rest reads
    more than 1 g): 5-15 and 500-1500 are refused the same way (the check needed all three
    axes: ``t,ax,az`` in m/s^2 was read as 9.8 g). Unless ``--units`` says so, a level
    above :data:`MAX_ACCEL_G` (raw counts: 16384 per g) is refused too, and, on three
    axes whose unit nothing states, one below :data:`MIN_ACCEL_G` but not 0 (a unit
    1000x off; all-zero columns: not measured; a stated unit may hold gravity-free
    "linear acceleration" or a drop test)."""
    axes = [a for a in ("ax", "ay", "az") if a in units]
    if not axes:
        return
    cols = values[:, [CHANNELS.index(a) for a in axes]]
    if len(axes) == 3:
        level = float(np.nanmedian(np.sqrt(np.nansum(cols ** 2, axis=1)))) if len(cols) \
            else math.nan
    else:
        level = float(np.nanmax(np.nanmedian(np.abs(cols), axis=0))) if len(cols) \
            else math.nan
    unit = units[axes[0]]
    said = unit + (" (--units)" if options.accel_unit is not None else "")
    what = ("the accelerometer reads" if len(axes) == 3
            else f"the accelerometer's {' and '.join(axes)} read")
    # the gyro's unit in the fix: the user's --units; otherwise the user must say it (a
    # file whose accelerometer is not in the unit it claims may have its gyro in rad/s
    # too, which "dps" would read 57x low)
    gyro = options.gyro_unit if options.gyro_unit is not None else "GYRO"
    gyro_hint = ("" if options.gyro_unit is not None else
                 f" (GYRO: the gyroscope's unit, dps or rad/s; it is read as "
                 f"{units.get('gx', 'dps')} now" + (", which nothing in the file states)"
                                                    if "gx" in assumed else ")"))
    for lo, hi, really in ((5.0, 15.0, "m/s2"), (500.0, 1500.0, "mg")):
        if lo < level < hi:
            raise RecordingError(f"{where}: {what} {level:.3g} g at rest, which is {really} "
                                 f"read as {said}; give --units {gyro},{really}{gyro_hint}")
    if len(axes) == 3 and 0.07 < level < 0.14 and unit in ("m/s2", "m/s^2"):
        raise RecordingError(f"{where}: {what} {level:.3g} g at rest, which is g read as "
                             f"{said}; give --units {gyro},g{gyro_hint}")
    stated = not any(a in assumed for a in axes)  # by the header or a metadata line
    if options.accel_unit is None and (level > MAX_ACCEL_G or (
            len(axes) == 3 and 0 < level < MIN_ACCEL_G and not stated)):
        raise RecordingError(
            f"{where}: {what} {level:.4g} g at rest in {unit}, "
            + ("beyond any accelerometer's range (raw counts?)" if level > MAX_ACCEL_G
               else "not 1 g (a unit 1000x off?)")
            + f"; give --units {gyro},ACCEL with the accelerometer's unit (g, mg, m/s2), "
            "or convert counts to a unit first")


MAX_ACCEL_G = 32.0
"""Largest level a static accelerometer's samples may read, g (the LSM6DS parts' widest
full scale is 16 g; raw int16 counts read as g are in the thousands)."""
MIN_ACCEL_G = 0.05
"""Smallest |a| of a three-axis accelerometer at rest, g (free fall aside: 1 g)."""


TIME_RATE_HZ = (1e-3, 1e6)
"""Rates (Hz) a time column may give: outside, its unit (often a ``--time-unit`` that
contradicts the file) is wrong, and the file is refused rather than read at that rate."""


SLOW_IN_SECONDS_HZ = 1.0
"""A time column in seconds by its header that gives less than this rate is said to be
slow for an IMU (a ``time_s`` column holding milliseconds reads 100 Hz as 0.1 Hz)."""


TEMP_UNITS: dict[str, tuple[float, float]] = {
    "degC": (1.0, 0.0), "K": (1.0, -273.15), "degF": (5.0 / 9.0, -32.0 * 5.0 / 9.0)}
"""A temperature column's header unit -> (factor, offset) to degC."""
_TEMP_WORDS = {"k": "K", "kelvin": "K", "f": "degF", "degf": "degF", "°f": "degF"}
LONG_TIME_UNITS_S: dict[str, float] = {"min": 60.0, "h": 3600.0}
"""Time units a header may state beyond ``--time-unit``'s (a spreadsheet's minutes)."""


def _in_degc(values: np.ndarray, col: Column, where: str) -> np.ndarray:
    """A temperature column in degC from its header unit (none: degC); an unknown unit is
    refused (``temperature [K]`` was read as 298.15 degC)."""
    unit = col.unit if col.unit is None else _TEMP_WORDS.get(col.unit.lower(), col.unit)
    if unit is None:
        return values
    if unit not in TEMP_UNITS:
        raise RecordingError(f"{where}: the temperature column {col.text.strip()!r} is in "
                             f"{unit!r}; imubench reads degC, K or degF")
    factor, offset = TEMP_UNITS[unit]
    return values * factor + offset


def _time_unit(col: Column, options: InputOptions, ros: bool, t_raw: np.ndarray,
               rate: float | None, where: str) -> tuple[str, float]:
    """(unit name, seconds per unit) of the time column."""
    if options.time_unit is not None:
        if col.unit in TIME_UNITS_S and col.unit != options.time_unit:
            return (f"{options.time_unit} (--time-unit; the header says {col.unit})",
                    TIME_UNITS_S[options.time_unit])
        return options.time_unit, TIME_UNITS_S[options.time_unit]
    if col.unit in TIME_UNITS_S:
        return f"{col.unit} (header)", TIME_UNITS_S[col.unit]
    if col.unit in LONG_TIME_UNITS_S:
        return f"{col.unit} (header)", LONG_TIME_UNITS_S[col.unit]
    if col.unit is not None:  # a time unit that is no time unit: refused, not ignored
        raise RecordingError(f"{where}: the time column {col.text.strip()!r} is in "
                             f"{col.unit!r}; imubench reads s, ms, us, ns, min or h "
                             "(--time-unit s|ms|us|ns)")
    if ros:
        return "ns (ROS)", 1e-9
    try:
        unit, scale = time_unit_from_spacing(t_raw, where)
    except RecordingError:
        if rate is not None and col.name == "t" and col.text.strip() == "t":
            return "s (imubench's t)", 1.0  # its own column is in seconds
        found = increasing_step(t_raw)
        if rate is None or found is None:
            raise
        per_sample = found * rate  # the unit that matches the given rate
        unit = min(TIME_UNITS_S, key=lambda u: abs(math.log(per_sample * TIME_UNITS_S[u])))
        return f"{unit} (from the rate)", TIME_UNITS_S[unit]
    if col.name == "t" and unit != "s" and col.text.strip() == "t":
        # imubench's own column is in seconds: a spacing that says otherwise is refused
        step = increasing_step(t_raw)
        assert step is not None  # time_unit_from_spacing found one
        raise RecordingError(
            f"{where}: column t steps by {step:.6g}: {1 / step:.6g} Hz if in seconds (as "
            f"imubench writes it), {1 / (step * scale):.6g} Hz if in {unit}; give "
            f"--time-unit {unit} or --time-unit s (or --rate HZ)")
    if unit == "d":
        return "days (MJD, detected)", SECONDS_PER_DAY
    return f"{unit} (detected{_other_reading(t_raw, unit)})", scale


def _other_reading(t_raw: np.ndarray, unit: str) -> str:
    """``; 0.1 Hz if in s: --time-unit s`` for a time unit told from the stamps' spacing
    (:func:`time_unit_from_spacing` takes the unit that gives 7 Hz to 7 kHz): a 0.1 Hz
    drift log in seconds reads as 100 Hz in ms, an 8 kHz one in ms as 8 Hz in s; the
    neighbouring reading is named so that a user can tell."""
    step = increasing_step(t_raw)
    units = list(TIME_UNITS_S)
    if step is None or unit not in units:
        return ""
    i = units.index(unit)
    out = []
    for j in (i - 1, i + 1):
        if 0 <= j < len(units):
            rate = 1.0 / (step * TIME_UNITS_S[units[j]])
            if TIME_RATE_HZ[0] <= rate <= TIME_RATE_HZ[1]:
                out.append(f"{rate:.4g} Hz if in {units[j]}: --time-unit {units[j]}")
    return "; " + ", ".join(out) if out else ""
