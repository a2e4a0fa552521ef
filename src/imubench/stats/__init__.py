"""Batch Allan-family statistics (NIST SP 1065 / Stable32 conventions).

Every function has the signature ``name(data, rate=1.0, data_type="phase",
taus="octave", *, confidence=0.683, alpha=None, bias_correction=True,
remove_drift=False, max_af=None, afs=None, progress=None) -> StatResult``; the variance
forms (``avar``, ``oavar``, ...) return the very same :class:`StatResult` (it holds both
the variance and the deviation). See ``docs/statistics.md``.
"""

from __future__ import annotations

from typing import Any

# The names below are resolved on first use (PEP 562), so that importing one submodule
# (``imubench.stats.taus``, the streaming engine) does not load the batch machinery and
# scipy; ``from imubench.stats import oadev`` works as before.
_STATS = ("adev", "oadev", "mdev", "tdev", "hdev", "ohdev", "totdev", "mtotdev", "ttotdev",
          "htotdev", "theo1", "theobr", "theoh", "stdev", "ostdev")
_VARS = {"adev": "avar", "oadev": "oavar", "mdev": "mvar", "tdev": "tvar", "hdev": "hvar",
         "ohdev": "ohvar", "totdev": "totvar", "mtotdev": "mtotvar", "ttotdev": "ttotvar",
         "htotdev": "htotvar", "theo1": "theo1var", "theobr": "theobrvar",
         "theoh": "theohvar", "stdev": "stdvar", "ostdev": "ostdvar"}


def _make(stat: str) -> Any:
    from functools import partial

    from imubench.stats.api import VAR_NAME, compute

    fn = partial(compute, stat)
    fn.__doc__ = f"{stat}: see imubench.stats.api.compute (variance name {VAR_NAME[stat]})."
    return fn


def __getattr__(name: str) -> Any:
    if name in ("DEV_NAME", "VAR_NAME", "compute"):
        from imubench.stats import api

        return getattr(api, name)
    if name == "STATISTICS":
        from imubench.stats.api import VAR_NAME

        return tuple(VAR_NAME)
    if name == "StatResult":
        from imubench.stats.result import StatResult

        return StatResult
    if name == "StreamingAllan":
        from imubench.stats.streaming import StreamingAllan

        return StreamingAllan
    stat = name if name in _STATS else next((s for s, v in _VARS.items() if v == name), None)
    if stat is not None:
        fn = _make(stat)
        globals()[name] = fn
        return fn
    raise AttributeError(f"module 'imubench.stats' has no attribute {name!r}")


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
