"""The one acquisition pipeline: a source, a ring buffer, and one reader per consumer.

``imubench run``, ``acquire`` and ``sim`` all move samples this way::

    source --(acquisition thread)--> RingBuffer --(one thread per consumer)--> consumer

* The acquisition thread reads the source and writes every batch (samples and the typed
  :class:`~imubench.batch.Gap` records of its holes) into the ring.
* A source that waits for its reader (``SourceInfo.realtime`` False: a replay, a
  virtual-clock simulator) gets a *blocking* ring: it is paced by the slowest consumer
  and never drops. A real-time source (a chip FIFO, a serial port, a wall-clock
  simulator) never waits for a consumer: one that falls more than the ring's capacity
  behind loses samples, only itself, declared as a gap ``consumer overrun: <name>``.
* Each consumer runs in its own thread with its own :class:`~imubench.ringbuffer.
  RingReader`; before every batch it is handed, the holes since its previous batch are
  explained (:func:`~imubench.batch.explain_holes`: each with its declared reason), and
  its :class:`Account` adds up what it received and what it lost, by reason.

Accounting: for every consumer that reads from the start, when the pipeline has
finished, ``delivered + lost == produced`` where ``produced`` is the samples written into
the ring plus the samples the source declared lost (:attr:`Pipeline.produced`). Tests
check it under stalls, faults and slow consumers. While it runs, :meth:`Pipeline.view`
gives ``delivered + lost + lag == produced`` at one instant, ``lag`` being what the
consumer has yet to read: samples, and samples declared lost in gaps it has not reached
(the live health; before 2026-12-06 its parts were read at different moments, and a
consumer caught between taking a batch and counting it read thousands short under load).

``duration_s`` ends the stream after ``round(duration_s * odr_hz)`` sample periods from
its first index (a gap across that end is cut there). :meth:`Pipeline.stop` ends it at
once: the source is interrupted, the ring closed, every consumer drains what the ring
holds and finishes (closes its file). A consumer too far behind to drain in the time a
stop allows is cut short by :meth:`Pipeline.cut_short`: what it has not taken yet is
counted lost, ``not processed before the stop: <name>``, and it finishes.
"""

from __future__ import annotations

import abc
import contextlib
import copy
import dataclasses
import logging
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from imubench.batch import Batch, explain_holes, gaps_before, hole_start
from imubench.ringbuffer import RingBuffer, RingReader
from imubench.sources.base import Source, SourceInfo

log = logging.getLogger(__name__)

MIN_CAPACITY = 4096
"""Smallest ring, samples (a few FIFO bursts at the highest ODR)."""
NOT_PROCESSED = "not processed before the stop"
"""Loss reason of the samples a consumer cut short at a stop had not taken
(:meth:`Pipeline.cut_short`), followed by its name."""


class Consumer(abc.ABC):
    """Something that takes every sample of a stream: a recorder, an Allan engine, ...

    The pipeline calls :meth:`prepare` before the source starts (open files, compile
    kernels), then :meth:`consume` from the consumer's own thread with each batch (its
    ``gaps`` explain every hole since the previous batch, with reasons), :meth:`idle`
    when no data came for a short while, and :meth:`finish` once at the end (also after
    an error).
    """

    name: str = "consumer"
    drains_at_stop: bool = False
    """A stop waits for this consumer to take everything the ring holds (a recorder:
    every sample in memory reaches the file); one that does not is cut short when it
    lags (:meth:`Pipeline.cut_short`)."""

    def prepare(self, info: SourceInfo) -> None:  # noqa: B027 - optional hook
        """Before the source starts: everything slow that must not stall the stream."""

    @abc.abstractmethod
    def consume(self, batch: Batch) -> None: ...

    def idle(self) -> None:  # noqa: B027 - optional hook
        """No data for a short while (serve requests, flush)."""

    def finish(self) -> None:  # noqa: B027 - optional hook
        """The stream has ended (or the pipeline stops): close what is open."""


