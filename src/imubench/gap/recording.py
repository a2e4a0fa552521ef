"""Recordings in, JSON structure out: channel selection, temperature column, replicates."""

from __future__ import annotations

import multiprocessing
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any

import numpy as np
from lsm6ds_sim.model import NoiseModel

from imubench.gap.diagnose import (
    EFFECTS,
    ChannelDiagnosis,
    GapOptions,
    Series,
    diagnose_channel,
)
from imubench.gap.errors import GapError
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
    return list(wanted)


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
    out: dict[str, Any] = {"schema": SCHEMA, "recording": str(rec.path),
                           "model": model.source, "rate_hz": rec.rate_hz,
                           "samples": len(rec.channel(chans[0])) if chans else 0,
                           "holdout_fraction": opt.holdout_fraction,
                           "realisations": opt.realisations, "seed": opt.seed,
                           "effects_tested": [e for e in EFFECTS if e in opt.effects],
                           "channels": {}}
    work = {ch: (model, ch, series_of(rec, ch), opt, [series_of(r, ch) for r in replicates],
                 limits) for ch in chans}
    done: dict[str, tuple[ChannelDiagnosis, dict[str, Any] | None]] = {}
    if jobs > 1 and len(chans) > 1:
        with ProcessPoolExecutor(max_workers=min(jobs, len(chans)),
                                 mp_context=multiprocessing.get_context("spawn")) as pool:
            futures = {pool.submit(_channel, *args): ch for ch, args in work.items()}
            try:
                for fut in as_completed(futures):
                    done[futures[fut]] = fut.result()
                    if progress is not None:
                        progress(futures[fut])
            except BaseException:  # an error or Ctrl-C: start no further channel
                for fut in futures:
                    fut.cancel()
                raise
    else:
        for ch, args in work.items():
            done[ch] = _channel(*args)
            if progress is not None:
                progress(ch)
    diags: dict[str, ChannelDiagnosis] = {}
    for ch in chans:
        d, lim = done[ch]
        diags[ch] = d
        out["channels"][ch] = d.to_dict()
        if lim is not None:
            out["channels"][ch]["limits"] = lim
    return _clean(out), diags


def _channel(model: NoiseModel, channel: str, series: Series, opt: GapOptions,
             reps: list[Series], limits: bool
             ) -> tuple[ChannelDiagnosis, dict[str, Any] | None]:
    """One channel's diagnosis and, when asked, its detection limits."""
    d = diagnose_channel(model, channel, series, opt, reps)
    if not limits:
        return d, None
    from imubench.gap.limits import detection_limits

    return d, detection_limits(model, channel, series, opt)


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
