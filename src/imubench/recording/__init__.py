"""Recordings: the native ``.imbr`` format, CSV and other text tables, ROS 2 bags and
MCAP, HDF5, chosen by suffix.

* :func:`load_recording` reads a whole recording into a :class:`Recording`: the one
  reader of every command, with :class:`~imubench.recording.options.InputOptions` for
  files from elsewhere (docs/recordings.md). What it had to infer (rate, time unit) and
  any damage it read around (how much was kept) is logged as a warning on
  ``imubench.recording``, the same for every command.
* :func:`open_writer` opens a writer (native, CSV or HDF5) for a new file.
* :func:`convert` converts between them, or exports one channel to a Stable32 data file
  (:mod:`imubench.recording.stable32`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from imubench.batch import CHANNELS, Batch, Gap, true_runs
from imubench.errors import RecordingError
from imubench.recording.csvio import CsvWriter
from imubench.recording.hdf5 import Hdf5Writer, read_hdf5
from imubench.recording.native import (
    STORAGE_FLOAT,
    STORAGE_RAW,
    NativeReader,
    NativeWriter,
)
from imubench.recording.options import InputOptions
from imubench.recording.rosin import is_ros2_bag, read_ros
from imubench.recording.secrets import drop_secrets
from imubench.recording.stable32 import write_stable32
from imubench.recording.textin import read_text
from imubench.recording.timebase import GIVEN_RATE_TOLERANCE

__all__ = [
    "STABLE32_SUFFIX", "STORAGE_FLOAT", "STORAGE_RAW", "Converted", "CsvWriter", "Gap",
    "Hdf5Writer", "InputOptions", "NativeReader", "NativeWriter", "Recording", "convert",
    "load_recording", "open_writer", "recording_kind", "segment_path", "writer_kind",
]

log = logging.getLogger(__name__)
TEXT_SUFFIXES = (".csv", ".txt", ".dat", ".tsv")
"""Text tables (each also as ``.gz``)."""

Writer = NativeWriter | CsvWriter | Hdf5Writer


@dataclass(frozen=True)
class Converted:
    """What :func:`convert` read and what it wrote: ``gaps`` / ``lost_samples`` count the
    gap records in the output (the writer's counts: a damaged input's holes included)."""

    recording: Recording
    gaps: int
    lost_samples: int
HDF5_SUFFIXES = (".h5", ".hdf5")
STABLE32_SUFFIX = ".dat"
"""What ``convert`` writes as a Stable32 data file (one channel)."""
CONVERT_BLOCK = 65536
"""Samples per data record when converting."""


def recording_kind(path: str | Path) -> str:
    """``native`` (``.imbr``), ``csv`` (``.csv``, ``.csv.gz``: imubench writes these),
    ``hdf5`` (``.h5``, ``.hdf5``), ``text`` (other text tables: ``.txt``, ``.dat``,
    ``.tsv``, each also ``.gz``) or ``ros`` (``.mcap``, a ROS 2 bag folder or its
    ``.db3``) from the name; RecordingError otherwise."""
    name = Path(path).name.lower()
    if name.endswith(".imbr"):
        return "native"
    if name.endswith(HDF5_SUFFIXES):
        return "hdf5"
    if name.endswith(".mcap") or is_ros2_bag(Path(path)):
        return "ros"
    if name.endswith((".csv", ".csv.gz")):
        return "csv"
    if name.endswith(TEXT_SUFFIXES + tuple(s + ".gz" for s in TEXT_SUFFIXES)):
        return "text"
    raise RecordingError(
        f"{path}: unknown recording suffix; use .imbr (native), .csv / .csv.gz, .h5, a "
        "text table .txt / .dat / .tsv (also .gz), .mcap or a ROS 2 bag"
    )


@dataclass
class Recording:
    """A whole recording in memory.

    ``values`` are in :data:`CHANNELS` order (dps, g) at the sample indices ``index``
    (increasing; holes are lost samples). :meth:`channel` returns a dense series on the
    full index grid with NaN in the holes, ready for the statistics (NaN = gap).
    """

    path: Path
    metadata: dict[str, Any]
    index: np.ndarray
    t_s: np.ndarray
    values: np.ndarray
    temp_c: np.ndarray
    raw: np.ndarray | None = None
    gaps: list[Gap] = field(default_factory=list)
    damage: str | None = None
    complete: bool = True

    @property
    def rate_hz(self) -> float:
        """The sample rate, Hz: the one measured from the time stamps when they show the
        chip's clock off its nominal ODR (``measured_odr_hz``, :func:`measured_rate`),
        else the header's ``odr_hz``."""
        return float(self.metadata.get("measured_odr_hz", self.metadata["odr_hz"]))

    @property
    def channels(self) -> list[str]:
        """Channels holding at least one value (plus ``temp`` when measured)."""
        out = [c for i, c in enumerate(CHANNELS) if np.isfinite(self.values[:, i]).any()]
        if np.isfinite(self.temp_c).any():
            out.append("temp")
        return out

    def __len__(self) -> int:
        return len(self.index)

    @property
    def lost_samples(self) -> int:
        """Samples lost: the holes between recorded samples, plus the gap records that lie
        before the first or after the last recorded sample (a stream that started or
        ended in a gap, e.g. a chip reset just before the end of ``acquire``)."""
        if not len(self.index):
            return sum(g.lost for g in self.gaps)
        first, last = int(self.index[0]), int(self.index[-1])
        inside = last - first + 1 - len(self.index)
        outside = sum(
            g.lost for g in self.gaps if g.at <= first or g.at - g.lost > last
        )
        return int(inside + outside)

    @property
    def holes(self) -> int:
        """Holes between recorded samples."""
        return int(np.count_nonzero(np.diff(self.index) > 1))

    def _dense(self, column: np.ndarray) -> np.ndarray:
        if not len(self.index):
            return np.zeros(0)
        out = np.full(int(self.index[-1] - self.index[0] + 1), np.nan)
        out[self.index - self.index[0]] = column
        return out

    def channel(self, name: str) -> np.ndarray:
        """Dense float64 series of ``name`` (gx..az, temp) with NaN where samples are lost."""
        if name == "temp":
            return self._dense(self.temp_c)
        if name not in CHANNELS:
            raise RecordingError(
                f"{self.path}: no channel {name!r}; channels are {', '.join((*CHANNELS, 'temp'))}"
            )
        return self._dense(self.values[:, CHANNELS.index(name)])

    def channel_lost(self, name: str) -> tuple[int, int]:
        """(samples lost, runs of them) of channel ``name`` between the first and the
        last recorded sample: the recording's holes and, besides them, the channel's
        own empty cells (a CSV line whose ``gx`` is empty keeps its other channels)."""
        missing = np.isnan(self.channel(name))
        return int(missing.sum()), len(true_runs(missing))

    def batch(self) -> Batch:
        return Batch(self.index, self.t_s, self.values, self.temp_c, self.raw)


