"""Run one task per recording and channel, sequentially or on Dask, with progress.

Each recording is first *planned* (a task that lists the channels to analyse, reading the
file), then one *work* task per channel runs the command's per-file analysis restricted to
that channel. Both are plain functions of (path, name) and (path, name, channel): ``path``
is absolute (a worker of an external cluster runs elsewhere, with shared storage), ``name``
is the recording as the user named it (what the reports say). The sequential run and the
Dask run execute the same code on the same inputs and give identical results.
Errors of the imubench family (a damaged recording, a channel without data) are kept per
task and reported; any other exception is a bug and propagates.
"""

from __future__ import annotations

import argparse
import glob
import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from imubench.errors import USER_ERRORS, ImubenchError
from imubench.progress import progress
from imubench.recording import segment_path
from imubench.recording.rosin import is_ros2_bag

RECORDING_SUFFIXES: tuple[str, ...] = (".imbr", ".csv", ".csv.gz", ".mcap", ".h5", ".hdf5")
"""What a directory or glob of recordings picks up (besides ROS 2 bag folders); other
text tables (``.txt``, ``.dat``) are read one at a time, as a folder may hold notes."""
_GLOB_CHARS = set("*?[")


LOCAL_WORKER_CONFIG: dict[str, object] = {
    "distributed.worker.profile.enabled": False,
    "distributed.worker.memory.monitor-interval": "1s",
    "distributed.admin.system-monitor.interval": "2s",
}
"""Dask settings of the ``--workers`` LocalCluster (a running cluster keeps its own)."""


class BatchError(ImubenchError):
    """Batch inputs, options or the Dask cluster are not usable."""


def add_batch_options(p: argparse.ArgumentParser) -> None:
    """``--workers``, ``--scheduler``, ``--out-dir`` for a command taking a recording."""
    g = p.add_argument_group("many recordings (INPUT is a directory or a quoted glob)")
    g.add_argument("--workers", type=int, default=None, metavar="N",
                   help="run on a Dask LocalCluster of N worker processes")
    g.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                   help="run on the running Dask cluster of this scheduler")
    g.add_argument("--out-dir", type=Path, default=None, metavar="DIR",
                   help="where the table (CSV and JSON) and the per-recording reports go")


def has_glob(text: str) -> bool:
    """Whether INPUT is a glob: it holds a glob character and is not itself an existing
    file or folder (``run_[1].csv`` is that file, not a pattern matching ``run_1.csv``)."""
    return any(c in _GLOB_CHARS for c in text) and not Path(text).exists()


def is_batch(spec: Path, args: argparse.Namespace) -> bool:
    """True when INPUT is a directory or a glob, or a cluster or ``--out-dir`` was asked
    for (one recording then runs as a batch of one)."""
    text = str(spec)
    folder = Path(text).is_dir() and not is_ros2_bag(Path(text))
    return (has_glob(text) or folder or args.workers is not None
            or args.scheduler is not None or args.out_dir is not None)


def _is_recording(path: Path) -> bool:
    return path.name.lower().endswith(RECORDING_SUFFIXES)


def expand_inputs(spec: str | Path) -> list[Path]:
    """The recordings named by a file, a directory (its :data:`RECORDING_SUFFIXES` files
    and ROS 2 bag folders) or a glob (``**`` recurses), sorted.
    BatchError when there are none, a glob matches something else, or two would write
    reports of the same name."""
    text = str(spec)
    if has_glob(text):
        paths = sorted(Path(p) for p in glob.glob(text, recursive=True) if Path(p).is_file())
        other = [p for p in paths if not _is_recording(p)]
        if other:
            raise BatchError(f"{text}: {other[0]} is not a recording; recordings end in "
                             + ", ".join(RECORDING_SUFFIXES))
    elif Path(text).is_dir():
        paths = sorted(p for p in Path(text).iterdir()
                       if (p.is_file() and _is_recording(p)) or is_ros2_bag(p))
    else:
        paths = [Path(text)]
    # a later segment is read with its first (imubench.recording, "Segments"): analysed
    # again on its own it made a second report of the same samples
    later = set()
    for p in paths:
        k = 2
        while (seg := segment_path(p, k)).exists():
            later.add(seg)
            k += 1
    paths = [p for p in paths if p not in later]
    if not paths:
        raise BatchError(f"{text}: no recordings ({', '.join(RECORDING_SUFFIXES)}) found")
    names: dict[str, Path] = {}
    for p in paths:
        other_path = names.setdefault(report_stem(p), p)
        if other_path != p:
            raise BatchError(f"{other_path} and {p} would write reports of the same name "
                             f"{report_stem(p)!r}; analyse them in separate runs")
    return paths


def report_stem(path: Path) -> str:
    """The recording's file name without its recording suffix: reports are named by it."""
    name = path.name
    for suffix in sorted(RECORDING_SUFFIXES, key=len, reverse=True):
        if name.lower().endswith(suffix):
            return name[: -len(suffix)]
    return path.stem


