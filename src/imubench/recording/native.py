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
(:attr:`NativeReader.damage`, :attr:`NativeReader.damaged`).
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

from imubench.batch import CHANNELS, Batch, Gap, explain_holes
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
        if len(header) < hlen or len(crc) < 4 or struct.unpack("<I", crc)[0] != zlib.crc32(header):
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
        return self.damaged[0] + more

    def batches(self) -> Iterator[Batch]:
        """Yield the data records as Batches (gap records are collected in ``gaps``),
        skipping damaged records (:attr:`damaged`)."""
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
            if kind not in _KINDS:
                problem = f"unknown record kind {kind!r} at byte {offset}"
            elif length > MAX_RECORD_BYTES:
                problem = f"impossible record length {length} at byte {offset}"
            else:
                payload = fh.read(length)
                if len(payload) < length:
                    self.damaged.append(f"truncated record at byte {offset}")
                    return
                if zlib.crc32(payload) != crc:
                    problem = f"CRC mismatch in record at byte {offset}"
                else:
                    problem = self._take(kind, payload, offset)
                    if problem is None and kind == b"D":
                        batch = self._decode(payload)
                        problem = self._out_of_order(batch, offset)
                        if problem is None:
                            if len(batch):
                                self._last_index = int(batch.index[-1])
                            yield batch
            if problem is not None:
                nxt = self._resync(offset + 1)
                if nxt is None:
                    self.damaged.append(f"{problem}; no whole record after it")
                    return
                self.damaged.append(f"{problem}; resumed at byte {nxt}")
                fh.seek(nxt)

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