SEGMENT_SUFFIXES = (".csv.gz", ".imbr", ".csv")
"""Suffixes of the recordings a live acquisition writes in segments."""


def segment_path(path: Path, segment: int) -> Path:
    """``NAME.partN.SUFFIX`` for segment ``N`` >= 2 (segment 1 is ``path`` itself): where
    the recorder goes on after a full disk (:mod:`imubench.recorder`)."""
    if segment <= 1:
        return path
    name = path.name
    for suffix in SEGMENT_SUFFIXES:
        if name.lower().endswith(suffix):
            stem = name[: -len(suffix)]
            return path.with_name(f"{stem}.part{segment}{name[len(stem):]}")
    return path.with_name(f"{name}.part{segment}")


MEASURED_RATE_MIN_SPAN_S = 10.0
"""Shortest span of time stamps the sample rate is measured from, s."""
MEASURED_RATE_TOLERANCE = 1e-4
"""Relative departure from the nominal ODR below which the nominal rate is kept."""


def empty_cells_text(rec: Recording, channel: str) -> str | None:
    """'gx: 1100 samples lost in 2 run(s), 100 of them empty cells beside the recording's
    1 hole(s); ...' when
    ``channel`` misses more samples than the recording's holes (:meth:`Recording.
    channel_lost`), else None: those samples are lost too (an outside reviewer's 1000
    empty cells were warned of while the coverage and the JSON said no holes)."""
    lost, runs = rec.channel_lost(channel)
    in_holes = (int(rec.index[-1] - rec.index[0]) + 1 - len(rec.index)) if len(rec.index) else 0
    if lost <= in_holes:
        return None
    return (f"{channel}: {lost} samples lost in {runs} run(s), "
            f"{lost - in_holes} of them empty cells beside the recording's "
            f"{rec.holes} hole(s); the curves are computed across them")


