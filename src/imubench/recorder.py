"""The recording consumer: every sample and gap of a stream into a crash-safe file.

A :class:`Recorder` writes a native ``.imbr`` or CSV recording (by suffix) through
:func:`imubench.recording.open_writer`: samples, and each hole as gap records with the
reasons the pipeline explained (FIFO overrun, chip reset, ``consumer overrun: recorder``
when the disk was too slow, ...).

Disk full (or any other write error: a quota, an I/O error): the recorder stops writing
cleanly (the file keeps every whole batch written before and ends there: the writer cuts
off the batch that failed, :mod:`imubench.recording.commit`), reports the state
(:attr:`Recorder.state`, the ``on_state`` callback: the daemon raises it on the retained
MQTT status), keeps taking the stream's samples and counting them as ``not recorded``,
and every ``retry_s`` tries to open the next *segment*: ``NAME.part2.imbr``,
``NAME.part3.imbr``, ... (same header, plus ``segment`` and ``previous_segment``). The
new segment starts with gap records that say exactly what is missing and why (``disk
full: not recorded`` for the samples taken while the disk was full, the stream's own
gaps of that time with their reasons).
"""

from __future__ import annotations

import contextlib
import errno
import logging
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from imubench.batch import Batch, Gap
from imubench.errors import RecordingError
from imubench.pipeline import Consumer
from imubench.recording import (
    STORAGE_FLOAT,
    STORAGE_RAW,
    Writer,
    open_writer,
    recording_kind,
    segment_path,
)
from imubench.sources.base import SourceInfo

log = logging.getLogger(__name__)

NOT_RECORDED = "disk full: not recorded"
"""Gap reason of the samples taken while no segment could be written."""
LIVE_KINDS = ("native", "csv")
"""Recording kinds a live acquisition writes: crash-safe, batch by batch (an HDF5 file
cut by a crash is refused whole, so HDF5 is for ``convert`` only)."""