@dataclass
class Outcome:
    """What came of one recording: its channels, each channel's result, and errors
    (key ``""`` for the planning step, else the channel)."""

    recording: Path
    channels: list[str] = field(default_factory=list)
    results: dict[str, Any] = field(default_factory=dict)
    errors: dict[str, str] = field(default_factory=dict)

    @property
    def complete(self) -> bool:
        return not self.errors and set(self.results) == set(self.channels)

    def planned(self, ok: bool, value: Any) -> list[str]:
        """Take the planning task's (ok, channels or error); the channels to run."""
        if not ok:
            self.errors[""] = value
            return []
        self.channels = list(value)
        return self.channels

    def worked(self, channel: str, ok: bool, value: Any) -> None:
        """Take one channel task's (ok, result or error)."""
        (self.results if ok else self.errors)[channel] = value


class Progress:
    """Recordings finished, on the command line's progress bar (:mod:`imubench.progress`:
    on stderr, shown on a terminal or with ``--progress on``)."""

    def __init__(self, label: str, recordings: int) -> None:
        self._bar = progress(recordings, label, unit="recording")

    def task_done(self, outcome: Outcome) -> None:
        """Called after each task of ``outcome``; counts the recording at its last one."""
        if set(outcome.results) | set(outcome.errors) >= set(outcome.channels):
            self._bar.update(1)

    def close(self) -> None:
        self._bar.close()


def _capture(fn: Callable[..., Any], *args: Any) -> tuple[bool, Any]:
    try:
        return True, fn(*args)
    except USER_ERRORS as exc:
        return False, str(exc)


Plan = Callable[[Path, str], list[str]]
Work = Callable[[Path, str, str], Any]


def _run_sequential(recordings: list[Path], plan: Plan, work: Work,
                    tracker: Progress) -> list[Outcome]:
    outcomes = []
    for path in recordings:
        out = Outcome(path)
        outcomes.append(out)
        chans = out.planned(*_capture(plan, path.resolve(), str(path)))
        if not chans:
            tracker.task_done(out)
        for ch in chans:
            out.worked(ch, *_capture(work, path.resolve(), str(path), ch))
            tracker.task_done(out)
    return outcomes


def _client(workers: int | None, scheduler: str | None) -> tuple[Any, Any]:
    """(distributed.Client, LocalCluster or None)."""
    import dask
    from distributed import Client, LocalCluster

    if logging.getLogger().getEffectiveLevel() > logging.INFO:  # imubench -v shows them
        logging.getLogger("distributed").setLevel(logging.ERROR)
    if scheduler is not None:
        try:
            return Client(scheduler, timeout="10s"), None
        except (OSError, TimeoutError) as exc:
            raise BatchError(f"--scheduler {scheduler}: cannot reach the Dask scheduler "
                             f"({exc})") from None
    assert workers is not None
    # Everything on loopback, the scheduler's status page included (on a free port). The
    # workers' statistical profiler (a stack sample every 10 ms) and their frequent
    # memory and system polls cost CPU the analysis needs on a small machine: off / slower.
    with dask.config.set(LOCAL_WORKER_CONFIG):
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               host="127.0.0.1", dashboard_address="127.0.0.1:0",
                               silence_logs=logging.WARNING)
    return Client(cluster), cluster


def _run_dask(recordings: list[Path], plan: Plan, work: Work, tracker: Progress,
              workers: int | None, scheduler: str | None) -> list[Outcome]:
    from distributed import as_completed

    client, cluster = _client(workers, scheduler)
    try:
        outcomes = [Outcome(p) for p in recordings]
        where: dict[Any, tuple[int, str | None]] = {}
        # plans first, in order; each recording's channel tasks follow as its plan returns
        plans = []
        for i, p in enumerate(recordings):
            f = client.submit(_capture, plan, p.resolve(), str(p), pure=False)
            where[f] = (i, None)
            plans.append(f)
        pending = as_completed(plans)
        for fut in pending:
            i, ch = where.pop(fut)
            out = outcomes[i]
            if ch is not None:
                out.worked(ch, *fut.result())
                tracker.task_done(out)
                continue
            chans = out.planned(*fut.result())
            if not chans:
                tracker.task_done(out)
            for c in chans:
                g = client.submit(_capture, work, out.recording.resolve(),
                                  str(out.recording), c, pure=False)
                where[g] = (i, c)
                pending.add(g)
        return outcomes
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def run_recordings(recordings: list[Path], plan: Plan, work: Work, *,
                   workers: int | None = None,
                   scheduler: str | None = None, label: str = "batch") -> list[Outcome]:
    """Plan every recording (``plan(path, name)``: its channels), run
    ``work(path, name, channel)`` for each planned channel, and return one
    :class:`Outcome` per recording in input order (module docstring).

    ``plan`` and ``work`` must be picklable (module-level functions or
    ``functools.partial`` of them) for Dask. ``workers``/``scheduler`` pick the Dask
    cluster; neither runs everything in this process, one task after another.
    """
    if workers is not None and scheduler is not None:
        raise BatchError("give --workers (a local cluster) or --scheduler (a running one), "
                         "not both")
    if workers is not None and workers < 1:
        raise BatchError(f"--workers {workers}: use 1 or more")
    tracker = Progress(label, len(recordings))
    try:
        if workers is None and scheduler is None:
            return _run_sequential(recordings, plan, work, tracker)
        return _run_dask(recordings, plan, work, tracker, workers, scheduler)
    finally:
        tracker.close()


__all__ = ["RECORDING_SUFFIXES", "BatchError", "Outcome", "Plan", "Progress", "Work",
           "add_batch_options", "expand_inputs", "has_glob", "is_batch", "report_stem",
           "run_recordings"]