def coverage_text(samples: int, lost_samples: int, holes: int) -> str:
    """``54950 samples, 2 hole(s) (6050 samples, 9.9 % missing; the curves are computed
    across them)``, or ``N samples, no holes``: what every analysis says of its input."""
    if not lost_samples:
        return f"{samples} samples, no holes"
    share = 100.0 * lost_samples / (samples + lost_samples)
    return (f"{samples} samples, {holes} hole(s) ({lost_samples} samples, {share:.3g} % "
            "missing; the curves are computed across them)")


def measured_rate(index: np.ndarray, t_s: np.ndarray, nominal_hz: float) -> float | None:
    """The rate the samples were taken at by their time stamps, when it departs from
    ``nominal_hz`` by more than :data:`MEASURED_RATE_TOLERANCE` over at least
    :data:`MEASURED_RATE_MIN_SPAN_S`; else None (how far off is the caller's to judge,
    :func:`_with_measured_rate`).

    imubench stamps each sample from the chip's timestamp counter with the tick period
    measured against the host clock (docs/drivers.md), so a part whose oscillator runs
    3.75 % fast (107.9 Hz for a nominal 104, within the LSM6DS parts' ODR tolerance)
    has stamps 1/107.9 s apart: at the header's 104 Hz every tau would be 3.75 % long
    and the densities read off it about 2 % off. The rate is the median over k of
    ``(index[k + n/2] - index[k]) / (t[k + n/2] - t[k])``: samples half the record
    apart, so a host's read jitter weighs little, and robust to the first seconds,
    stamped at the nominal rate before the tick period is first measured (a least-squares
    slope took 108.03 Hz from those for 107.90)."""
    rate = _stamps_rate(index, t_s)
    if rate is None:
        return None
    return rate if abs(rate / nominal_hz - 1.0) > MEASURED_RATE_TOLERANCE else None


COARSE_SPAN_S = 1.0
"""Shortest span of time stamps a gross contradiction (beyond GIVEN_RATE_TOLERANCE) of a
stated rate is judged over: a 9 s file at twice its stamps' rate was read without a word,
the 10 s needed to measure a clock's few percent applying to it too."""


def _stamps_rate(index: np.ndarray, t_s: np.ndarray, strict: bool = False,
                 min_span_s: float = MEASURED_RATE_MIN_SPAN_S) -> float | None:
    """The median over k of ``(index[k + n/2] - index[k]) / (t[k + n/2] - t[k])`` (see
    :func:`measured_rate`); None over less than ``min_span_s``, where those spans do not
    all increase, or (``strict``) where two stamps repeat (rounded coarser than a period:
    the stamps have no rate of their own)."""
    ok = np.isfinite(t_s)
    i, t = index[ok].astype(np.float64), t_s[ok]
    h = len(t) // 2
    if h < 1 or t[-1] - t[0] < min_span_s:
        return None
    if strict and not np.all(np.diff(t) > 0):
        return None
    dt = t[h:] - t[: len(t) - h]
    if not np.all(dt > 0):
        return None
    return float(np.median((i[h:] - i[: len(t) - h]) / dt))




def _check_given_rate(rec: Recording, given_hz: float, where: str) -> None:
    """RecordingError when ``--rate`` contradicts the rate the recording's own time stamps
    show (over at least :data:`COARSE_SPAN_S`) by more than
    :data:`GIVEN_RATE_TOLERANCE`: ``--rate 52`` on imubench's own 104 Hz files was taken
    without a word, every tau twice as long, and ``convert --rate`` wrote it into the
    copy's header for good (a foreign CSV's time column was already checked)."""
    own = _stamps_rate(rec.index, rec.t_s, strict=True, min_span_s=COARSE_SPAN_S)
    if own is not None and abs(given_hz / own - 1.0) > GIVEN_RATE_TOLERANCE:
        raise RecordingError(
            f"{where}: --rate {given_hz:g} Hz contradicts the recording's time stamps, which "
            f"give {own:.6g} Hz; drop --rate to read it at its own rate")


CHIP_CLOCK_MAX_OFF = 0.5
"""Largest departure of the time stamps of imubench's own files (stamped from the chip's
timestamp counter) from the header's nominal ODR that is taken as the chip's clock (the
driver measures a tick period up to 50 % off); beyond it the stamps are refused."""


