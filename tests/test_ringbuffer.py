"""Ring buffer: several readers with own cursors, explicit missed counts, thread + asyncio."""

from __future__ import annotations

import asyncio
import threading

import numpy as np
import pytest

from imubench.batch import UNEXPLAINED, Batch, Gap, explain_holes
from imubench.ringbuffer import RingBuffer


def batch(start: int, n: int, raw: bool = True, gaps: tuple[Gap, ...] = ()) -> Batch:
    idx = np.arange(start, start + n, dtype=np.int64)
    r = (idx[:, None] % 1000 + np.arange(6)).astype(np.int16)
    return Batch(idx, idx * 0.01, r.astype(float), np.full(n, 25.0), r if raw else None,
                 gaps)


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


def test_index_holes_and_their_reasons_survive_the_ring() -> None:
    ring = RingBuffer(64)
    r = ring.reader("r")
    ring.write(batch(0, 10))
    ring.write(batch(15, 10, gaps=(Gap(15, 5, "fifo overrun"),)))
    got = r.read().batch
    assert got is not None
    assert got.gaps == (Gap(15, 5, "fifo overrun"),)
    assert explain_holes(got, None) == [Gap(15, 5, "fifo overrun")]


def test_a_lagging_reader_gets_the_gaps_it_skipped_and_its_own_overrun_gap() -> None:
    ring = RingBuffer(50)
    slow = ring.reader("slow")
    fast = ring.reader("fast")
    ring.write(batch(0, 20))
    assert fast.read().batch is not None
    ring.write(batch(23, 20, gaps=(Gap(23, 3, "chip reset"),)))
    ring.write(batch(43, 60))  # 100 samples written: the slow reader is 100 behind a 50 ring
    res = slow.read()
    assert res.missed == 50 and res.batch is not None
    assert int(res.batch.index[0]) == 53
    explained = explain_holes(res.batch, None)
    # at the start of its stream a reader takes the declared gaps as they come
    assert Gap(23, 3, "chip reset") in explained
    assert Gap(53, 50, "consumer overrun: slow") in explained
    # a reader that had seen sample 19 explains the whole hole 20..55 with both reasons
    again = RingBuffer(50)
    r = again.reader("r")
    again.write(batch(0, 20))
    first = r.read().batch
    assert first is not None
    again.write(batch(23, 20, gaps=(Gap(23, 3, "chip reset"),)))
    again.write(batch(43, 60))
    res = r.read()
    assert res.batch is not None
    gaps = explain_holes(res.batch, int(first.index[-1]))
    assert sorted((g.reason, g.lost) for g in gaps) == [
        ("chip reset", 3), ("consumer overrun: r", 30)]
    assert all(g.at == 53 for g in gaps)
    assert UNEXPLAINED not in {g.reason for g in gaps}


def test_blocking_ring_paces_the_writer_by_the_slowest_reader_and_drops_nothing() -> None:
    ring = RingBuffer(64, blocking=True)
    reader = ring.reader("slow")
    total = 5000
    seen: list[int] = []

    def consume() -> None:
        while True:
            res = reader.read(7)
            assert res.missed == 0
            if res.batch is None:
                if reader.finished:
                    return
                reader.wait(0.01)
                continue
            seen.extend(res.batch.index.tolist())

    t = threading.Thread(target=consume)
    t.start()
    for start in range(0, total, 100):  # batches larger than the ring are split
        assert ring.write(batch(start, 100))
    ring.close()
    t.join(10)
    assert seen == list(range(total))


def test_blocking_write_gives_up_when_stopped() -> None:
    ring = RingBuffer(16, blocking=True)
    ring.reader("never reads")
    stop = threading.Event()
    stop.set()
    assert ring.write(batch(0, 16))
    assert not ring.write(batch(16, 4), stop)
    assert ring.head == 16


def test_gaps_at_the_end_of_a_stream_reach_every_reader_once() -> None:
    ring = RingBuffer(32)
    r = ring.reader("r")
    ring.write(batch(0, 10))
    ring.write(Batch.empty(with_raw=True, gaps=(Gap(14, 4, "chip reset"),)))
    ring.close()
    first = r.read()
    assert first.batch is not None and len(first.batch) == 10 and not first.batch.gaps
    end = r.read()
    assert end.batch is not None and len(end.batch) == 0
    assert end.batch.gaps == (Gap(14, 4, "chip reset"),)
    assert r.read().batch is None and r.finished


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
