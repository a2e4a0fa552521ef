"""The unit of data that flows from a source to the ring buffer and its consumers.

A :class:`Batch` holds consecutive samples of the six inertial channels
(``gx gy gz`` in dps, ``ax ay az`` in g) and the temperature in degC. Every sample
carries its *sample index*: the count of nominal output-data-rate periods since the
start of acquisition. Samples lost on the way (FIFO overrun, dropped frame, chip reset,
a consumer that fell behind) leave a hole in the index sequence, and every hole is
described by one or more typed :class:`Gap` records carried in :attr:`Batch.gaps`:
where it ends, how many samples it holds and why. A hole is never implicit.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from lsm6ds.channels import CHANNELS

UNITS: dict[str, str] = {
    "gx": "dps", "gy": "dps", "gz": "dps", "ax": "g", "ay": "g", "az": "g", "temp": "degC",
}

UNEXPLAINED = "unexplained"
"""Reason given to a hole in the sample index that no source or consumer declared (a
defect: every path declares its losses; tests assert it never appears)."""


@dataclass(frozen=True)
class Gap:
    """``lost`` samples missing just before sample index ``at`` (the index of the first
    sample after the hole, or the end index of a stream that ended in a hole), and why."""

    at: int
    lost: int
    reason: str

    def __post_init__(self) -> None:
        if self.lost <= 0:
            raise ValueError(f"Gap at index {self.at}: lost={self.lost} must be positive")


def true_runs(flags: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) index of each run of consecutive True values of ``flags``."""
    edges = np.diff(np.concatenate(([0], np.asarray(flags).astype(np.int8), [0])))
    return list(zip(np.flatnonzero(edges == 1).tolist(),
                    (np.flatnonzero(edges == -1) - 1).tolist(), strict=True))


def gaps_before(gaps: Sequence[Gap], end: int) -> list[Gap]:
    """The parts of ``gaps``' holes that lie below sample index ``end`` (a stream cut at
    ``end``), each as a gap at ``min(at, end)``.

    Gaps that share ``at`` are adjacent holes, the one listed first the earlier: together
    they are ``[at - sum(lost), at - 1]`` (a recording's segment that starts with a full
    disk's loss and a FIFO overrun before the same sample). Taking each as
    ``[at - lost, at - 1]`` alone dropped the earlier one at a cut. ``gaps`` sorted by
    ``at``."""
    out: list[Gap] = []
    for at, group in itertools.groupby(gaps, key=lambda g: g.at):
        same = list(group)
        start = at - sum(g.lost for g in same)
        for g in same:
            lost = min(start + g.lost, end) - start
            if lost > 0:
                out.append(Gap(min(at, end), lost, g.reason))
            start += g.lost
    return out


def hole_start(gaps: Sequence[Gap]) -> int:
    """The first sample index inside the earliest hole of ``gaps`` (sorted by ``at``)."""
    first = gaps[0].at
    return first - sum(g.lost for g in gaps if g.at == first)