def _with_measured_rate(rec: Recording, kind: str) -> Recording:
    """``rec`` with ``measured_odr_hz`` in its metadata when :func:`measured_rate` finds
    one (said in a warning). A text file's stated rate is trusted up to
    :data:`GIVEN_RATE_TOLERANCE` from its stamps, the nominal ODR of imubench's own files
    (native, HDF5, its CSV with a ``chip`` line) up to :data:`CHIP_CLOCK_MAX_OFF` (a
    chip 30 % slow was read at its nominal rate, every tau 30 % long, since only 10 % was
    measured); beyond, RecordingError naming both."""
    nominal = float(rec.metadata["odr_hz"])
    rate = measured_rate(rec.index, rec.t_s, nominal)
    if rate is None:  # under 10 s: only a gross contradiction is judged
        coarse = _stamps_rate(rec.index, rec.t_s, min_span_s=COARSE_SPAN_S)
        if coarse is None or abs(coarse / nominal - 1.0) <= GIVEN_RATE_TOLERANCE:
            return rec
        rate = coarse
    off = rate / nominal - 1.0
    own = kind in ("native", "hdf5") or (kind == "csv" and "chip" in rec.metadata)
    limit = CHIP_CLOCK_MAX_OFF if own else GIVEN_RATE_TOLERANCE
    if abs(off) > limit:
        raise RecordingError(
            f"{rec.path}: the header states {nominal:g} Hz but the time stamps give "
            f"{rate:.6g} Hz ({100.0 * off:+.3g} %); give --rate HZ with the right one")
    rec.metadata["measured_odr_hz"] = rate
    log.warning("%s: rate %.6g Hz, measured from the time stamps: the clock runs %+.3g %% "
                "off the nominal %g Hz the header states (odr_hz); taus use the measured "
                "rate (--rate overrides)", rec.path, rate, 100.0 * off, nominal)
    return rec


def load_recording(path: str | Path, options: InputOptions | None = None) -> Recording:
    """Read a recording (:func:`recording_kind`). ``options`` override what the file
    states (rate) or say what it does not (columns, units, time unit).

    A damaged file is read around its damage (native: the damaged records are skipped;
    text: the unreadable lines), with one warning saying what was kept; a file that
    cannot be read at all raises RecordingError naming the file and the fix.
    """
    path = Path(path)
    opts = options or InputOptions()
    kind = recording_kind(path)
    rec, where, stated = _load(path, kind, opts)
    if "segment" not in rec.metadata:
        rec = _with_segments(rec, kind, opts)
    if opts.rate_hz is not None:
        _check_given_rate(rec, opts.rate_hz, str(path))
    if rec.damage:
        log.warning("%s: damaged: %s; kept %d samples, %d lost in holes", where,
                    rec.damage, len(rec), rec.lost_samples)
    # a converted recording's header may carry one: it is measured again, or --rate rules
    rec.metadata.pop("measured_odr_hz", None)
    return _with_measured_rate(rec, kind) if stated and opts.rate_hz is None else rec


