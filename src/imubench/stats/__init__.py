"""Batch Allan-family statistics (NIST SP 1065 / Stable32 conventions).

Every function has the signature ``name(data, rate=1.0, data_type="phase",
taus="octave", *, confidence=0.683, alpha=None, bias_correction=True,
remove_drift=False, max_af=None, afs=None, progress=None) -> StatResult``; the variance
forms (``avar``, ``oavar``, ...) return the very same :class:`StatResult` (it holds both
the variance and the deviation). See ``docs/statistics.md``.
"""

from __future__ import annotations

from functools import partial
from typing import Any

from imubench.stats.api import DEV_NAME, VAR_NAME, compute
from imubench.stats.result import StatResult
from imubench.stats.streaming import StreamingAllan

STATISTICS: tuple[str, ...] = tuple(VAR_NAME)


def _make(stat: str) -> Any:
    fn = partial(compute, stat)
    fn.__doc__ = f"{stat}: see imubench.stats.api.compute (variance name {VAR_NAME[stat]})."
    return fn


adev = avar = _make("adev")
oadev = oavar = _make("oadev")
mdev = mvar = _make("mdev")
tdev = tvar = _make("tdev")
hdev = hvar = _make("hdev")
ohdev = ohvar = _make("ohdev")
totdev = totvar = _make("totdev")
mtotdev = mtotvar = _make("mtotdev")
ttotdev = ttotvar = _make("ttotdev")
htotdev = htotvar = _make("htotdev")
theo1 = theo1var = _make("theo1")
theobr = theobrvar = _make("theobr")
theoh = theohvar = _make("theoh")
stdev = stdvar = _make("stdev")
ostdev = ostdvar = _make("ostdev")

__all__ = [
    "DEV_NAME",
    "STATISTICS",
    "VAR_NAME",
    "StatResult",
    "StreamingAllan",
    "adev",
    "avar",
    "compute",
    "hdev",
    "htotdev",
    "htotvar",
    "hvar",
    "mdev",
    "mtotdev",
    "mtotvar",
    "mvar",
    "oadev",
    "oavar",
    "ohdev",
    "ohvar",
    "ostdev",
    "ostdvar",
    "stdev",
    "stdvar",
    "tdev",
    "theo1",
    "theo1var",
    "theobr",
    "theobrvar",
    "theoh",
    "theohvar",
    "totdev",
    "totvar",
    "ttotdev",
    "ttotvar",
    "tvar",
]
