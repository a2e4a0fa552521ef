"""Ring buffer: several readers with own cursors, explicit missed counts, thread + asyncio."""

from __future__ import annotations

import asyncio
import threading

import numpy as np
import pytest

from imubench.batch import Batch
from imubench.ringbuffer import RingBuffer


def batch(start: int, n: int, raw: bool = True) -> Batch:
    idx = np.arange(start, start + n, dtype=np.int64)
    r = (idx[:, None] % 1000 + np.arange(6)).astype(np.int16)
    return Batch(idx, idx * 0.01, r.astype(float), np.full(n, 25.0), r if raw else None)


def test_readers_have_independent_cursors_and_see_every_sample_in_order() -> None:
    ring = RingBuffer(100)
    a, b = ring.reader("a"), ring.reader("b")
    ring.write(batch(0, 30))
    ring.write(batch(30, 30))
    ra = a.read()
    assert ra.missed == 0 and ra.batch is not None
    np.testing.assert_array_equal(ra.batch.index, np.arange(60))
    ring.write(batch(60, 10))
    rb1 = b.read(45)
    rb2 = b.read()
    assert rb1.batch is not None and rb2.batch is not None
    np.testing.assert_array_equal(np.concatenate([rb1.batch.index, rb2.batch.index]),
                                  np.arange(70))
    np.testing.assert_array_equal(rb2.batch.raw[:, 0], np.arange(45, 70) % 1000)
    assert a.read().batch.index.tolist() == list(range(60, 70))  # type: ignore[union-attr]


def test_lagging_reader_is_told_exactly_how_many_samples_it_missed() -> None:
    ring = RingBuffer(50)
    slow = ring.reader("slow")
    for k in range(8):
        ring.write(batch(k * 20, 20))  # 160 written, capacity 50
    res = slow.read()
    assert res.missed == 110 and slow.missed == 110
    assert res.batch is not None
    np.testing.assert_array_equal(res.batch.index, np.arange(110, 160))


def test_index_holes_survive_the_ring() -> None:
    ring = RingBuffer(64)
    r = ring.reader("r")
    ring.write(batch(0, 10))
    ring.write(batch(15, 10))  # five lost samples before index 15
    got = r.read().batch
    assert got is not None
    assert got.internal_gaps.tolist() == [[15, 5]]


def test_batch_larger_than_capacity_keeps_newest_and_counts_the_rest() -> None:
    ring = RingBuffer(32)
    r = ring.reader("r")
    ring.write(batch(0, 100))
    res = r.read()
    assert res.missed == 68
    np.testing.assert_array_equal(res.batch.index, np.arange(68, 100))  # type: ignore[union-attr]


@pytest.mark.parametrize("capacity", [256, 40000])
def test_thread_writer_and_asyncio_reader_account_for_every_sample(capacity: int) -> None:
    """Whatever the speeds, every sample is either read (in order) or counted missed."""
    ring = RingBuffer(capacity)
    reader = ring.reader("engine")
    total = 20000

    def produce() -> None:
        for start in range(0, total, 37):
            ring.write(batch(start, min(37, total - start)))
        ring.close()

    async def consume() -> tuple[list[int], int]:
        seen: list[int] = []
        missed = 0
        while True:
            has = await reader.wait_async(1.0)
            res = reader.read(100)
            missed += res.missed
            if res.batch is not None:
                seen.extend(res.batch.index.tolist())
            elif not has and ring.closed:
                return seen, missed

    t = threading.Thread(target=produce)
    t.start()
    seen, missed = asyncio.run(consume())
    t.join()
    assert len(seen) + missed == total
    assert seen == sorted(seen) and len(set(seen)) == len(seen)
    if capacity >= total:
        assert missed == 0 and seen == list(range(total))
