"""Fixed-capacity ring buffer of samples: one writer, several readers with own cursors.

The acquisition thread writes Batches; each consumer (recorder, Allan engine, ...) holds a
:class:`RingReader`. Positions are absolute sample counts since the buffer was created, so
a reader knows exactly how far behind it is.

Two ways to handle a reader that falls behind, chosen by the writer's source:

* ``blocking=True`` (a source that waits for its reader: a replay, a virtual-clock
  simulator): :meth:`RingBuffer.write` waits until the slowest attached reader has made
  room, so nothing is ever dropped;
* ``blocking=False`` (a real-time source: a chip FIFO, a serial port): the write never
  waits; a reader more than ``capacity`` samples behind is moved forward to the oldest
  sample still held, and the samples it missed come back to it as a
  :class:`~imubench.batch.Gap` with the reason ``consumer overrun: <reader name>`` in the
  next batch it reads. Only that reader loses them.

Gaps travel with the samples: the gaps of a written batch are kept beside the ring (at
the position of the sample after each hole, up to ``max_gaps`` of them) and handed to
every reader with the samples that follow them, also when the reader skipped those
samples, so each consumer can tell every hole's reason. A batch without samples (the
end of a stream) leaves its gaps for readers to collect once the ring is closed.

Thread safety: the writer fills the slots and publishes the new head under one lock,
readers copy under the same lock (short numpy copies). Asyncio consumers await
:meth:`RingReader.wait_async`, woken through ``call_soon_threadsafe``.
"""

from __future__ import annotations

import asyncio
import threading
from collections import deque
from dataclasses import dataclass

import numpy as np

from imubench.batch import Batch, Gap

MAX_GAPS = 65_536
"""Gap records kept beside the ring (older ones are dropped; a reader that skipped them
sees the holes as ``unexplained``)."""


@dataclass(frozen=True)
class ReadResult:
    """What one read returned: the samples and gaps (None if nothing new) and the number
    of samples this reader missed (also declared as a gap in ``batch``)."""

    batch: Batch | None
    missed: int


