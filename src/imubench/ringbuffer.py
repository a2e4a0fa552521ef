"""Fixed-capacity ring buffer of samples: one writer, several readers with own cursors.

The acquisition thread writes Batches; consumers (logger, Allan engine, MQTT) each hold
a :class:`RingReader`. Positions are absolute sample counts since the buffer was created,
so a reader knows exactly how far behind it is. A reader that falls more than
``capacity`` samples behind is moved forward to the oldest sample still held and told how
many samples it missed (:attr:`ReadResult.missed`, accumulated in
:attr:`RingReader.missed`): nothing is lost silently.

Thread safety: the writer fills the slots and publishes the new head under one lock,
and readers copy under the same lock (critical sections are short numpy copies), so a
lagging reader can never copy a slot the writer is overwriting. Asyncio
consumers await :meth:`RingReader.wait_async`, woken through ``call_soon_threadsafe``.
Sample indices (and therefore gaps, as holes in the index) are stored with the samples.
"""

from __future__ import annotations

import asyncio
import threading
from dataclasses import dataclass

import numpy as np

from imubench.batch import Batch


@dataclass(frozen=True)
class ReadResult:
    """What one read returned: the samples (None if nothing new) and samples missed."""

    batch: Batch | None
    missed: int


class RingBuffer:
    """Numpy-backed ring of ``capacity`` samples of the six channels."""

    def __init__(self, capacity: int, *, with_raw: bool = True) -> None:
        if capacity < 1:
            raise ValueError("ring buffer capacity must be at least one sample")
        self.capacity = int(capacity)
        self._index = np.zeros(capacity, np.int64)
        self._t = np.zeros(capacity, np.float64)
        self._values = np.zeros((capacity, 6), np.float64)
        self._temp = np.zeros(capacity, np.float64)
        self._raw = np.zeros((capacity, 6), np.int16) if with_raw else None
        self._has_raw = np.zeros(capacity, bool)
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

    def reader(self, name: str, *, from_start: bool = False) -> RingReader:
        """A new reader positioned at the current head (or at the oldest sample held)."""
        with self._lock:
            start = max(0, self._head - self.capacity) if from_start else self._head
            reader = RingReader(self, name, start)
            self._readers.append(reader)
            return reader

    def write(self, batch: Batch) -> None:
        """Append a batch (the only writer). Batches larger than the capacity keep
        their newest ``capacity`` samples; lagging readers are told what they missed."""
        n = len(batch)
        if n == 0:
            return
        with self._cond:
            head = self._head
            start = 0
            if n > self.capacity:
                start = n - self.capacity
            pos = (head + start) % self.capacity
            count = n - start
            first = min(count, self.capacity - pos)
            for dst_sl, src_sl in (
                (slice(pos, pos + first), slice(start, start + first)),
                (slice(0, count - first), slice(start + first, n)),
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
            self._cond.notify_all()
            waiters = list(self._waiters)
        for loop, event in waiters:
            loop.call_soon_threadsafe(event.set)

    def close(self) -> None:
        """No more data will come: wake every waiting reader."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()
            waiters = list(self._waiters)
        for loop, event in waiters:
            loop.call_soon_threadsafe(event.set)

    def _read(self, reader: RingReader, max_samples: int | None) -> ReadResult:
        with self._lock:
            head = self._head
            missed = 0
            oldest = head - self.capacity
            if reader.position < oldest:
                missed = oldest - reader.position
                reader.position = oldest
            n = head - reader.position
            if max_samples is not None:
                n = min(n, max_samples)
            if n <= 0:
                return ReadResult(None, missed)
            idx = (reader.position + np.arange(n)) % self.capacity
            raw = None
            if self._raw is not None and bool(self._has_raw[idx].all()):
                raw = self._raw[idx]
            batch = Batch(self._index[idx], self._t[idx], self._values[idx],
                          self._temp[idx], raw)
            reader.position += n
            return ReadResult(batch, missed)


class RingReader:
    """A consumer's cursor into a :class:`RingBuffer`."""

    def __init__(self, ring: RingBuffer, name: str, position: int) -> None:
        self.ring = ring
        self.name = name
        self.position = position
        self.missed = 0

    @property
    def lag(self) -> int:
        """Samples written but not yet read by this reader."""
        return self.ring.head - self.position

    def read(self, max_samples: int | None = None) -> ReadResult:
        result = self.ring._read(self, max_samples)
        self.missed += result.missed
        return result

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