class Recorder(Consumer):
    """Writes every sample and gap of the stream (see the module docstring).

    Args:
        path: the recording's path (``.imbr``, ``.csv`` or ``.csv.gz``).
        metadata: header fields besides what the source's info gives (configuration,
            station, sensor); no secrets.
        fsync_interval_s: flush and fsync at least this often (native format).
        retry_s: seconds between attempts to open a new segment after a write error.
        on_state: called (from the recorder's thread) with :attr:`state` when it changes.
    """

    name = "recorder"
    drains_at_stop = True

    def __init__(self, path: Path, metadata: dict[str, Any], *, fsync_interval_s: float = 1.0,
                 retry_s: float = 5.0,
                 on_state: Callable[[str], None] | None = None,
                 make_dirs: bool = False) -> None:
        if recording_kind(path) not in LIVE_KINDS:
            raise RecordingError(
                f"{path}: a live recording must be .imbr, .csv or .csv.gz (written batch by "
                "batch, readable after a crash); record to .imbr and `imubench convert` it")
        self.path = Path(path)
        self.extra = dict(metadata)
        self.fsync_interval_s = fsync_interval_s
        self.retry_s = retry_s
        self.on_state = on_state
        self.make_dirs = make_dirs
        """Create the directory of the recording (the daemon's ``log.path``); without it a
        missing directory is an error (``acquire``'s OUT given on the command line)."""
        self.state = "starting"
        self.segments: list[Path] = []
        self.samples = 0
        """Samples written (all segments)."""
        self.not_recorded = 0
        """Samples taken while no segment could be written."""
        self.gap_records = 0
        """Gap records written (all segments)."""
        self._writer: Writer | None = None
        self._meta: dict[str, Any] = {}
        self._outage: dict[str, int] = {}  # reason -> samples missing from the files
        self._next_try = 0.0
        self._error: str | None = None

    # -- metadata ---------------------------------------------------------------------
    def _metadata(self, info: SourceInfo) -> dict[str, Any]:
        meta = {
            "chip": info.chip, "odr_hz": info.odr_hz, "fs_dps": info.fs_dps, "fs_g": info.fs_g,
            "gyro_sensitivity_dps": info.gyro_sensitivity_dps,
            "accel_sensitivity_g": info.accel_sensitivity_g,
            "source_uri": info.uri, "source_config": info.config,
            "storage": STORAGE_RAW if info.has_raw else STORAGE_FLOAT,
        }
        meta.update(self.extra)
        return meta

    def _set_state(self, state: str) -> None:
        if state != self.state:
            self.state = state
            if self.on_state is not None:
                self.on_state(state)

    # -- Consumer -----------------------------------------------------------------------
    def prepare(self, info: SourceInfo) -> None:
        """Open the first segment; an error here (permissions, exists) stops the start."""
        self._meta = self._metadata(info)
        self._writer = self._open(1)
        self._set_state("recording")

    def _open(self, segment: int) -> Writer:
        path = segment_path(self.path, segment)
        meta = dict(self._meta)
        if segment > 1:
            meta["segment"] = segment
            meta["previous_segment"] = str(self.segments[-1]) if self.segments else None
        try:
            if self.make_dirs:
                path.parent.mkdir(parents=True, exist_ok=True)
            elif segment > 1 and not path.parent.is_dir():  # gone while recording: retry
                raise FileNotFoundError(errno.ENOENT, "no such directory", str(path.parent))
            writer = open_writer(path, meta, fsync_interval_s=self.fsync_interval_s)
        except OSError:
            with contextlib.suppress(OSError):  # a header cut by a full disk is no file
                if path.exists():
                    path.unlink()
            raise
        self.segments.append(path)
        log.info("recording to %s", path)
        return writer

    def consume(self, batch: Batch) -> None:
        if self._writer is None:
            self._retry(batch)
            return
        try:
            self._writer.write(batch)
            self.samples += len(batch)
        except OSError as exc:
            self._fail(exc, batch)

    def _close_writer(self) -> None:
        writer, self._writer = self._writer, None
        if writer is None:
            return
        try:
            writer.close()
        finally:
            self.gap_records += writer.gaps

    def _fail(self, exc: OSError, batch: Batch) -> None:
        what = "disk full" if exc.errno in (errno.ENOSPC, errno.EDQUOT) else "write error"
        self._error = f"{what}: {exc}"
        log.error("recording %s: %s; still acquiring, retrying every %g s",
                  self.segments[-1] if self.segments else self.path, self._error,
                  self.retry_s)
        with contextlib.suppress(OSError):
            self._close_writer()
        self._outage = {}
        self._next_try = time.monotonic() + self.retry_s
        self._set_state(f"not recording: {self._error}")
        self._count_outage(batch)

    def _count_outage(self, batch: Batch) -> None:
        self.not_recorded += len(batch)
        if len(batch):
            self._outage[NOT_RECORDED] = self._outage.get(NOT_RECORDED, 0) + len(batch)
        for g in batch.gaps:
            self._outage[g.reason] = self._outage.get(g.reason, 0) + g.lost

    def _retry(self, batch: Batch) -> None:
        if time.monotonic() < self._next_try or not len(batch):
            self._count_outage(batch)
            return
        try:
            writer = self._open(len(self.segments) + 1)
        except OSError as exc:
            log.debug("new segment not possible yet: %s", exc)
            self._next_try = time.monotonic() + self.retry_s
            self._count_outage(batch)
            return
        first = int(batch.index[0])
        missing = tuple(Gap(first, lost, reason) for reason, lost in self._outage.items())
        resumed = Batch(batch.index, batch.t_s, batch.values, batch.temp_c, batch.raw,
                        missing + batch.gaps)
        self._writer = writer
        self._outage = {}
        log.warning("recording resumed in %s", self.segments[-1])
        self._set_state("recording")
        self.consume(resumed)

    def idle(self) -> None:
        """Nothing new: a pending segment retry waits for the next batch (its gaps need
        the next sample index)."""

    def finish(self) -> None:
        try:
            self._close_writer()
        except OSError as exc:
            log.error("closing %s: %s", self.segments[-1], exc)
        if self.state == "recording":
            self._set_state("closed")
