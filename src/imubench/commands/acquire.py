"""``imubench acquire SOURCE --duration-s S --out REC [--stats-json PATH]``: one recording.

The source is any registered URI (``sim://``, ``i2c://``, ``sensortile://``, ``replay://``,
...), read through the one acquisition pipeline (:mod:`imubench.pipeline`) into the
recorder (:class:`~imubench.recorder.Recorder`). Every hole in the sample index is written
as an explicit gap with its reason (FIFO overrun, chip reset, ...). The stats JSON holds
the source telemetry (``samples``, ``gaps``, ``lost_samples``, ``overruns``,
``bus_bytes``, ``bus_utilization``, ``io_errors``, ``retries``, ``bad_frames``,
``reconnects``, ``measured_odr_hz`` (the ODR measured against the host clock: a crystal
error shows here), ``elapsed_s``, ``expected_samples``, ``lost_by_reason``) plus
``duration_s`` (source seconds elapsed, at most ``--duration-s``), ``produced`` and what
the recording holds (``recorded``, ``recording_lost``); with ``--calibration``,
``calibration_extrapolated``: the samples whose die temperature lay outside the
calibration's sweep (a warning says when it leaves and re-enters it). Ctrl-C or SIGTERM
stops the acquisition and keeps, closed and readable, everything recorded so far; the
counters of it are still written, with ``"interrupted": true``. A source or a consumer
that fails (a device lost for good, a disk full) ends it the same way: the recording is
closed with what it holds, the summary line and the counters say so (``"error"``: the
failure's message), then the error.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from imubench.calibration import Calibration, recording_header
from imubench.calibration.live import LiveCalibration
from imubench.commands import check_writable, summary_stream, write_json
from imubench.errors import RecordingError, SourceError
from imubench.pipeline import Pipeline
from imubench.progress import progress
from imubench.recorder import NOT_RECORDED, Recorder
from imubench.sources.base import Source
from imubench.sources.registry import open_source, with_default_param

WAIT_SLICE_S = 0.2


def add_duration(uri: str, duration_s: float) -> str:
    """``uri`` with ``duration_s=`` set, for backends that declare it (a finite
    simulated stream knows its length ahead: exact end accounting, flicker noise exact
    over the whole run); other URIs are returned unchanged (the pipeline ends them)."""
    return with_default_param(uri, "duration_s", duration_s)


def record(src: Source, out: Path, duration_s: float | None = None,
           calibration: Calibration | None = None) -> dict[str, Any]:
    """Read ``src`` (to its end, or for ``duration_s``) into the recording ``out``, with
    ``calibration`` applied to the values (raw counts untouched, the header says which);
    return the stats (see the module docstring)."""
    recorder = Recorder(out, {"calibration": recording_header(calibration)})
    live = (None if calibration is None else LiveCalibration(
        calibration, f"source {src.info.uri}", lambda text: print(text, file=sys.stderr)))
    pipeline = Pipeline(src, [recorder], duration_s=duration_s, transform=live)
    pipeline.prepare()
    pipeline.start()
    try:
        with progress(duration_s, f"recording {out.name}", unit="s") as bar:
            while not pipeline.join(WAIT_SLICE_S):
                bar.fraction(pipeline.produced / (pipeline.info.odr_hz * (duration_s or 1)))
    except KeyboardInterrupt:  # Ctrl-C or SIGTERM (imubench.cli raises it for both): keep
        # what was recorded: stop, drain, close the file, and say what it holds
        pipeline.stop()
        pipeline.join()
        stats = _stats(src, pipeline, recorder, live, duration_s)
        stats["interrupted"] = True
        raise AcquisitionInterrupted(stats) from None
    stats = _stats(src, pipeline, recorder, live, duration_s)
    failure = pipeline.error or next(iter(pipeline.consumer_errors().values()), None)
    if failure is None and recorder.not_recorded:  # a full disk: the recorder went on
        # counting what it could not write (exit 0, "56 lost" with no reason, before)
        failure = RecordingError(
            f"{out}: {recorder.not_recorded} samples not recorded ({NOT_RECORDED}; "
            f"the recorder's state at the end: {recorder.state})")
    if failure is not None:
        stats["error"] = str(failure)
        raise AcquisitionError(stats, failure) from failure
    return stats


class AcquisitionError(Exception):
    """The source or a consumer failed: :attr:`error`, with the counters of what the
    (closed) recording holds (:attr:`stats`)."""

    def __init__(self, stats: dict[str, Any], error: BaseException) -> None:
        super().__init__(str(error))
        self.stats = stats
        self.error = error


class AcquisitionInterrupted(KeyboardInterrupt):
    """A stop by Ctrl-C or SIGTERM (a KeyboardInterrupt, as :mod:`imubench.cli` expects),
    with the counters of what was recorded up to it (:attr:`stats`)."""

    def __init__(self, stats: dict[str, Any]) -> None:
        super().__init__()
        self.stats = stats


def _stats(src: Source, pipeline: Pipeline, recorder: Recorder,
           live: LiveCalibration | None, duration_s: float | None) -> dict[str, Any]:
    """The counters of a finished (or stopped) acquisition: the module docstring.
    ``duration_s`` is the source's seconds up to ``duration_s`` (the acquisition's limit):
    a source on a virtual clock polls on past the limit until the pipeline stops it (3 s
    of ``sim://...&clock=virtual`` had said 5.6 s)."""
    tel = src.telemetry()
    stats: dict[str, Any] = tel.as_dict()
    stats["duration_s"] = (tel.elapsed_s if duration_s is None
                           else min(tel.elapsed_s, duration_s))
    stats["produced"] = pipeline.produced
    account = pipeline.accounts()["recorder"]
    stats["recorded"] = recorder.samples
    stats["recording_lost"] = account.lost + recorder.not_recorded
    if live is not None:
        stats["calibration_extrapolated"] = live.samples_extrapolated
        stats["calibration_extrapolated_range_c"] = {
            name: list(r) for name, r in live.extrapolated_range_c.items()}
    return stats


def record_uri(uri: str, out: Path, stats_json: Path | None,
               duration_s: float | None = None,
               calibration: Path | None = None) -> dict[str, Any]:
    """Open the source ``uri``, record it to ``out`` (with the calibration file
    ``calibration`` applied) and write the counters to ``stats_json`` (if given); returns
    the counters (see :func:`record`)."""
    cal = None if calibration is None else Calibration.load(calibration)
    src = open_source(uri)
    if cal is not None:  # another chip or range: refused before anything is recorded
        cal.check_data(src.info.chip, src.info.fs_dps, src.info.fs_g, None, f"source {uri}")
    try:
        stats = record(src, out, duration_s, cal)
    except (AcquisitionInterrupted, AcquisitionError) as stop:  # the counters of what
        # was kept, then the exit
        if stats_json is not None:
            write_json(stop.stats, str(stats_json), "--stats-json")
        raise
    if stats_json is not None:
        write_json(stats, str(stats_json), "--stats-json")
    return stats


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "acquire",
        help="record a source to a file",
        description="Acquire from SOURCE (a URI such as sim://lsm6dsl?odr_hz=104 or "
        "i2c:///dev/i2c-1?chip=lsm6dsl&addr=0x6a) for --duration-s seconds into --out "
        "(.imbr native or .csv). Gaps are recorded explicitly.",
    )
    p.add_argument("source", metavar="SOURCE", help="source URI (README: Sources)")
    p.add_argument("--duration-s", type=float, required=True,
                   help="seconds of data to record (a finite source may end sooner)")
    p.add_argument("--out", type=Path, required=True,
                   help="recording to write: .imbr (native), .csv or .csv.gz")
    p.add_argument("--stats-json", type=Path, default=None,
                   help="write the acquisition counters as JSON here (- for stdout)")
    p.add_argument("--calibration", type=Path, default=None, metavar="FILE",
                   help="calibration file applied to the values (docs/calibration.md); "
                   "raw counts stay in an .imbr recording (a CSV holds the corrected values only)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.duration_s <= 0:
        raise SourceError(f"--duration-s {args.duration_s} must be > 0")
    check_writable(args.stats_json, "--stats-json")  # before the acquisition, not after
    uri = add_duration(args.source, args.duration_s)
    try:
        stats = record_uri(uri, args.out, args.stats_json, args.duration_s, args.calibration)
    except AcquisitionError as failed:  # what the closed recording holds, then the error
        print(_summary(args.out, failed.stats) + " (up to the failure below)",
              file=summary_stream(args.stats_json))
        raise _as_written(failed.error, uri, args.source) from None
    except SourceError as exc:
        raise _as_written(exc, uri, args.source) from None
    print(_summary(args.out, stats), file=summary_stream(args.stats_json))
    return 0


def _summary(out: Path, stats: dict[str, Any]) -> str:
    """The file's own counts first (the source may have read past the duration, which the
    pipeline does not deliver), then the source's."""
    return (f"{out}: {stats['recorded']} samples recorded, {stats['recording_lost']} lost; "
            f"source: {stats['samples']} read, {stats['gaps']} gaps, "
            f"{stats['lost_samples']} lost, {stats['overruns']} overruns, "
            f"{stats['io_errors']} I/O errors")


def _as_written(error: BaseException, uri: str, written: str) -> BaseException:
    """``error``, a source error naming the URI the user wrote (not the one with
    ``duration_s`` added)."""
    if isinstance(error, SourceError):
        return SourceError(str(error).replace(uri, written))
    return error