def _with_segments(first: Recording, kind: str, opts: InputOptions) -> Recording:
    """``first`` joined with the segments that continue it (``NAME.part2.imbr``, ...:
    :func:`segment_path`, each header's ``previous_segment`` naming the one before), as
    one recording: a recorder that met a full disk went on in a new segment, and the
    segments with their gap records hold every sample of the run. Reading ``NAME.imbr``
    alone gave the first segment's samples as the whole run, without a word. A later
    segment given by its own name is read alone."""
    parts = [first]
    while (nxt := segment_path(first.path, len(parts) + 1)).exists():
        rec = _load(nxt, kind, opts)[0]
        previous = Path(str(rec.metadata.get("previous_segment") or "")).name
        why = _not_a_continuation(parts[-1], rec, previous)
        if why is not None:
            log.warning("%s: not read as a segment of %s: %s", nxt, first.path, why)
            break
        if len(rec) and len(parts[-1]) and rec.index[0] <= parts[-1].index[-1]:
            raise RecordingError(
                f"{nxt}: its first sample {int(rec.index[0])} does not follow "
                f"{parts[-1].path.name}'s last {int(parts[-1].index[-1])}")
        parts.append(rec)
    nxt = segment_path(first.path, len(parts) + 1)
    later = [segment_path(first.path, k) for k in range(len(parts) + 2, len(parts) + 6)]
    if not nxt.exists() and any(p.exists() for p in later):  # (one refused was said)
        log.warning("%s: %s is missing, so the later segment(s) %s are not read with it",
                    first.path, nxt.name,
                    ", ".join(p.name for p in later if p.exists()))
    if len(parts) == 1:
        return first
    log.warning("%s: read with its %d later segment(s): %s", first.path, len(parts) - 1,
                ", ".join(p.path.name for p in parts[1:]))
    raws = [p.raw for p in parts]
    damage = "; ".join(f"{p.path.name}: {p.damage}" for p in parts if p.damage)
    meta = {**first.metadata, "segments": [p.path.name for p in parts]}
    return Recording(
        first.path, meta,
        np.concatenate([p.index for p in parts]),
        np.concatenate([p.t_s for p in parts]),
        np.concatenate([p.values for p in parts]),
        np.concatenate([p.temp_c for p in parts]),
        None if any(r is None for r in raws) else np.concatenate(raws),  # type: ignore[arg-type]
        [g for p in parts for g in p.gaps], damage or None, parts[-1].complete)


SEGMENT_KEYS = ("odr_hz", "chip", "source_uri", "gyro_sensitivity_dps",
                "accel_sensitivity_g")
"""Header keys a segment must share with the one before it (when both state them)."""


def _not_a_continuation(before: Recording, rec: Recording, previous: str) -> str | None:
    """Why ``rec`` does not continue ``before`` (None: it does): its header names another
    segment before it, states another ODR, chip, source or scale, or its time stamps go
    back (a leftover ``NAME.part2.imbr`` of an older run at 416 Hz was joined to a new
    104 Hz recording, its gap record rewritten)."""
    if previous != before.path.name:
        return f"its header names {previous or None!r} as the segment before it"
    for key in SEGMENT_KEYS:
        a, b = before.metadata.get(key), rec.metadata.get(key)
        if a is not None and b is not None and a != b:
            return f"its {key} is {b!r}, {before.path.name}'s {a!r}"
    if len(before) and len(rec) and rec.t_s[0] < before.t_s[-1]:
        return (f"its time stamps start at {rec.t_s[0]:.6g} s, before {before.path.name} "
                f"ends ({before.t_s[-1]:.6g} s)")
    return None


def _load(path: Path, kind: str, opts: InputOptions) -> tuple[Recording, str, bool]:
    """The recording, where its damage starts (the path, or path:line), and whether its
    rate is the one the file states (not read off its time stamps)."""
    if kind == "hdf5":
        meta, b, gaps, complete = read_hdf5(path)
        if opts.rate_hz is not None:
            meta["odr_hz"] = opts.rate_hz
        if not complete:
            log.warning("%s: the writer did not close this file (interrupted?); read %d "
                        "samples", path, len(b))
        return (Recording(path, meta, b.index, b.t_s, b.values, b.temp_c, b.raw, gaps, None,
                          complete), str(path), True)
    if kind != "native":
        read = read_ros(path, opts) if kind == "ros" else read_text(path, opts)
        b = read.batch
        for note in read.notes:
            log.log(logging.WARNING if read.inferred else logging.INFO, "%s", note)
        for warning in read.warnings:
            log.warning("%s", warning)
        damage = None
        where = str(path)
        if read.bad_lines:
            first = read.bad_lines[0]
            damage = (f"{len(read.bad_lines)} {read.item}(s) skipped (unreadable, out of "
                      f"time order or stray at an end), first "
                      + ("at the end of a damaged compressed stream" if first < 0
                         else f"{read.item.split()[-1]} {first}"))
            where = f"{path}:{first}" if first > 0 else where
        return (Recording(path, read.meta, b.index, b.t_s, b.values, b.temp_c, None,
                          read.gaps, damage), where, read.rate_stated)
    return _load_native(path, opts), str(path), True


