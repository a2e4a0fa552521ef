"""The source interface: anything that yields :class:`~imubench.batch.Batch` objects.

A source is picked by a URI in the configuration, never by import (see
:mod:`imubench.sources.registry`). Backends implement three small hooks and inherit the
shared behaviour (context manager, iteration, gap accounting, telemetry), in the style of
python-can's ``BusABC``.
"""

from __future__ import annotations

import abc
import threading
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from typing import Any

from imubench.batch import Batch
from imubench.errors import SourceError

COUNTER_NAMES: tuple[str, ...] = (
    "samples", "gaps", "lost_samples", "overruns", "bus_bytes", "io_errors",
    "retries", "bad_frames", "reconnects",
)
"""Acquisition counters every source keeps (zero where a counter does not apply)."""


@dataclass(frozen=True)
class Telemetry:
    """What a source reports about its acquisition (:meth:`Source.telemetry`).

    Attributes:
        samples: samples delivered in batches.
        gaps: gaps declared (holes in the sample index, each with a reason).
        lost_samples: samples lost at the source (sum of the gaps' ``lost``).
        overruns: polls that found the FIFO's overrun flag set (chips); samples lost to
            overwritten FIFO data are under ``lost_by_reason["fifo overrun"]``, flag or not.
        bus_bytes: wire bytes moved on the I2C bus or the serial link.
        bus_utilization: share of the link's payload limit used, 0..1 (0 when unknown).
        io_errors: failed transfers (each retried or counted as a loss).
        retries: transfers retried.
        bad_frames: damaged or implausible frames dropped (serial links).
        reconnects: link re-opens after an unplug.
        measured_odr_hz: output data rate measured against the host clock, Hz (None
            where the source cannot measure it).
        elapsed_s: source seconds since the stream started.
        expected_samples: length of a finite stream in samples (None: endless).
        lost_by_reason: samples lost per gap reason.
    """

    samples: int = 0
    gaps: int = 0
    lost_samples: int = 0
    overruns: int = 0
    bus_bytes: int = 0
    bus_utilization: float = 0.0
    io_errors: int = 0
    retries: int = 0
    bad_frames: int = 0
    reconnects: int = 0
    measured_odr_hz: float | None = None
    elapsed_s: float = 0.0
    expected_samples: int | None = None
    lost_by_reason: dict[str, int] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class SourceInfo:
    """What a recording's metadata must say about the sensor behind a source.

    Attributes:
        uri: the source URI as given.
        chip: ``lsm6dsl``, ``lsm6dsm``, ``lsm6ds3h`` or a free text for foreign data.
        odr_hz: nominal output data rate of the samples in the batches, Hz.
        realtime: True when samples are lost if the source is not read in time (a chip
            FIFO, a serial port, a wall-clock simulator); False for a source that waits
            for its reader (a replay, a virtual-clock simulator), which a pipeline paces
            by its slowest consumer and never drops.
        fs_dps: gyro full scale, dps (None if unknown).
        fs_g: accelerometer full scale, g (None if unknown).
        gyro_sensitivity_dps: dps per LSB of the raw counts (None without raw counts).
        accel_sensitivity_g: g per LSB of the raw counts (None without raw counts).
        channels: the channels that carry data (subset of CHANNELS).
        config: backend configuration, stored in the recording metadata.
    """

    uri: str
    chip: str
    odr_hz: float
    realtime: bool
    fs_dps: float | None = None
    fs_g: float | None = None
    gyro_sensitivity_dps: float | None = None
    accel_sensitivity_g: float | None = None
    channels: tuple[str, ...] = ("gx", "gy", "gz", "ax", "ay", "az")
    config: dict[str, Any] = field(default_factory=dict)

    @property
    def has_raw(self) -> bool:
        """True when the batches carry raw counts with known sensitivities."""
        return self.gyro_sensitivity_dps is not None and self.accel_sensitivity_g is not None


