"""Recordings in, JSON structure out: channel selection, temperature column, replicates."""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from lsm6ds_sim.model import NoiseModel

from imubench.gap.candidates import EFFECTS
from imubench.gap.diagnose import diagnose_channel
from imubench.gap.errors import GapError
from imubench.gap.parts import Series
from imubench.gap.result import ChannelDiagnosis, GapOptions
from imubench.recording import Recording

SCHEMA = "imubench.gap/1"


def series_of(rec: Recording, channel: str) -> Series:
    """One channel of a recording as a :class:`Series` (temperature when measured)."""
    chans = [c for c in rec.channels if c != "temp"]
    if channel not in chans:
        raise GapError(f"{rec.path}: no channel {channel!r}; channels are {', '.join(chans)}")
    temp = rec.channel("temp") if "temp" in rec.channels else None
    return Series(rec.channel(channel), temp, rec.rate_hz, str(rec.path))


def pick_channels(rec: Recording, wanted: Sequence[str] | None) -> list[str]:
    chans = [c for c in rec.channels if c != "temp"]
    if not wanted:
        return chans
    for c in wanted:
        if c not in chans:
            raise GapError(
                f"--channels: {rec.path} has no channel {c!r}; channels are {', '.join(chans)}"
            )
    twice = sorted({c for c in wanted if list(wanted).count(c) > 1})
    if twice:
        raise GapError(f"--channels: {', '.join(twice)} given more than once")
    return list(wanted)


PARALLEL_MIN_SAMPLES = 2**18
"""Samples per channel from which ``imubench gap`` diagnoses the channels in parallel by
default (:func:`default_jobs`): ~42 min at 104 Hz."""


def default_jobs(rec: Recording, limits: bool = False) -> int:
    """``imubench gap``'s default ``--jobs``: one process per CPU this process may use for
    a recording of at least PARALLEL_MIN_SAMPLES samples per channel or with ``limits``
    (minutes per channel), else 1. A spawned worker spends ~2 s importing; measured on
    2 cores, 6 channels: 15 min at 104 Hz 5.4 s in this process and 6.7 s with two
    workers; 1 h 20.0 s and 15.5-17 s; 1 h with two effects kept on every channel
    118.5 s and 75.4 s."""
    if len(rec.index) < PARALLEL_MIN_SAMPLES and not limits:
        return 1
    return len(os.sched_getaffinity(0))


def diagnose_recording(
    rec: Recording,
    model: NoiseModel,
    channels: Sequence[str] | None = None,
    options: GapOptions | None = None,
    replicates: Sequence[Recording] = (),
    effects_requested: bool = False,
    progress: Callable[[str], None] | None = None,
    limits: bool = False,
    jobs: int = 1,
) -> tuple[dict[str, Any], dict[str, ChannelDiagnosis]]:
    """(JSON structure, per-channel diagnoses) for the channels of ``rec``.

    ``limits``: also measure the detection limits on this recording
    (:func:`imubench.gap.limits.detection_limits`, ``limits`` in each channel's entry).

    ``jobs``: channels diagnosed at once, each in its own process (spawned, so no state
    of this one is shared). The channels are independent and every channel's
    realisations are seeded from ``options.seed`` alone, so the result is the same for
    any ``jobs``. ``progress`` is called with each channel as it finishes.

    ``effects_requested``: the caller named the effects explicitly, so ``temperature``
    without a temperature column is an error instead of a skipped candidate.
    """
    opt = options or GapOptions()
    chans = pick_channels(rec, channels)
    for r in (rec, *replicates):
        if "temperature" in opt.effects and effects_requested and "temp" not in r.channels:
            raise GapError(
                f"{r.path}: the effect 'temperature' was requested but the recording has no "
                "'temp' column (a CSV needs a 'temp' header field); drop it from --effects"
            )
        if abs(r.rate_hz - rec.rate_hz) > 1e-9 * rec.rate_hz:
            raise GapError(
                f"{r.path}: rate {r.rate_hz:g} Hz differs from {rec.path}'s {rec.rate_hz:g} Hz"
            )
    untested = ({"temperature": f"{rec.path} has no temperature column"}
                if "temperature" in opt.effects and "temp" not in rec.channels else {})
    out: dict[str, Any] = {"schema": SCHEMA, "recording": str(rec.path),
                           "model": model.source, "rate_hz": rec.rate_hz,
                           "samples": len(rec.channel(chans[0])) if chans else 0,
                           "lost_samples": rec.lost_samples, "holes": rec.holes,
                           "holdout_fraction": opt.holdout_fraction,
                           "realisations": opt.realisations, "seed": opt.seed,
                           "effects_tested": [e for e in EFFECTS if e in opt.effects
                                              and e not in untested],
                           "effects_untested": untested,
                           "channels": {}}
    work: list[Job] = [(model, ch, series_of(rec, ch), opt,
                        [series_of(r, ch) for r in replicates], limits) for ch in chans]
    done: dict[str, tuple[ChannelDiagnosis, dict[str, Any] | None]] = {}
    # a Pool, not a ProcessPoolExecutor: leaving the block (an error in a channel, Ctrl-C)
    # terminates the workers at once instead of finishing the queued channels
    parallel = jobs > 1 and len(chans) > 1
    with (multiprocessing.get_context("spawn").Pool(
            min(jobs, len(chans)), initializer=_leave_ctrl_c_to_the_parent) if parallel
          else contextlib.nullcontext()) as pool:
        results = pool.imap_unordered(_channel_job, work) if pool else map(_channel_job, work)
        for ch, result in results:
            done[ch] = result
            if progress is not None:
                progress(ch)
    diags: dict[str, ChannelDiagnosis] = {}
    for ch in chans:
        d, lim = done[ch]
        diags[ch] = d
        lost, runs = rec.channel_lost(ch)
        out["channels"][ch] = {**d.to_dict(), "lost_samples": lost, "holes": runs}
        if lim is not None:
            out["channels"][ch]["limits"] = lim
    return _clean(out), diags


def _leave_ctrl_c_to_the_parent() -> None:
    """A worker ignores SIGINT: Ctrl-C (sent to the whole process group) is the parent's
    to handle, which terminates the workers, without a traceback from each."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


Job = tuple[NoiseModel, str, Series, GapOptions, list[Series], bool]
"""One channel's work: model, channel, series, options, replicates' series, limits?"""


def _channel_job(job: Job) -> tuple[str, tuple[ChannelDiagnosis, dict[str, Any] | None]]:
    """(channel, (its diagnosis, its detection limits when asked))."""
    model, channel, series, opt, reps, limits = job
    d = diagnose_channel(model, channel, series, opt, reps)
    if not limits:
        return channel, (d, None)
    from imubench.gap.limits import detection_limits

    return channel, (d, detection_limits(model, channel, series, opt))


def _clean(obj: Any) -> Any:
    """JSON-safe: numpy scalars to Python, non-finite floats to None."""
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_clean(v) for v in obj]
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, float | np.floating):
        f = float(obj)
        return f if np.isfinite(f) else None
    if isinstance(obj, Path):
        return str(obj)
    return obj
