"""Batch analysis of many recordings (``imubench allan|fit|gap DIR-or-GLOB``).

:mod:`~imubench.batchrun.runner` expands the inputs and runs one task per recording and
channel, in this process or on Dask (``--workers N``: a LocalCluster of N single-threaded
worker processes; ``--scheduler tcp://HOST:PORT``: a running cluster), with progress on
stderr. :mod:`~imubench.batchrun.jobs` turns each command's per-file call into those
tasks and writes one table (CSV and JSON) plus the per-recording reports the command
writes for one file.
"""

from __future__ import annotations

from imubench.batchrun.runner import (
    BatchError,
    Outcome,
    add_batch_options,
    expand_inputs,
    is_batch,
    run_recordings,
)

__all__ = ["BatchError", "Outcome", "add_batch_options", "expand_inputs", "is_batch",
           "run_recordings"]