def _load_native(path: Path, opts: InputOptions) -> Recording:
    with NativeReader(path) as reader:
        b = reader.read_all()
        meta = dict(reader.metadata)
        cal = meta.get("calibration")
        if reader.storage == STORAGE_RAW and isinstance(cal, dict) and cal.get("applied"):
            # raw counts are stored; the values were recorded calibrated: calibrate again
            from imubench.calibration import Calibration, CalibrationError

            try:
                b = Calibration.from_description(cal).apply(b)
            except CalibrationError as exc:
                raise RecordingError(f"{path}: header calibration: {exc}") from None
        if opts.rate_hz is not None:
            meta["odr_hz"] = opts.rate_hz
        if reader.end is None:  # a killed writer, or one still writing
            log.warning("%s: no end record: the writer did not close this file (killed, "
                        "its disk full, or still recording); read %d samples, what came "
                        "after the last whole record is not in it", path, len(b))
        return Recording(path, meta, b.index, b.t_s, b.values, b.temp_c, b.raw,
                         reader.gaps, reader.damage, reader.end is not None)


def open_writer(path: str | Path, metadata: dict[str, Any], **kwargs: Any) -> Writer:
    """Writer for a new recording, native, CSV or HDF5 by suffix."""
    kind = writer_kind(path)
    if kind == "csv":
        return CsvWriter(path, metadata, **kwargs)
    if kind == "hdf5":
        return Hdf5Writer(path, metadata, **kwargs)
    return NativeWriter(path, metadata, **kwargs)


def writer_kind(path: str | Path) -> str:
    """``native``, ``csv`` or ``hdf5``: the kind of recording :func:`open_writer` writes
    to ``path``; RecordingError listing the writable formats otherwise (the input-only
    ones, .mcap, ROS 2 bags and other text tables, are not offered)."""
    try:
        kind = recording_kind(path)
    except RecordingError:
        kind = "unknown"
    if kind not in ("native", "csv", "hdf5"):
        raise RecordingError(f"{path}: imubench cannot write this format; use .imbr, .csv, "
                             ".csv.gz or .h5 (or .dat with --channel for one channel as "
                             "Stable32 data)")
    return kind


def convert(src: str | Path, dst: str | Path, options: InputOptions | None = None,
            channel: str | None = None, calibration: str | Path | None = None,
            on_progress: Callable[[int, int], None] | None = None) -> Converted:
    """Convert ``src`` to ``dst`` (by suffix), keeping metadata, gaps and raw counts; a
    ``.dat`` destination is a Stable32 data file of ``channel``. The directory ``dst``
    goes into must exist (writers never create one).

    ``calibration``: a calibration file applied to the values (raw counts stay as they
    are; the header states it, as ``acquire --calibration`` does); refused when the
    header says a calibration was applied already. Secrets of an old header (an MQTT
    password: :mod:`imubench.recording.secrets`) are dropped, with a warning naming them.
    ``on_progress(done, total)`` after each block of samples written (a progress bar).
    """
    is_dat = Path(dst).name.lower().endswith(STABLE32_SUFFIX)
    if is_dat and channel is None:
        raise RecordingError(f"{dst}: a Stable32 .dat file holds one channel; give "
                             "--channel gx (or gy, gz, ax, ay, az, temp)")
    if not is_dat and channel is not None:
        raise RecordingError(f"{dst}: --channel is for a Stable32 .dat export; other "
                             "formats keep every channel")
    kind = "dat" if is_dat else writer_kind(dst)  # before reading: a bad OUT fails fast
    rec = load_recording(src, options)
    if calibration is not None:
        rec = _calibrated(rec, calibration)
    out = Path(dst)
    existed = out.exists()
    if kind == "hdf5" and not existed:
        _check_room_for_hdf5(rec, out)
    try:
        return _write_converted(rec, src, out, kind, channel, on_progress)
    except BaseException as exc:
        # a half-written file would read as a shorter recording (no end record in a CSV)
        # and block a retry ("exists already"): remove what this call created
        if not existed and out.exists():
            out.unlink()
        if isinstance(exc, OSError):
            raise RecordingError(f"{dst}: {exc.strerror or exc}; nothing was kept of the "
                                 "partial output") from exc
        raise


HDF5_BYTES_PER_SAMPLE = 8 + 8 + 4 + 6 * 8 + 6 * 2
"""Uncompressed bytes of one sample in an HDF5 recording (index, t, temperature, six
values, six raw counts)."""


