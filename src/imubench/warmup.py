"""Compile and cache the numba kernels once, so a daemon's first start is not a cold compile.

``python -m imubench.warmup`` (run by ``python3 dev.py setup`` and, for a service, as its
user with the service's ``NUMBA_CACHE_DIR``; docs/service.md) runs the streaming engine's
warm-up (:func:`imubench.stats.streaming.warm_up`: both input kinds, both memory modes,
every streaming statistic) and every batch statistic on tiny phase and frequency data,
with and without gaps (what ``fit``, ``allan``, ``report`` and ``gap`` run), and the
gap's two-level likelihood ratio. numba writes
the compiled code to its cache: ``NUMBA_CACHE_DIR`` when set, else ``__pycache__`` beside
the modules; later processes load it instead of compiling.
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np


def warm_numba_cache() -> float:
    """Run every kernel once on tiny inputs; returns the seconds it took."""
    from imubench.gap.two_level import two_level_llr
    from imubench.stats import STATISTICS, compute
    from imubench.stats.streaming import warm_up

    t0 = time.perf_counter()
    warm_up()
    rng = np.random.default_rng(0)
    y = rng.standard_normal(600)
    y_gaps = y.copy()
    y_gaps[50:53] = np.nan
    for stat in STATISTICS:
        for series in (y, y_gaps):
            compute(stat, series, 10.0, "freq", "octave")
        compute(stat, np.cumsum(y), 10.0, "phase", "octave")
    two_level_llr(y_gaps, 10.0, 1.0, 5.0, 20.0)  # gap: telegraph against Markov
    return time.perf_counter() - t0


def main() -> int:
    where = os.environ.get("NUMBA_CACHE_DIR") or "__pycache__ beside the modules"
    print(f"imubench: compiling the numba kernels into the cache ({where}) ...", flush=True)
    print(f"imubench: kernels ready in {warm_numba_cache():.1f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