@dataclass
class Account:
    """What one consumer received and what it lost, by reason."""

    delivered: int = 0
    lost_by_reason: dict[str, int] = field(default_factory=dict)
    first_index: int | None = None
    last_index: int | None = None

    @property
    def lost(self) -> int:
        return sum(self.lost_by_reason.values())

    def add(self, batch: Batch) -> None:
        self.delivered += len(batch)
        self._follow(batch)

    def add_unprocessed(self, batch: Batch, reason: str) -> None:
        """``batch`` was not handed to the consumer: its samples are lost for ``reason``
        (its holes keep their own reasons)."""
        if len(batch):
            self.lost_by_reason[reason] = self.lost_by_reason.get(reason, 0) + len(batch)
        self._follow(batch)

    def _follow(self, batch: Batch) -> None:
        for gap in batch.gaps:
            self.lost_by_reason[gap.reason] = self.lost_by_reason.get(gap.reason, 0) + gap.lost
        if len(batch):
            if self.first_index is None:
                self.first_index = int(batch.index[0])
            self.last_index = int(batch.index[-1])


class _Runner(threading.Thread):
    """The thread feeding one consumer from its ring reader."""

    def __init__(self, consumer: Consumer, reader: RingReader, max_chunk: int) -> None:
        super().__init__(name=f"imubench-{consumer.name}", daemon=True)
        self.consumer = consumer
        self.reader = reader
        self.max_chunk = max_chunk
        self.account = Account()
        self.error: BaseException | None = None
        self.cut = threading.Event()
        """Set by :meth:`Pipeline.cut_short`: count the rest as lost instead of consuming."""
        self.lock = threading.Lock()
        """Held from taking a batch off the ring to counting it in :attr:`account`, so that
        :meth:`Pipeline.view` never sees it in neither."""

    def run(self) -> None:
        try:
            while True:
                with self.lock:
                    batch = self._take()
                if batch is None:
                    if self.reader.finished:
                        return
                    if not self.reader.wait(0.05):
                        self.consumer.idle()
                    continue
                if len(batch) or batch.gaps:
                    self.consumer.consume(batch)
        except BaseException as exc:  # reported by the pipeline, never swallowed
            self.error = exc
            log.exception("consumer %s failed", self.consumer.name)
        finally:
            self.reader.detach()
            try:
                self.consumer.finish()
            except BaseException as exc:
                self.error = self.error or exc
                log.exception("consumer %s failed to finish", self.consumer.name)

    def _take(self) -> Batch | None:
        """The next batch, its holes explained and counted (None when the ring has none
        now; an empty batch when it was counted lost, the pipeline cutting it short)."""
        res = self.reader.read(self.max_chunk)
        if res.batch is None:
            return None
        batch = res.batch
        gaps = tuple(explain_holes(batch, self.account.last_index))
        if gaps != batch.gaps:
            batch = dataclasses.replace(batch, gaps=gaps)
        if self.cut.is_set():
            self.account.add_unprocessed(batch, f"{NOT_PROCESSED}: {self.consumer.name}")
            return Batch.empty(with_raw=batch.raw is not None)
        self.account.add(batch)
        return batch


def _finish_quietly(c: Consumer) -> None:
    """``c.finish()``, an error logged rather than raised (the others are closed all the
    same)."""
    try:
        c.finish()
    except Exception as exc:
        log.error("consumer %s failed to finish: %s", c.name, exc)


