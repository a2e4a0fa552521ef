"""The source interface: anything that yields :class:`~imubench.batch.Batch` objects.

A source is picked by a URI in the configuration, never by import (see
:mod:`imubench.sources.registry`). Backends implement three small hooks and inherit the
shared behaviour (context manager, iteration, counters), in the style of python-can's
``BusABC``.
"""

from __future__ import annotations

import abc
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

from imubench.batch import Batch

COUNTER_NAMES: tuple[str, ...] = (
    "samples", "gaps", "lost_samples", "overruns", "bus_bytes", "io_errors",
    "retries", "bad_frames", "reconnects",
)
"""Acquisition counters every source keeps (zero where a counter does not apply)."""


@dataclass
class SourceInfo:
    """What a recording's metadata must say about the sensor behind a source.

    Attributes:
        uri: the source URI as given.
        chip: ``lsm6dsl``, ``lsm6dsm``, ``lsm6ds3h`` or a free text for foreign data.
        odr_hz: nominal output data rate of the samples in the batches, Hz.
        fs_dps: gyro full scale, dps (None if unknown).
        fs_g: accelerometer full scale, g (None if unknown).
        gyro_sensitivity_dps: dps per LSB of the raw counts (None without raw counts).
        accel_sensitivity_g: g per LSB of the raw counts (None without raw counts).
        channels: the channels that carry data (subset of CHANNELS).
        config: free-form backend configuration, stored in the recording metadata.
    """

    uri: str
    chip: str
    odr_hz: float
    fs_dps: float | None = None
    fs_g: float | None = None
    gyro_sensitivity_dps: float | None = None
    accel_sensitivity_g: float | None = None
    channels: tuple[str, ...] = ("gx", "gy", "gz", "ax", "ay", "az")
    config: dict[str, Any] = field(default_factory=dict)


class Source(abc.ABC):
    """Base class of every source backend.

    Subclasses set :attr:`info` in ``__init__`` and implement :meth:`_open`,
    :meth:`_read` and :meth:`_close`. :meth:`read` blocks until at least one sample is
    available (a wall-clock source paces itself) and returns ``None`` at the end of a
    finite stream (end of a replay file, ``duration_s`` reached). Samples a backend loses
    are counted in ``counters["lost_samples"]`` and show as holes in ``Batch.index``.
    """

    info: SourceInfo

    def __init__(self) -> None:
        self.counters: dict[str, int] = dict.fromkeys(COUNTER_NAMES, 0)
        self._opened = False

    # -- hooks for backends -------------------------------------------------------
    @abc.abstractmethod
    def _open(self) -> None: ...

    @abc.abstractmethod
    def _read(self) -> Batch | None: ...

    @abc.abstractmethod
    def _close(self) -> None: ...

    # -- shared behaviour ---------------------------------------------------------
    def open(self) -> None:
        if not self._opened:
            self._open()
            self._opened = True

    def read(self) -> Batch | None:
        """Next batch, or None at the end of a finite stream."""
        if not self._opened:
            self.open()
        batch = self._read()
        if batch is not None and len(batch):
            self.counters["samples"] += len(batch)
        return batch

    def close(self) -> None:
        if self._opened:
            self._opened = False
            self._close()

    def __enter__(self) -> Source:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __iter__(self) -> Iterator[Batch]:
        while True:
            batch = self.read()
            if batch is None:
                return
            if len(batch):
                yield batch