class Source(abc.ABC):
    """Base class of every source backend.

    Subclasses set :attr:`info` in ``__init__`` and implement :meth:`_open`,
    :meth:`_read` and :meth:`_close`; they update the link counters in
    :attr:`counters` (``overruns``, ``bus_bytes``, ``io_errors``, ``retries``,
    ``bad_frames``, ``reconnects``) and may override :attr:`measured_odr_hz`,
    :attr:`elapsed_s`, :attr:`expected_samples` and :attr:`bus_utilization`.
    :meth:`read` blocks until samples are available (a wall-clock source paces
    itself) and returns ``None`` at the end of a finite stream. Every sample a backend
    loses is a hole in the sample index declared by a :class:`~imubench.batch.Gap` in
    the next batch (or in a batch without samples at the end of the stream); the base
    class counts them (``gaps``, ``lost_samples``, :attr:`Telemetry.lost_by_reason`).
    A backend whose :meth:`_read` fails for good (:class:`SourceError`: a device lost)
    says in :meth:`_lost_at_failure` what the outage before the failure cost; that batch
    is delivered first and the error raised by the next :meth:`read`.
    """

    info: SourceInfo

    def __init__(self) -> None:
        self.counters: dict[str, int] = dict.fromkeys(COUNTER_NAMES, 0)
        self.lost_by_reason: dict[str, int] = {}
        self._opened = False
        self._interrupt = threading.Event()
        """Set by :meth:`interrupt`; backends wait on it instead of sleeping."""
        self._failure: SourceError | None = None
        """The failure to raise at the next :meth:`read`, after its outage's batch."""

    # -- hooks for backends -------------------------------------------------------
    @abc.abstractmethod
    def _open(self) -> None: ...

    @abc.abstractmethod
    def _read(self) -> Batch | None: ...

    @abc.abstractmethod
    def _close(self) -> None: ...

    def _lost_at_failure(self) -> Batch | None:
        """At a failure that ends the stream: the samples the device made after the newest
        one read, as a batch of gaps with their reason, or None (none, or the backend
        cannot tell). A device lost for good had its outage uncounted: an outside
        reviewer's bus stuck for 2.5 s before ``io_timeout_s`` gave up ended with "112
        recorded, 0 lost" where a stop during the same outage counted 204 lost."""
        return None

    def prepare(self) -> None:  # noqa: B027 - optional hook
        """Slow set-up before the stream starts (a simulator generating its first noise
        block), so that reading in real time is never stalled by it."""

    @property
    def measured_odr_hz(self) -> float | None:
        """Output data rate measured against the host clock, Hz (None: not measured)."""
        return None

    @property
    @abc.abstractmethod
    def elapsed_s(self) -> float:
        """Source seconds since the stream started (of the samples read so far)."""

    @property
    def expected_samples(self) -> int | None:
        """Length of a finite stream in samples (None: endless)."""
        return None

    @property
    def bus_utilization(self) -> float:
        """Share of the link's payload limit used, 0..1 (0 when unknown)."""
        return 0.0

    # -- shared behaviour ---------------------------------------------------------
    def open(self) -> None:
        if not self._opened:
            self._open()
            self._opened = True

    def interrupt(self) -> None:
        """Make a blocked or later :meth:`read` return None soon (from any thread)."""
        self._interrupt.set()

    def read(self) -> Batch | None:
        """Next batch (samples and/or the gaps before them), or None at the end (or after
        :meth:`interrupt`)."""
        if not self._opened:
            self.open()
        if self._failure is not None:
            failure, self._failure = self._failure, None
            raise failure
        if self._interrupt.is_set():
            return None
        try:
            batch = self._read()
        except SourceError as exc:
            batch = self._lost_at_failure()
            if batch is None:
                raise
            self._failure = exc
        if batch is not None:
            self.counters["samples"] += len(batch)
            for gap in batch.gaps:
                self.counters["gaps"] += 1
                self.counters["lost_samples"] += gap.lost
                self.lost_by_reason[gap.reason] = self.lost_by_reason.get(gap.reason, 0) + gap.lost
        return batch

    def telemetry(self) -> Telemetry:
        """The acquisition counters and measurements, in one consistent record."""
        c = self.counters
        return Telemetry(
            samples=c["samples"], gaps=c["gaps"], lost_samples=c["lost_samples"],
            overruns=c["overruns"], bus_bytes=c["bus_bytes"],
            bus_utilization=float(self.bus_utilization), io_errors=c["io_errors"],
            retries=c["retries"], bad_frames=c["bad_frames"], reconnects=c["reconnects"],
            measured_odr_hz=self.measured_odr_hz, elapsed_s=float(self.elapsed_s),
            expected_samples=self.expected_samples, lost_by_reason=dict(self.lost_by_reason),
        )

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
        """Batches with samples or gaps, until the end of the stream."""
        while True:
            batch = self.read()
            if batch is None:
                return
            if len(batch) or batch.gaps:
                yield batch
