"""The unit of data that flows from a source to the ring buffer and its consumers.

A :class:`Batch` holds consecutive samples of the six inertial channels
(``gx gy gz`` in dps, ``ax ay az`` in g) and the temperature in degC. Every sample
carries its *sample index*: the count of nominal output-data-rate periods since the
start of acquisition. Samples lost by the source (FIFO overrun, dropped frame, I/O
error) leave a hole in the index sequence; a gap is therefore never implicit: it is
the difference between consecutive indices, and sources additionally report it in
:attr:`Batch.lost_before` for the hole just before the batch's first sample.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from lsm6ds.channels import CHANNELS

UNITS: dict[str, str] = {
    "gx": "dps", "gy": "dps", "gz": "dps", "ax": "g", "ay": "g", "az": "g", "temp": "degC",
}


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
        lost_before: samples lost immediately before ``index[0]`` (also visible as the
            jump from the previous batch's last index).
    """

    index: np.ndarray
    t_s: np.ndarray
    values: np.ndarray
    temp_c: np.ndarray
    raw: np.ndarray | None = None
    lost_before: int = 0
    meta: dict[str, object] = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = len(self.index)
        if self.values.shape != (n, len(CHANNELS)):
            raise ValueError(f"Batch.values must have shape ({n}, 6), got {self.values.shape}")
        if len(self.t_s) != n or len(self.temp_c) != n:
            raise ValueError("Batch.t_s and Batch.temp_c must have one entry per sample")
        if self.raw is not None and self.raw.shape != (n, len(CHANNELS)):
            raise ValueError(f"Batch.raw must have shape ({n}, 6), got {self.raw.shape}")

    def __len__(self) -> int:
        return len(self.index)

    @property
    def internal_gaps(self) -> np.ndarray:
        """``(k, 2)`` int64 array of (index of the sample after the hole, samples lost)."""
        d = np.diff(self.index) - 1
        where = np.nonzero(d > 0)[0]
        return np.column_stack([self.index[where + 1], d[where]]).astype(np.int64)

    @staticmethod
    def concat(batches: list[Batch]) -> Batch:
        """Join batches in order (``lost_before`` of the first one is kept)."""
        if not batches:
            raise ValueError("Batch.concat needs at least one batch")
        raw = None
        if all(b.raw is not None for b in batches):
            raw = np.concatenate([b.raw for b in batches])  # type: ignore[misc]
        return Batch(
            index=np.concatenate([b.index for b in batches]),
            t_s=np.concatenate([b.t_s for b in batches]),
            values=np.concatenate([b.values for b in batches]),
            temp_c=np.concatenate([b.temp_c for b in batches]),
            raw=raw,
            lost_before=batches[0].lost_before,
        )
