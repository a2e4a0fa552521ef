"""The streaming-Allan consumer: every sample of a stream into a
:class:`~imubench.stats.streaming.StreamingAllan`, snapshots on request.

The engine lives in the consumer's own thread (the pipeline's), so its updates never
run on the daemon's event loop. Other threads ask for a snapshot with
:meth:`AllanConsumer.request_snapshot` (or its saved state with
:meth:`AllanConsumer.request_state`); the consumer's thread answers between two
updates (at most one update late), so nobody touches the engine while it updates.

Holes in the stream go to the engine as gap samples (NaN rows / masked raw counts), in
blocks of at most :data:`GAP_BLOCK` rows, so a long outage costs time in proportion to its
length but bounded memory. :meth:`prepare` compiles (or loads from the numba cache) the
engine's kernels before the stream starts, so no sample waits for a compiler.
"""

from __future__ import annotations

import concurrent.futures
import logging
import queue
import threading
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from imubench.batch import Batch
from imubench.pipeline import Consumer
from imubench.sources.base import SourceInfo
from imubench.stats.streaming import StreamingAllan, warm_up

log = logging.getLogger(__name__)

GAP_BLOCK = 1 << 16
"""Most gap rows handed to the engine in one update."""

Snapshot = Mapping[str, Any] | list[Mapping[str, Any]]


class AllanConsumer(Consumer):
    """Feeds a :class:`StreamingAllan` (made by ``make_engine(info, use_raw)``).

    ``use_raw`` is True when the batches carry raw counts with known sensitivities and
    no calibration changes their values (``calibrated``): the engine then sums exact
    integers and scales them (``StreamingAllan(scale=...)``). A calibration corrects the
    values only (raw counts stay what the chip said), so a calibrated stream feeds the
    engine its values: the raw counts gave the live deviations of the uncalibrated
    sensor, 1.02x the recording's for a gyro gain of 1.02 (an outside reviewer).
    """

    name = "engine"

    def __init__(self, make_engine: Callable[[SourceInfo, bool], StreamingAllan],
                 measured_rate: Callable[[], float | None] | None = None,
                 calibrated: bool = False) -> None:
        self.make_engine = make_engine
        self.calibrated = calibrated
        self.measured_rate = measured_rate
        """The source's ODR measured against the host clock (None until known): each
        snapshot reports its taus at it (:meth:`StreamingAllan.set_rate`)."""
        self.engine: StreamingAllan | None = None
        self.use_raw = False
        self._last_index: int | None = None
        self._requests: queue.SimpleQueue[
            tuple[concurrent.futures.Future[Any], Callable[[StreamingAllan], Any]]
        ] = queue.SimpleQueue()
        self._finished = False
        self._lock = threading.Lock()
        self.temperature_c: float | None = None
        """The die temperature of the latest sample that has one, degC."""
        self.samples_fed = 0
        """Samples (not gap rows) given to the engine in this run."""
        self.samples_at_snapshot = 0
        """:attr:`samples_fed` when the latest snapshot was made (the payload's count of
        the samples its deviations are computed on)."""
        self.leading_gap_rows = 0
        """Gap rows put before the first sample (an engine resumed from a saved state: the
        time between the runs, so that no estimate joins them as if continuous)."""

    def prepare(self, info: SourceInfo) -> None:
        warm_up()
        self.use_raw = info.has_raw and not self.calibrated
        self.engine = self.make_engine(info, self.use_raw)

    @property
    def n_samples(self) -> int:
        return 0 if self.engine is None else self.engine.n_samples

    # -- snapshots ----------------------------------------------------------------------
    def request_snapshot(self) -> concurrent.futures.Future[Snapshot]:
        """A future snapshot of the engine, answered by the consumer's thread (at once
        when the stream has finished)."""
        return self._request(self._snapshot)

    def request_state(self) -> concurrent.futures.Future[bytes]:
        """A future of the engine's saved state (:meth:`StreamingAllan.save_state`),
        made in the consumer's thread like a snapshot."""
        return self._request(lambda engine: engine.save_state())

    def _snapshot(self, engine: StreamingAllan) -> Snapshot:
        rate = self.measured_rate() if self.measured_rate is not None else None
        if rate is not None:
            engine.set_rate(rate)
        self.samples_at_snapshot = self.samples_fed
        return engine.snapshot()

    def _request(self, what: Callable[[StreamingAllan], Any]
                 ) -> concurrent.futures.Future[Any]:
        fut: concurrent.futures.Future[Any] = concurrent.futures.Future()
        with self._lock:
            finished = self._finished
            if not finished:
                self._requests.put((fut, what))
        if finished:
            self._answer(fut, what)
        return fut

    def _answer(self, fut: concurrent.futures.Future[Any],
                what: Callable[[StreamingAllan], Any]) -> None:
        if not fut.set_running_or_notify_cancel():
            return
        try:
            assert self.engine is not None
            fut.set_result(what(self.engine))
        except BaseException as exc:
            fut.set_exception(exc)

    def _serve(self) -> None:
        while True:
            try:
                fut, what = self._requests.get_nowait()
            except queue.Empty:
                return
            self._answer(fut, what)

    # -- Consumer -----------------------------------------------------------------------
    def _gap_rows(self, n: int) -> None:
        engine = self.engine
        assert engine is not None
        while n > 0:  # a long outage: gap rows in bounded blocks
            k = min(n, GAP_BLOCK)
            if self.use_raw:
                engine.update(np.zeros((k, 6), np.int64), gaps=np.ones((k, 6), bool))
            else:
                engine.update(np.full((k, 6), np.nan))
            n -= k
            self._serve()

    def consume(self, batch: Batch) -> None:
        self._serve()
        engine = self.engine
        assert engine is not None
        if not len(batch):
            return
        idx = batch.index
        measured = batch.temp_c[np.isfinite(batch.temp_c)]
        if len(measured):
            self.temperature_c = float(measured[-1])
        src = batch.raw if self.use_raw else batch.values
        assert src is not None
        if self._last_index is None and self.leading_gap_rows:
            self._gap_rows(self.leading_gap_rows)
            self.leading_gap_rows = 0
        breaks = (np.nonzero(np.diff(idx) > 1)[0] + 1).tolist()
        for lo, hi in zip([0, *breaks], [*breaks, len(idx)], strict=True):
            expected = int(idx[lo]) if self._last_index is None else self._last_index + 1
            self._gap_rows(int(idx[lo]) - expected)
            if self.use_raw:
                engine.update(src[lo:hi], gaps=np.isnan(batch.values[lo:hi]))
            else:
                engine.update(src[lo:hi])
            self.samples_fed += hi - lo
            self._last_index = int(idx[hi - 1])
        self._serve()

    def idle(self) -> None:
        self._serve()

    def finish(self) -> None:
        with self._lock:
            self._finished = True
        self._serve()