class Pipeline:
    """Source -> ring buffer -> consumers (see the module docstring).

    Args:
        source: the source (not yet opened).
        consumers: every consumer; each gets its own reader and thread.
        capacity_s: ring capacity, seconds of data at the source's ODR.
        duration_s: end the stream after this many seconds of data (None: until the
            source ends or :meth:`stop`).
        max_chunk: most samples a consumer takes per call.
        transform: applied to every batch in the acquisition thread before it enters the
            ring (a calibration: :meth:`imubench.calibration.Calibration.apply`).
    """

    def __init__(self, source: Source, consumers: Sequence[Consumer], *,
                 capacity_s: float = 30.0, duration_s: float | None = None,
                 max_chunk: int = 1 << 16,
                 transform: Callable[[Batch], Batch] | None = None) -> None:
        self.source = source
        self.consumers = list(consumers)
        names = [c.name for c in self.consumers]
        if len(set(names)) != len(names):
            raise ValueError(f"consumer names must be unique, got {names}")
        self.capacity_s = capacity_s
        self.duration_s = duration_s
        self.max_chunk = max_chunk
        self.transform = transform
        self.stop_event = threading.Event()
        self.error: BaseException | None = None
        self.ring: RingBuffer | None = None
        self._runners: list[_Runner] = []
        self._thread: threading.Thread | None = None
        self._prepared: list[Consumer] = []
        self._prepare_lock = threading.Lock()
        self._given_up = False
        """:meth:`close_unstarted` was called: a set-up still running closes what it
        opens after that."""
        self.started_at: float | None = None

    # -- life cycle -------------------------------------------------------------------
    @property
    def info(self) -> SourceInfo:
        return self.source.info

    def prepare(self) -> None:
        """The slow set-up before the stream: :meth:`Source.prepare` and every consumer's
        :meth:`Consumer.prepare` (compiling, opening files)."""
        self.source.prepare()
        for c in self.consumers:
            c.prepare(self.source.info)
            with self._prepare_lock:
                given_up = self._given_up
                if not given_up:
                    self._prepared.append(c)
            if given_up:  # the daemon gave up on this start while c was being set up
                _finish_quietly(c)
                return

    def close_unstarted(self) -> None:
        """A pipeline that will not start (stopped while it was set up): each consumer
        :meth:`prepare` reached finishes, closing what it opened (a recording gets its
        end record; an outside reviewer's daemon stopped 1.2 s after its start said
        "recording closed" over a file without one). Nothing once started: the consumer
        threads finish them."""
        if self._runners:
            return
        with self._prepare_lock:  # a set-up thread still running closes what it opens next
            self._given_up = True
            prepared, self._prepared = self._prepared, []
        for c in prepared:
            _finish_quietly(c)

    def start(self) -> None:
        """Open the source and start the acquisition and consumer threads (call
        :meth:`prepare` first). Errors opening the source are raised here, after the
        consumers prepared are closed (:meth:`close_unstarted`: a recording opened for a
        device that never answered was left without its end record)."""
        # the source first: a device that does not answer leaves no consumer thread
        # unstarted (join() then failed with "cannot join thread before it is started",
        # an internal error of the daemon hiding the device's own)
        try:
            self.source.open()
        except BaseException:
            self.close_unstarted()
            raise
        info = self.source.info
        capacity = max(MIN_CAPACITY, round(self.capacity_s * info.odr_hz))
        self.ring = RingBuffer(capacity, with_raw=info.has_raw, blocking=not info.realtime)
        self._runners = [
            _Runner(c, self.ring.reader(c.name), self.max_chunk) for c in self.consumers
        ]
        self.started_at = time.monotonic()
        for r in self._runners:
            r.start()
        self._thread = threading.Thread(target=self._acquire, name="imubench-acquisition",
                                        daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """End the stream now: interrupt the source; consumers drain and finish."""
        self.stop_event.set()
        self.source.interrupt()

    def join(self, timeout_s: float | None = None) -> bool:
        """Wait for the acquisition and every consumer to finish; True if they did."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        threads: list[threading.Thread] = [*([self._thread] if self._thread else []),
                                           *self._runners]
        for t in threads:
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            t.join(left)
        return not any(t.is_alive() for t in threads)

    def cut_short(self) -> dict[str, int]:
        """After :meth:`stop`: every consumer still draining, except those that drain at a
        stop (:attr:`Consumer.drains_at_stop`), counts what it has not taken as lost
        (:data:`NOT_PROCESSED`) instead of consuming it, and finishes once the batch in
        hand is done. Returns each cut consumer's lag (samples) at the cut."""
        cut = [r for r in self._runners if r.is_alive() and not r.consumer.drains_at_stop]
        for r in cut:
            r.cut.set()
        return {r.consumer.name: r.reader.lag for r in cut}

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    @property
    def done(self) -> bool:
        """The acquisition and every consumer have finished."""
        threads = [*([self._thread] if self._thread else []), *self._runners]
        return bool(threads) and not any(t.is_alive() for t in threads)

    # -- accounting -------------------------------------------------------------------
    @property
    def produced(self) -> int:
        """Samples written into the ring plus samples the source declared lost."""
        return 0 if self.ring is None else self.ring.head + self.ring.declared_lost

    def accounts(self) -> dict[str, Account]:
        """Each consumer's account (a live view while running)."""
        return {r.consumer.name: r.account for r in self._runners}

    def view(self) -> tuple[int, dict[str, tuple[Account, int]]]:
        """(produced, each consumer's account and lag) at one instant: every consumer's
        ``delivered + lost + lag == produced``, ``lag`` being the samples it has yet to
        read and those declared lost in the gaps it has not reached. The consumers'
        take-and-count steps and the ring's writes wait while it is read (microseconds;
        the accounts are copied)."""
        if self.ring is None:
            return 0, {}
        ring = self.ring
        with contextlib.ExitStack() as held:
            for r in self._runners:
                held.enter_context(r.lock)
            with ring.locked():
                produced = ring.head + ring.declared_lost
                return produced, {
                    r.consumer.name: (copy.deepcopy(r.account),
                                      ring.head - r.reader.position + ring.unread_lost(r.reader))
                    for r in self._runners}

    def consumer_errors(self) -> dict[str, BaseException]:
        return {r.consumer.name: r.error for r in self._runners if r.error is not None}

    # -- the acquisition thread -----------------------------------------------------------
    def _acquire(self) -> None:
        assert self.ring is not None
        ring = self.ring
        end: int | None = None
        try:
            while not self.stop_event.is_set():
                batch = self.source.read()
                if batch is None:
                    break
                if not len(batch) and not batch.gaps:
                    continue
                if self.transform is not None:
                    batch = self.transform(batch)
                parts, finished = [batch], False
                if self.duration_s is not None:
                    if end is None:
                        origin = (int(batch.index[0]) if len(batch)
                                  else hole_start(batch.gaps))
                        end = origin + round(self.duration_s * self.source.info.odr_hz)
                    parts, finished = _cut(batch, end)
                # False: a stop ended a blocking ring's wait (what went in is counted
                # produced: its samples and the gaps before them)
                if not all(ring.write(part, self.stop_event) for part in parts) or finished:
                    break
        except BaseException as exc:  # reported by the owner, never swallowed
            self.error = exc
            log.error("acquisition from %s failed: %s", self.source.info.uri, exc)
        finally:
            try:
                self.source.close()
            except Exception as exc:  # closing a broken device: the first error counts
                log.warning("closing %s: %s", self.source.info.uri, exc)
            ring.close()


def _cut(batch: Batch, end: int) -> tuple[list[Batch], bool]:
    """``batch`` without what lies at or after sample index ``end`` (a gap across ``end``
    is cut there, and sent in a batch of its own after the samples); True when the stream
    has reached ``end``."""
    n_all = len(batch)
    reached = (n_all and int(batch.index[-1]) >= end - 1) or any(g.at >= end for g in batch.gaps)
    if not reached:
        return [batch], False
    n = int((batch.index < end).sum())
    kept = batch.head(n)
    last = int(kept.index[-1]) if n else None
    out = [kept] if n else []
    # the gaps the kept samples do not carry, cut at end
    tail = gaps_before([g for g in batch.gaps if last is None or g.at > last], end)
    if tail:
        out.append(Batch.empty(with_raw=batch.raw is not None, gaps=tail))
    return out, True
