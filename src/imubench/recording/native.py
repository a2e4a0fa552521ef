"""The native recording format (``.imbr``): append-only, crash-safe, self-describing.

Layout (all integers little-endian)::

    file    := MAGIC header record*
    MAGIC   := b"IMBR" u16 version(=1) b"\\r\\n"          (8 bytes)
    header  := u32 length, JSON metadata (UTF-8, `length` bytes), u32 crc32(JSON)
    record  := u8 kind, u32 length, u32 crc32(payload), payload (`length` bytes)

Record kinds:

* ``D`` data: ``u32 n``, then ``index int64[n]``, ``t_s float64[n]``,
  ``temp_c float32[n]`` (NaN = not measured), then the samples: ``int16[n, 6]`` raw
  counts when the header says ``"storage": "raw_int16"`` (scaled values are
  ``raw * sensitivity`` per the header), else ``float64[n, 6]`` scaled values
  (``"storage": "float64"``). Channel order gx gy gz ax ay az (dps, g).
* ``G`` gap: ``int64 at_index``, ``int64 lost``, UTF-8 reason. Written when a source
  reports lost samples; the hole is also visible in the data's sample indices.
* ``E`` end: JSON ``{"samples": n, "gaps": k, "lost_samples": l, "stopped_utc": ...}``
  written by a clean close. Its absence means the writer died; everything before the
  first incomplete record is still read.

The header's JSON metadata holds: ``format``, ``version``, ``chip``, ``odr_hz``,
``fs_dps``, ``fs_g``, ``gyro_sensitivity_dps`` and ``accel_sensitivity_g`` (per LSB),
``channels``, ``storage``, ``start_utc``, ``source_uri``, ``config`` (the daemon's
configuration) and any extra keys the writer was given.

Crash safety: records are written whole with one ``write`` call and flushed; ``fsync``
runs at least every ``fsync_interval_s``. A batch that cannot be written whole (disk
full, I/O error) is taken back: the file is cut to the end of the last whole batch
(:func:`imubench.recording.commit.cut_back`) and the error raised, so the file never ends
in a partial record and the caller counts exactly that batch as not recorded.
A reader never returns data from a damaged record: a record that fails its CRC (or whose
length or sample count is impossible) is skipped, and reading resumes at the next byte
offset where a whole record with a valid CRC starts (a false match has probability 2^-32
per candidate), so a flipped bit loses that one record; a truncated tail ends the
reading. Each is reported
(:attr:`NativeReader.damage`, :attr:`NativeReader.damaged`), and the samples a skipped
stretch held become gaps with the reason :data:`DAMAGED_RECORD` at their true place
(:meth:`NativeReader.batches`): kept + lost = what the writer produced.
"""

from __future__ import annotations

import contextlib
import heapq
import json
import os
import struct
import time
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from imubench.batch import CHANNELS, Batch, Gap, explain_holes, index_holes
from imubench.errors import RecordingError
from imubench.recording.commit import cut_back, need_parent
from imubench.recording.timebase import utc_now

MAGIC = b"IMBR"
VERSION = 1
_PREAMBLE = MAGIC + struct.pack("<H", VERSION) + b"\r\n"
_REC = struct.Struct("<cII")
MAX_RECORD_BYTES = 1 << 26
"""Largest record a reader accepts (64 MiB; writers emit at most a few MiB): a corrupted
length field beyond it is damage, not a reason to read gigabytes."""
_KINDS = (b"D", b"G", b"E")
DAMAGED_RECORD = "damaged record"
"""Gap reason of the samples a reader skipped with a damaged record (a data record that
failed its CRC, or a gap record whose own reason was lost with it)."""
STORAGE_RAW = "raw_int16"
STORAGE_FLOAT = "float64"