@dataclass(frozen=True)
class Batch:
    """Consecutive samples of one sensor.

    Attributes:
        index: int64 ``(n,)`` sample index (nominal ODR periods since start), increasing.
        t_s: float64 ``(n,)`` timestamp in seconds since the acquisition start.
        values: float64 ``(n, 6)`` scaled values in :data:`CHANNELS` order (dps, g);
            NaN where a channel is absent.
        temp_c: float64 ``(n,)`` temperature in degC, NaN where not measured.
        raw: int16 ``(n, 6)`` raw output counts when the source has them, else None.
        gaps: the holes before and between this batch's samples (sorted by ``at``);
            a batch without samples carries only gaps (a stream that ended in a hole).
    """

    index: np.ndarray
    t_s: np.ndarray
    values: np.ndarray
    temp_c: np.ndarray
    raw: np.ndarray | None = None
    gaps: tuple[Gap, ...] = ()

    def __post_init__(self) -> None:
        n = len(self.index)
        if self.values.shape != (n, len(CHANNELS)):
            raise ValueError(f"Batch.values must have shape ({n}, 6), got {self.values.shape}")
        if len(self.t_s) != n or len(self.temp_c) != n:
            raise ValueError("Batch.t_s and Batch.temp_c must have one entry per sample")
        if self.raw is not None and self.raw.shape != (n, len(CHANNELS)):
            raise ValueError(f"Batch.raw must have shape ({n}, 6), got {self.raw.shape}")
        if n and self.gaps and max(g.at for g in self.gaps) > int(self.index[-1]):
            raise ValueError(
                "Batch.gaps: a gap after the last sample belongs to the next batch "
                "(or to a batch without samples at the end of the stream)"
            )

    def __len__(self) -> int:
        return len(self.index)

    @property
    def lost(self) -> int:
        """Samples lost in this batch's gaps."""
        return sum(g.lost for g in self.gaps)

    def head(self, n: int) -> Batch:
        """The first ``n`` samples, with the gaps that end at or before the last of them."""
        if n >= len(self):
            return self
        last = int(self.index[n - 1]) if n else None
        gaps = tuple(g for g in self.gaps if last is not None and g.at <= last)
        return Batch(self.index[:n], self.t_s[:n], self.values[:n], self.temp_c[:n],
                     None if self.raw is None else self.raw[:n], gaps)

    @staticmethod
    def empty(*, with_raw: bool = False, gaps: Iterable[Gap] = ()) -> Batch:
        """A batch without samples (optionally carrying gaps)."""
        z = np.zeros(0)
        return Batch(np.zeros(0, np.int64), z, np.zeros((0, len(CHANNELS))), z,
                     np.zeros((0, len(CHANNELS)), np.int16) if with_raw else None, tuple(gaps))

    @staticmethod
    def concat(batches: list[Batch]) -> Batch:
        """Join batches in order (their gaps too)."""
        if not batches:
            raise ValueError("Batch.concat needs at least one batch")
        raw = None
        if all(b.raw is not None for b in batches):
            raw = np.concatenate([b.raw for b in batches])
        return Batch(
            index=np.concatenate([b.index for b in batches]),
            t_s=np.concatenate([b.t_s for b in batches]),
            values=np.concatenate([b.values for b in batches]),
            temp_c=np.concatenate([b.temp_c for b in batches]),
            raw=raw,
            gaps=tuple(g for b in batches for g in b.gaps),
        )


def index_holes(index: np.ndarray, last_index: int | None) -> list[tuple[int, int]]:
    """The holes ``[start, end)`` of sample indices before and inside ``index`` (increasing,
    not empty): after ``last_index`` (the previous sample; None: nothing before) and
    between neighbours."""
    first = int(index[0])
    holes: list[tuple[int, int]] = []
    if last_index is not None and first > last_index + 1:
        holes.append((last_index + 1, first))
    for k in np.nonzero(np.diff(index) > 1)[0]:
        holes.append((int(index[k]) + 1, int(index[k + 1])))
    return holes


def explain_holes(batch: Batch, last_index: int | None) -> list[Gap]:
    """Every hole before and inside ``batch`` as gaps with their declared reasons.

    ``last_index`` is the stream's previous sample (None at the start of a stream: the
    declared gaps up to the first sample are then returned as they are, since a stream may
    begin after lost samples). A hole ``[start, end)`` (``end`` the index of the sample
    after it) is explained by the declared gaps with ``start <= at <= end``: a consumer
    that skipped samples learns of the source gaps inside the skipped range, and they are
    moved to ``end``. What no declared gap explains gets :data:`UNEXPLAINED`. A batch
    without samples (the end of a stream) returns its gaps as they are.
    """
    if not len(batch):
        return list(batch.gaps)
    first = int(batch.index[0])
    holes = index_holes(batch.index, last_index)
    declared = sorted(batch.gaps, key=lambda g: g.at)
    out: list[Gap] = []
    j = 0
    if last_index is None:
        while j < len(declared) and declared[j].at <= first:
            out.append(declared[j])
            j += 1
    for start, end in holes:
        while j < len(declared) and declared[j].at < start:
            j += 1  # declared where no hole is: the index is the truth
        left = end - start
        while j < len(declared) and declared[j].at <= end:
            take = min(declared[j].lost, left)
            if take > 0:
                out.append(Gap(end, take, declared[j].reason))
                left -= take
            j += 1
        if left > 0:
            out.append(Gap(end, left, UNEXPLAINED))
    return out


__all__ = [
    "CHANNELS",
    "UNEXPLAINED",
    "UNITS",
    "Batch",
    "Gap",
    "explain_holes",
    "gaps_before",
    "hole_start",
    "index_holes",
]