def _check_room_for_hdf5(rec: Recording, dst: Path) -> None:
    """RecordingError when the disk under ``dst`` has less free space than ``rec`` takes
    uncompressed: HDF5 (h5py 3) does not fail cleanly on a full disk (a convert to a
    full tmpfs printed seven library tracebacks, then crashed with a segmentation fault
    and left a corrupt file). Compression may make it fit in less; the check is
    deliberately on the safe side."""
    import shutil

    if not dst.parent.is_dir():
        return  # the writer names the missing directory
    need = len(rec) * HDF5_BYTES_PER_SAMPLE + (1 << 20)
    free = shutil.disk_usage(dst.parent).free
    if free < need:
        raise RecordingError(
            f"{dst}: {free / 1e6:.1f} MB free on its disk, {need / 1e6:.1f} MB needed for "
            f"{len(rec)} samples uncompressed; HDF5 cannot fail cleanly on a full disk, so "
            "nothing was written: free some space or convert to .imbr or .csv.gz")


def _write_converted(rec: Recording, src: str | Path, dst: Path, kind: str,
                     channel: str | None,
                     on_progress: Callable[[int, int], None] | None) -> Converted:
    """The writing half of :func:`convert`."""
    if kind == "dat":
        assert channel is not None
        log.info("%s", write_stable32(rec, channel, dst))
        if on_progress is not None:
            on_progress(len(rec), len(rec))
        return Converted(rec, 0, 0)
    meta, dropped = drop_secrets(dict(rec.metadata))
    if dropped:
        log.warning("%s: dropped %d secret(s) from the header: %s (not copied to %s)", src,
                    len(dropped), ", ".join(dropped), dst)
    meta["converted_from"] = str(src)
    if rec.damage:
        meta["damage"] = f"{src}: {rec.damage}"
    if not rec.complete:
        meta["source_incomplete"] = ("the source's writer did not close it (killed or still "
                                     "recording): samples after its last record are missing")
    # the start of the source, never the conversion's time: its own, else its first
    # absolute time stamp, else unknown (null), which a writer does not replace with now
    meta.setdefault("start_utc", _start_from_stamps(rec.t_s))
    meta.pop("format", None)  # the source's container format; the writer states its own
    if kind == "native":
        meta["storage"] = STORAGE_RAW if rec.raw is not None else STORAGE_FLOAT
    else:
        meta.pop("storage", None)
    gaps = sorted(rec.gaps, key=lambda g: g.at)
    with open_writer(dst, meta) as writer:
        j = 0
        for start in range(0, len(rec), CONVERT_BLOCK):
            part = slice(start, start + CONVERT_BLOCK)
            last = int(rec.index[part][-1])
            mine = []
            while j < len(gaps) and gaps[j].at <= last:
                mine.append(gaps[j])
                j += 1
            writer.write(
                Batch(rec.index[part], rec.t_s[part], rec.values[part], rec.temp_c[part],
                      None if rec.raw is None else rec.raw[part], tuple(mine)),
            )
            if on_progress is not None:
                on_progress(min(start + CONVERT_BLOCK, len(rec)), len(rec))
        if j < len(gaps):  # the recording ended in a gap
            writer.write(Batch.empty(with_raw=rec.raw is not None, gaps=gaps[j:]))
    return Converted(rec, writer.gaps, writer.lost_samples)


def _start_from_stamps(t_s: np.ndarray) -> str | None:
    """The UTC start of a recording whose time stamps are Unix seconds (2001-2099), as
    ISO 8601; None when they count from anything else (a start that is not known)."""
    from imubench.recording.timebase import start_utc

    return start_utc(float(t_s[0])) if len(t_s) else None


def _calibrated(rec: Recording, path: str | Path) -> Recording:
    """``rec`` with the calibration file ``path`` applied to its values (raw counts
    unchanged) and stated in its header."""
    import dataclasses

    from imubench.calibration import Calibration

    already = rec.metadata.get("calibration")
    if isinstance(already, dict) and already.get("applied"):
        raise RecordingError(f"{rec.path}: its header says calibration "
                             f"{already.get('path')!r} was applied already; drop "
                             "--calibration")
    cal = Calibration.load(path)
    meta = rec.metadata
    for warning in cal.check_data(meta.get("chip"), meta.get("fs_dps"), meta.get("fs_g"),
                                  rec.temp_c, str(rec.path)):
        log.warning("%s", warning)
    values = cal.apply(rec.batch()).values
    meta = {**rec.metadata, "calibration": cal.describe()}
    return dataclasses.replace(rec, values=values, metadata=meta)