class NativeWriter:
    """Append-only writer of ``.imbr`` recordings."""

    def __init__(
        self,
        path: str | Path,
        metadata: dict[str, Any],
        *,
        fsync_interval_s: float = 1.0,
    ) -> None:
        self.path = Path(path)
        self.metadata = dict(metadata)
        self.metadata.setdefault("format", "imubench-native")
        self.metadata.setdefault("version", VERSION)
        self.metadata.setdefault("start_utc", utc_now())
        self.metadata.setdefault("channels", list(CHANNELS))
        storage = self.metadata.setdefault("storage", STORAGE_FLOAT)
        if storage not in (STORAGE_RAW, STORAGE_FLOAT):
            raise RecordingError(f"{self.path}: unknown storage {storage!r}")
        if storage == STORAGE_RAW and (
            self.metadata.get("gyro_sensitivity_dps") is None
            or self.metadata.get("accel_sensitivity_g") is None
        ):
            raise RecordingError(
                f"{self.path}: raw_int16 storage needs gyro_sensitivity_dps and "
                "accel_sensitivity_g in the metadata"
            )
        self.fsync_interval_s = fsync_interval_s
        self.samples = 0
        self.gaps = 0
        self.lost_samples = 0
        self._last_index: int | None = None
        self._last_sync = time.monotonic()
        need_parent(self.path)
        try:
            self._fh: BinaryIO | None = open(self.path, "xb")  # noqa: SIM115
        except FileExistsError:
            raise RecordingError(
                f"{self.path}: exists already; recordings are never overwritten"
            ) from None
        header = json.dumps(self.metadata, sort_keys=True, default=str).encode()
        self._fh.write(
            _PREAMBLE + struct.pack("<I", len(header)) + header
            + struct.pack("<I", zlib.crc32(header))
        )
        self._sync(force=True)
        self._committed = os.fstat(self._fh.fileno()).st_size

    @property
    def storage(self) -> str:
        return str(self.metadata["storage"])

    def _record(self, kind: bytes, payload: bytes) -> None:
        if self._fh is None:
            raise RecordingError(f"{self.path}: writer is closed")
        self._fh.write(_REC.pack(kind, len(payload), zlib.crc32(payload)) + payload)
        self._sync()

    def _sync(self, force: bool = False) -> None:
        assert self._fh is not None
        self._fh.flush()
        now = time.monotonic()
        if force or now - self._last_sync >= self.fsync_interval_s:
            os.fsync(self._fh.fileno())
            self._last_sync = now

    def write(self, batch: Batch) -> None:
        """Append a batch; every hole before and inside it becomes a gap record first,
        with the reason its :class:`~imubench.batch.Gap` declares
        (:func:`~imubench.batch.explain_holes`). A batch without samples writes its gaps
        (a stream that ended in a hole)."""
        n = len(batch)
        if n and self._last_index is not None and int(batch.index[0]) <= self._last_index:
            raise RecordingError(
                f"{self.path}: sample index {int(batch.index[0])} does not follow "
                f"{self._last_index}"
            )
        with self._all_or_nothing():
            self._write(batch, n)

    def _write(self, batch: Batch, n: int) -> None:
        for gap in explain_holes(batch, self._last_index):
            self._gap(gap.at, gap.lost, gap.reason)
        if n == 0:
            return
        if self.storage == STORAGE_RAW:
            if batch.raw is None:
                raise RecordingError(f"{self.path}: raw_int16 storage but batch has no raw counts")
            samples = np.ascontiguousarray(batch.raw, dtype="<i2").tobytes()
        else:
            samples = np.ascontiguousarray(batch.values, dtype="<f8").tobytes()
        payload = b"".join((
            struct.pack("<I", n),
            np.ascontiguousarray(batch.index, dtype="<i8").tobytes(),
            np.ascontiguousarray(batch.t_s, dtype="<f8").tobytes(),
            np.ascontiguousarray(batch.temp_c, dtype="<f4").tobytes(),
            samples,
        ))
        self._record(b"D", payload)
        self.samples += n
        self._last_index = int(batch.index[-1])

    def write_gap(self, at_index: int, lost: int, reason: str) -> None:
        """Record ``lost`` samples missing before ``at_index`` (explicit gap)."""
        with self._all_or_nothing():
            self._gap(at_index, lost, reason)

    def _gap(self, at_index: int, lost: int, reason: str) -> None:
        self._record(b"G", struct.pack("<qq", at_index, lost) + reason.encode())
        self.gaps += 1
        self.lost_samples += lost

    @contextlib.contextmanager
    def _all_or_nothing(self) -> Iterator[None]:
        """Commit what the block writes, or take it all back (counters and bytes)."""
        if self._fh is None:
            raise RecordingError(f"{self.path}: writer is closed")
        counts = (self.samples, self.gaps, self.lost_samples, self._last_index)
        try:
            yield
        except OSError:
            fh, self._fh = self._fh, None
            self.samples, self.gaps, self.lost_samples, self._last_index = counts
            cut_back(self.path, fh, self._committed)
            raise
        self._committed = os.fstat(self._fh.fileno()).st_size

    def close(self) -> None:
        if self._fh is None:
            return
        end = {
            "samples": self.samples, "gaps": self.gaps, "lost_samples": self.lost_samples,
            "stopped_utc": utc_now(),
        }
        with self._all_or_nothing():
            self._record(b"E", json.dumps(end).encode())
            self._sync(force=True)
        fh, self._fh = self._fh, None
        if fh is not None:
            fh.close()

    def __enter__(self) -> NativeWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _covered(gaps: list[Gap]) -> list[tuple[int, int]]:
    """The ``[start, end)`` sample indices the gaps declare lost, sorted by start; gaps
    sharing ``at`` are adjacent holes (:func:`~imubench.batch.gaps_before`)."""
    total: dict[int, int] = {}
    for g in gaps:
        total[g.at] = total.get(g.at, 0) + g.lost
    return sorted((at - lost, at) for at, lost in total.items())