class RingBuffer:
    """Numpy-backed ring of ``capacity`` samples of the six channels."""

    def __init__(self, capacity: int, *, with_raw: bool = True, blocking: bool = False,
                 max_gaps: int = MAX_GAPS) -> None:
        if capacity < 1:
            raise ValueError("ring buffer capacity must be at least one sample")
        self.capacity = int(capacity)
        self.blocking = blocking
        self._index = np.zeros(capacity, np.int64)
        self._t = np.zeros(capacity, np.float64)
        self._values = np.zeros((capacity, 6), np.float64)
        self._temp = np.zeros(capacity, np.float64)
        self._raw = np.zeros((capacity, 6), np.int16) if with_raw else None
        self._has_raw = np.zeros(capacity, bool)
        self._gaps: deque[tuple[int, int, Gap]] = deque(maxlen=max_gaps)  # (seq, pos, gap)
        self._gap_seq = 0
        self._declared_lost = 0  # samples lost in the gaps written
        self._head = 0  # absolute count of samples written
        self._lock = threading.Lock()
        self._cond = threading.Condition(self._lock)
        self._waiters: list[tuple[asyncio.AbstractEventLoop, asyncio.Event]] = []
        self._closed = False
        self._readers: list[RingReader] = []

    @property
    def head(self) -> int:
        """Absolute number of samples written so far."""
        return self._head

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def declared_lost(self) -> int:
        """Samples lost in the gaps written so far (their holes' sizes)."""
        return self._declared_lost

    def unread_lost(self, reader: RingReader) -> int:
        """Samples lost in the gaps ``reader`` has yet to read (call with the ring's lock
        held, :meth:`locked`, for a value consistent with :attr:`head`)."""
        return sum(gap.lost for seq, _, gap in self._gaps if seq >= reader.gap_seq)

    def locked(self) -> threading.Lock:
        """The lock under which the writer publishes and readers copy: hold it to read
        :attr:`head`, :attr:`declared_lost` and the readers' positions at one instant."""
        return self._lock

    def reader(self, name: str, *, from_start: bool = False) -> RingReader:
        """A new reader positioned at the current head (or at the oldest sample held)."""
        with self._lock:
            start = max(0, self._head - self.capacity) if from_start else self._head
            first_gap = self._gaps[0][0] if self._gaps else self._gap_seq
            gap_seq = first_gap if from_start else self._gap_seq
            reader = RingReader(self, name, start, gap_seq)
            self._readers.append(reader)
            return reader

    def detach(self, reader: RingReader) -> None:
        """``reader`` reads no more: it no longer holds a blocking writer back."""
        with self._cond:
            if reader in self._readers:
                self._readers.remove(reader)
            self._cond.notify_all()

    def _room(self) -> int:
        if not self._readers:
            return self.capacity
        slowest = min(r.position for r in self._readers)
        return self.capacity - (self._head - slowest)

    def write(self, batch: Batch, stop: threading.Event | None = None) -> bool:
        """Append a batch (the only writer).

        A blocking ring waits (in pieces of at most ``capacity`` samples) until the
        slowest reader has made room; returns False if ``stop`` was set or the ring
        closed while waiting (the rest of the batch is not written). A non-blocking ring
        never waits and always returns True.
        """
        n = len(batch)
        if n == 0:
            if batch.gaps:
                with self._cond:
                    self._add_gaps(batch, 0)
                self._wake()
            return True
        done = 0
        while done < n:
            with self._cond:
                take = min(n - done, self.capacity)
                if self.blocking:
                    while self._room() < take:
                        if self._closed or (stop is not None and stop.is_set()):
                            return False
                        self._cond.wait(0.1)
                self._store(batch, done, take)
                self._cond.notify_all()
            self._wake()
            done += take
        return True

    def _add_gaps(self, batch: Batch, start: int, stop: int | None = None) -> None:
        """Keep the gaps of ``batch`` that precede its samples ``start:stop``."""
        if not batch.gaps:
            return
        n = len(batch)
        after = int(batch.index[start - 1]) if 0 < start <= n else None
        hi = int(batch.index[stop - 1]) if stop is not None and stop > 0 else None
        for gap in batch.gaps:
            if n == 0:
                pos = self._head
            else:
                if after is not None and gap.at <= after:
                    continue  # kept with an earlier piece
                if hi is not None and gap.at > hi:
                    continue  # belongs to a later piece
                k = int(np.searchsorted(batch.index, gap.at))
                pos = self._head + (k - start)
            self._gaps.append((self._gap_seq, pos, gap))
            self._gap_seq += 1
            self._declared_lost += gap.lost

    def _store(self, batch: Batch, start: int, n: int) -> None:
        self._add_gaps(batch, start, start + n)
        head = self._head
        pos = head % self.capacity
        first = min(n, self.capacity - pos)
        for dst_sl, src_sl in (
            (slice(pos, pos + first), slice(start, start + first)),
            (slice(0, n - first), slice(start + first, start + n)),
        ):
            if dst_sl.stop <= dst_sl.start:
                continue
            self._index[dst_sl] = batch.index[src_sl]
            self._t[dst_sl] = batch.t_s[src_sl]
            self._values[dst_sl] = batch.values[src_sl]
            self._temp[dst_sl] = batch.temp_c[src_sl]
            if self._raw is not None and batch.raw is not None:
                self._raw[dst_sl] = batch.raw[src_sl]
            self._has_raw[dst_sl] = batch.raw is not None
        self._head = head + n

    def _wake(self) -> None:
        with self._lock:
            waiters = list(self._waiters)
        for loop, event in waiters:
            loop.call_soon_threadsafe(event.set)

    def close(self) -> None:
        """No more data will come: wake every waiting reader and a blocked writer."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        self._wake()

    def _read(self, reader: RingReader, max_samples: int | None) -> ReadResult:
        with self._cond:
            head = self._head
            missed = 0
            oldest = head - self.capacity
            if reader.position < oldest:
                missed = oldest - reader.position
                reader.position = oldest
            n = head - reader.position
            if max_samples is not None:
                n = min(n, max_samples)
            end = reader.position + n
            # gaps after the last sample (the end of a stream) come alone, once closed
            trailing = n <= 0 and self._closed and end == head
            gaps = []
            for seq, pos, gap in self._gaps:
                if seq < reader.gap_seq:
                    continue
                if pos < end or (trailing and pos <= end):
                    gaps.append(gap)
                    reader.gap_seq = seq + 1
                else:
                    break
            if trailing:
                reader.gap_seq = self._gap_seq
            if n <= 0:
                self._cond.notify_all()
                if gaps or missed:
                    return ReadResult(Batch.empty(with_raw=self._raw is not None,
                                                  gaps=gaps), missed)
                return ReadResult(None, 0)
            idx = (reader.position + np.arange(n)) % self.capacity
            raw = None
            if self._raw is not None and bool(self._has_raw[idx].all()):
                raw = self._raw[idx]
            index = self._index[idx]
            if missed:
                gaps.append(Gap(int(index[0]), missed, f"consumer overrun: {reader.name}"))
            batch = Batch(index, self._t[idx], self._values[idx], self._temp[idx], raw,
                          tuple(g for g in gaps if g.at <= int(index[-1])))
            reader.position = end
            self._cond.notify_all()
            return ReadResult(batch, missed)


class RingReader:
    """A consumer's cursor into a :class:`RingBuffer`."""

    def __init__(self, ring: RingBuffer, name: str, position: int, gap_seq: int) -> None:
        self.ring = ring
        self.name = name
        self.position = position
        self.gap_seq = gap_seq
        self.missed = 0

    @property
    def lag(self) -> int:
        """Samples written but not yet read by this reader."""
        return self.ring.head - self.position

    @property
    def finished(self) -> bool:
        """The ring is closed and this reader has read every sample and gap."""
        ring = self.ring
        return ring.closed and self.position >= ring.head and self.gap_seq >= ring._gap_seq

    def read(self, max_samples: int | None = None) -> ReadResult:
        result = self.ring._read(self, max_samples)
        self.missed += result.missed
        return result

    def detach(self) -> None:
        self.ring.detach(self)

    def wait(self, timeout_s: float | None = None) -> bool:
        """Block until data is available or the ring is closed; True if data."""
        with self.ring._cond:
            self.ring._cond.wait_for(
                lambda: self.ring.head > self.position or self.ring.closed, timeout_s
            )
            return self.ring.head > self.position

    async def wait_async(self, timeout_s: float | None = None) -> bool:
        """Asyncio version of :meth:`wait`."""
        loop = asyncio.get_running_loop()
        event = asyncio.Event()
        entry = (loop, event)
        with self.ring._lock:
            if self.ring.head > self.position or self.ring.closed:
                return self.ring.head > self.position
            self.ring._waiters.append(entry)
        try:
            await asyncio.wait_for(event.wait(), timeout_s)
        except TimeoutError:
            pass
        finally:
            with self.ring._lock:
                self.ring._waiters.remove(entry)
        return self.ring.head > self.position