def _uncovered(lo: int, hi: int, covered: list[tuple[int, int]]) -> list[tuple[int, int]]:
    """The parts of ``[lo, hi)`` outside the ``covered`` intervals (sorted by start)."""
    out: list[tuple[int, int]] = []
    pos = lo
    for a, b in covered:
        if b <= pos:
            continue
        if a >= hi:
            break
        if a > pos:
            out.append((pos, a))
        pos = b
    if pos < hi:
        out.append((pos, hi))
    return out


def _less(held: list[int | None], exact: list[Gap]) -> int | None:
    """Samples of the skipped records (``held``, None: not known) that ``exact`` gaps do
    not place already; None when not known."""
    if any(h is None for h in held):
        return None
    return max(sum(h for h in held if h is not None) - sum(g.lost for g in exact), 0)


def _damaged_gaps(lo: int, hi: int, covered: list[tuple[int, int]]) -> list[Gap]:
    """A :data:`DAMAGED_RECORD` gap for each part of ``[lo, hi)`` that no gap covers."""
    return [Gap(b, b - a, DAMAGED_RECORD) for a, b in _uncovered(lo, hi, covered)]


def _find_all(data: bytes, needle: bytes) -> Iterator[int]:
    i = data.find(needle)
    while i >= 0:
        yield i
        i = data.find(needle, i + 1)


class NativeReader:
    """Reads ``.imbr`` files; tolerant of a crashed writer's truncated tail."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.damaged: list[str] = []
        """Every damaged or truncated stretch, in file order (what was skipped)."""
        self._last_index: int | None = None  # of the last data record taken
        self.end: dict[str, Any] | None = None
        self.gaps: list[Gap] = []
        self._first_index: int | None = None  # of the first data record taken
        self._taken = 0  # data records taken (with samples)
        self._kept = 0  # samples taken
        self._holes: list[tuple[int, int]] = []  # [start, end) sample indices not taken
        self._stretches: list[tuple[int, int | None]] = []
        """Each damaged stretch skipped: (data records taken before it, samples its
        records held by their own lengths, None when that is not known)."""
        self._uncounted: list[str] = []  # losses that could not be counted, said
        try:
            self._fh: BinaryIO = open(self.path, "rb")  # noqa: SIM115
        except OSError as exc:
            raise RecordingError(f"{self.path}: cannot open recording: {exc.strerror}") from None
        pre = self._fh.read(len(_PREAMBLE))
        if pre[:4] != MAGIC:
            raise RecordingError(f"{self.path}: not an imubench native recording (bad magic)")
        (version,) = struct.unpack("<H", pre[4:6])
        if version != VERSION:
            raise RecordingError(f"{self.path}: format version {version} is not supported")
        raw_len = self._fh.read(4)
        if len(raw_len) < 4:
            raise RecordingError(f"{self.path}: truncated header")
        (hlen,) = struct.unpack("<I", raw_len)
        header = self._fh.read(hlen)
        crc = self._fh.read(4)
        if len(header) < hlen or len(crc) < 4:  # a file cut inside its header
            raise RecordingError(
                f"{self.path}: truncated header ({len(_PREAMBLE) + 4 + len(header) + len(crc)} "
                f"of {len(_PREAMBLE) + 8 + hlen} bytes: the file was cut, e.g. by a crash "
                "right after it was created)")
        if struct.unpack("<I", crc)[0] != zlib.crc32(header):
            raise RecordingError(f"{self.path}: header damaged (byte offset {len(_PREAMBLE)})")
        self.metadata: dict[str, Any] = json.loads(header)
        storage = self.metadata.get("storage")
        if storage not in (STORAGE_RAW, STORAGE_FLOAT):
            raise RecordingError(f"{self.path}: header field 'storage' is {storage!r}")
        self.storage = storage
        self._scale = None
        if storage == STORAGE_RAW:
            g = float(self.metadata["gyro_sensitivity_dps"])
            a = float(self.metadata["accel_sensitivity_g"])
            self._scale = np.array([g, g, g, a, a, a])

    def close(self) -> None:
        self._fh.close()

    def __enter__(self) -> NativeReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def damage(self) -> str | None:
        """The damage found, in one line (None for an intact file)."""
        if not self.damaged:
            return None
        more = f" (and {len(self.damaged) - 1} more)" if len(self.damaged) > 1 else ""
        return "; ".join([self.damaged[0] + more, *self._uncounted])

    def batches(self) -> Iterator[Batch]:
        """Yield the data records as Batches (gap records are collected in ``gaps``),
        skipping damaged records (:attr:`damaged`). Once the last is read, the samples
        the skipped records held are in ``gaps`` too (:meth:`_account_damage`), so that
        the samples read plus the gaps' ``lost`` are every sample the writer produced."""
        yield from self._records()
        self._account_damage()

    def _records(self) -> Iterator[Batch]:
        """The data records that are whole and in order, in file order."""
        fh = self._fh
        while True:
            offset = fh.tell()
            head = fh.read(_REC.size)
            if not head:
                return
            if len(head) < _REC.size:
                self.damaged.append(f"truncated record header at byte {offset}")
                return
            kind, length, crc = _REC.unpack(head)
            problem = None
            resumed: int | None = -1  # the next whole record once searched (-1: not yet)
            held_from = offset  # where the samples of the skipped stretch are counted from
            if kind not in _KINDS:
                problem = f"unknown record kind {kind!r} at byte {offset}"
            elif length > MAX_RECORD_BYTES:
                problem = f"impossible record length {length} at byte {offset}"
            else:
                payload = fh.read(length)
                if len(payload) < length:
                    resumed = self._resync(offset + 1)
                    if resumed is None:  # a crashed writer's tail: nothing whole after it
                        self.damaged.append(f"truncated record at byte {offset}")
                        return
                    # whole records follow (the whole file was lost to such a length)
                    problem = (f"record at byte {offset} claims {length} bytes, past the "
                               "end of the file (damaged length)")
                elif zlib.crc32(payload) != crc:
                    problem = f"CRC mismatch in record at byte {offset}"
                else:
                    problem = self._take(kind, payload, offset)
                    if problem is None and kind == b"D":
                        batch = self._decode(payload)
                        problem = self._out_of_order(batch, offset)
                        if problem is None:
                            self._took(batch)
                            yield batch
                        elif "repeated or out of order" in problem:
                            # whole samples, read already or placed by the indices
                            held_from = offset + _REC.size + length
            if problem is not None:
                nxt = self._resync(offset + 1) if resumed == -1 else resumed
                stop = os.fstat(fh.fileno()).st_size if nxt is None else nxt
                self._stretches.append((self._taken, self._held(held_from, stop)))
                if nxt is None:
                    self.damaged.append(f"{problem}; no whole record after it")
                    return
                self.damaged.append(f"{problem}; resumed at byte {nxt}")
                fh.seek(nxt)

    def _took(self, batch: Batch) -> None:
        """Note a data record taken: its samples and the holes before and inside it."""
        if not len(batch):
            return
        self._holes += index_holes(batch.index, self._last_index)
        if self._first_index is None:
            self._first_index = int(batch.index[0])
        self._last_index = int(batch.index[-1])
        self._taken += 1
        self._kept += len(batch)

    def _held(self, start: int, stop: int) -> int | None:
        """Samples held by the records in bytes ``[start, stop)`` (a skipped stretch),
        read from their own length fields, or None when that cannot be known: the
        lengths must chain from ``start`` exactly to ``stop`` (the next whole record, or
        the end of the file), so they were not what was damaged, and each record must be
        a data record of whole samples (an unknown kind only when its sample count field
        agrees) or an end record (none); a damaged gap record's count is lost with it."""
        fh = self._fh
        fh.seek(start)
        data = fh.read(stop - start)
        per = 8 + 8 + 4 + 6 * (2 if self.storage == STORAGE_RAW else 8)
        pos, held = 0, 0
        while pos < len(data):
            if pos + _REC.size > len(data):
                return None
            kind, length, _ = _REC.unpack_from(data, pos)
            end = pos + _REC.size + length
            if end > len(data):
                return None
            n, part = divmod(length - 4, per)
            counted = struct.unpack_from("<I", data, pos + _REC.size)[0] if length >= 4 else -1
            samples = n > 0 and not part and (kind == b"D" or (kind not in _KINDS
                                                               and counted == n))
            if kind != b"E" and not samples:
                return None
            held += n if samples else 0
            pos = end
        return held

    def _account_damage(self) -> None:
        """Add the samples of the skipped stretches to ``gaps`` as :data:`DAMAGED_RECORD`
        gaps at their true place; what cannot be counted is said in :attr:`damage`.

        Between two records taken, a stretch's samples are the part of the hole in the
        sample indices that no gap record covers (gap records sharing ``at`` are adjacent
        holes, :func:`~imubench.batch.gaps_before`): exact, whatever the damage hit. Before
        the first record taken and after the last one the indices bound only the part
        between them and the gap records there; the rest is counted from the end record
        (the writer's ``samples + lost_samples`` less what was read and declared), else
        from the skipped records' own lengths (:meth:`_held`). Left out, a damaged first
        record's samples were counted nowhere, and a damaged record between two others
        was a hole that a conversion wrote as ``unexplained``."""
        if not self._stretches:
            return
        covered = _covered(self.gaps)
        new: list[Gap] = []
        for lo, hi in self._holes:
            new += _damaged_gaps(lo, hi, covered)
        lead = [held for taken, held in self._stretches if taken == 0]
        tail = [held for taken, held in self._stretches if taken == self._taken]
        first, last = self._first_index, self._last_index
        # each end with damage: (what to call it, its count by the records' lengths, the
        # index its uncounted samples end at (before) or start at (after), before?)
        ends: list[tuple[str, int | None, int, bool]] = []
        if first is not None and lead:
            ahead = [(a, b) for a, b in covered if b <= first]
            start = min([a for a, _ in ahead], default=first)
            exact = _damaged_gaps(start, first, ahead)
            new += exact
            ends.append((f"before sample {first}", _less(lead, exact), start, True))
        if tail:  # (every stretch, when no record was taken)
            behind = [(a, b) for a, b in covered if last is None or a > last]
            base = 0 if last is None else last + 1
            stop = max([b for _, b in behind], default=base)
            exact = _damaged_gaps(base, stop, behind)
            new += exact
            what = "in the file" if last is None else f"after sample {last}"
            ends.append((what, _less(tail, exact), stop, False))
        counts = self._end_counts(ends, self._kept + sum(g.lost for g in [*self.gaps, *new]))
        for (_, _, at, before), count in zip(ends, counts, strict=True):
            if count > 0:
                new.append(Gap(at, count, DAMAGED_RECORD) if before
                           else Gap(at + count, count, DAMAGED_RECORD))
        if new:
            self.gaps = sorted([*self.gaps, *new], key=lambda g: g.at)

    def _end_counts(self, ends: list[tuple[str, int | None, int, bool]],
                    known: int) -> list[int]:
        """The samples lost in damaged records at each of ``ends`` (before the first
        record taken, after the last) that the indices do not bound; ``known``: samples
        read plus lost in gaps so far. Said in :attr:`damage` when not known."""
        end = self.end if isinstance(self.end, dict) else {}
        samples, lost = end.get("samples"), end.get("lost_samples")
        if not (isinstance(samples, int) and isinstance(lost, int)):  # by the lengths
            for what, held, _, _ in ends:
                if held is None:
                    self._uncounted.append(
                        f"the samples of the damaged record(s) {what} are not counted (no "
                        "end record, and their lengths are damaged)")
            return [held or 0 for _, held, _, _ in ends]
        total = max(samples + lost - known, 0)
        if not ends:
            if total:
                self._uncounted.append(f"the end record counts {total} samples more than "
                                       "were read or declared; they are in no gap")
            return []
        if len(ends) == 1:
            return [total]
        (_, lead, start, _), (_, tail, _, _) = ends
        if lead is None and tail is None:  # indices start at 0: at most ``start`` before
            ahead = min(total, max(start, 0))
            self._uncounted.append(f"{total} samples lost in damaged records at both ends, "
                                   f"split {ahead} before and {total - ahead} after (a guess)")
            return [ahead, total - ahead]
        if lead is not None:
            return [min(lead, total), total - min(lead, total)]
        assert tail is not None
        return [total - min(tail, total), min(tail, total)]

    def read_all(self) -> Batch:
        """Every data record (:meth:`batches`) as one Batch. The arrays are sized once
        from the file's length (no record holds more samples than its bytes allow) and
        filled in place: a long recording takes its arrays' memory once, where a list of
        batches and their join took it twice."""
        width = 2 if self.storage == STORAGE_RAW else 8
        cap = os.fstat(self._fh.fileno()).st_size // (8 + 8 + 4 + 6 * width)
        index = np.empty(cap, np.int64)
        t_s = np.empty(cap)
        temp = np.empty(cap)
        values = np.empty((cap, 6))
        raw = np.empty((cap, 6), np.int16) if self.storage == STORAGE_RAW else None
        n = 0
        for b in self.batches():
            k = len(b)
            index[n:n + k] = b.index
            t_s[n:n + k] = b.t_s
            temp[n:n + k] = b.temp_c
            values[n:n + k] = b.values
            if raw is not None and b.raw is not None:  # every record holds counts
                raw[n:n + k] = b.raw
            n += k
        return Batch(index[:n], t_s[:n], values[:n], temp[:n],
                     None if raw is None else raw[:n])

    def _out_of_order(self, batch: Batch, offset: int) -> str | None:
        """Why a data record that passed its CRC is still not taken: its sample indices
        do not increase, or do not follow the last record taken (a record written twice,
        or records swapped: read as they came, 288 samples were duplicated and the lost
        count was off), else None. Its samples then count as lost, in the open."""
        if len(batch) == 0:
            return None
        if np.any(np.diff(batch.index) <= 0):
            return f"data record at byte {offset} has sample indices that do not increase"
        if self._last_index is not None and int(batch.index[0]) <= self._last_index:
            return (f"data record at byte {offset} holds samples {int(batch.index[0])}-"
                    f"{int(batch.index[-1])}, not after {self._last_index} (repeated or out "
                    "of order)")
        return None

    def _take(self, kind: bytes, payload: bytes, offset: int) -> str | None:
        """Check a record that passed its CRC; take gap and end records. A problem
        description, or None."""
        if kind == b"D":
            if len(payload) < 4:
                return f"data record at byte {offset} too short"
            (n,) = struct.unpack_from("<I", payload)
            width = 2 if self.storage == STORAGE_RAW else 8
            expected = 4 + n * (8 + 8 + 4 + 6 * width)
            if len(payload) != expected:
                return (f"data record at byte {offset} has {len(payload)} bytes, expected "
                        f"{expected} for {n} samples")
        elif kind == b"G":
            if len(payload) < 16:
                return f"gap record at byte {offset} too short"
            at, lost = struct.unpack_from("<qq", payload)
            self.gaps.append(Gap(at, lost, payload[16:].decode(errors="replace")))
        else:
            try:
                self.end = json.loads(payload)
            except ValueError:
                return f"end record at byte {offset} is not JSON"
        return None

    def _resync(self, start: int) -> int | None:
        """The first byte offset at or after ``start`` where a whole record with a valid
        CRC begins (None if there is none)."""
        fh = self._fh
        fh.seek(start)
        rest = fh.read()
        for i in heapq.merge(*(_find_all(rest, k) for k in _KINDS)):
            if i + _REC.size > len(rest):
                break
            _, length, crc = _REC.unpack_from(rest, i)
            end = i + _REC.size + length
            if length <= MAX_RECORD_BYTES and end <= len(rest) and zlib.crc32(
                    rest[i + _REC.size:end]) == crc:
                return start + i
        return None

    def _decode(self, payload: bytes) -> Batch:
        (n,) = struct.unpack_from("<I", payload)
        pos = 4
        index = np.frombuffer(payload, "<i8", n, pos).astype(np.int64)
        pos += 8 * n
        t_s = np.frombuffer(payload, "<f8", n, pos).astype(np.float64)
        pos += 8 * n
        temp = np.frombuffer(payload, "<f4", n, pos).astype(np.float64)
        pos += 4 * n
        if self._scale is not None:
            raw = np.frombuffer(payload, "<i2", 6 * n, pos).reshape(n, 6).astype(np.int16)
            values = raw * self._scale
        else:
            raw = None
            values = np.frombuffer(payload, "<f8", 6 * n, pos).reshape(n, 6).astype(np.float64)
        return Batch(index=index, t_s=t_s, values=values, temp_c=temp, raw=raw)
