"""The plain ASCII output of ST's STSW-STLKT01 "DataLog" application (fallback mode).

Reference: ``lsm6ds-registers.md`` §14.B (DataLog V2.0.0, 27-Apr-2017). Each record is a
block of five CRLF-terminated lines, lines 2-5 starting with a space::

    TimeStamp: 1234567
     Acc_X: 12, Acc_Y: -3, Acc_Z :1001
     Gyro_X:150, Gyro_Y:-280, Gyro_Z:70
     Magn_X:-200, Magn_Y:110, Magn_Z:-420
     Press:1013.25, Temp:25.00, Hum:45.0

TimeStamp is milliseconds since boot (HAL tick); integers are mg / mdps / mgauss. The
parser is tolerant (regex on ``name\\s*:\\s*value``), incremental, and resynchronises on the
next ``TimeStamp:`` line. There is no checksum in this mode: a damaged digit that still
reads as a number cannot be detected; only damaged structure is.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass

DATA_PERIOD_MS = 20
"""Record period of the default DataLog build (50 Hz; 40 ms and 10 ms builds exist)."""

_NUM = r"(-?\d+(?:\.\d+)?)"
_LINE_PATTERNS: tuple[tuple[str, re.Pattern[str]], ...] = (
    ("time", re.compile(r"^TimeStamp\s*:\s*(\d+)$")),
    ("acc", re.compile(rf"^Acc_X\s*:\s*{_NUM}\s*,\s*Acc_Y\s*:\s*{_NUM}\s*,\s*Acc_Z\s*:\s*{_NUM}$")),
    (
        "gyro",
        re.compile(rf"^Gyro_X\s*:\s*{_NUM}\s*,\s*Gyro_Y\s*:\s*{_NUM}\s*,\s*Gyro_Z\s*:\s*{_NUM}$"),
    ),
    (
        "mag",
        re.compile(rf"^Magn_X\s*:\s*{_NUM}\s*,\s*Magn_Y\s*:\s*{_NUM}\s*,\s*Magn_Z\s*:\s*{_NUM}$"),
    ),
    ("env", re.compile(rf"^Press\s*:\s*{_NUM}\s*,\s*Temp\s*:\s*{_NUM}\s*,\s*Hum\s*:\s*{_NUM}$")),
)
_ORDER = tuple(name for name, _ in _LINE_PATTERNS)
MAX_LINE_LEN = 256


@dataclass(frozen=True)
class DataLogRecord:
    """One five-line DataLog record (values as printed)."""

    timestamp_ms: int
    accel_mg: tuple[int, int, int]
    gyro_mdps: tuple[int, int, int]
    mag_mgauss: tuple[int, int, int]
    pressure_hpa: float
    temperature_c: float
    humidity_pct: float

    def format(self) -> bytes:
        """The record as the firmware prints it (``sprintf`` formats of §14.B)."""
        a, g, m = self.accel_mg, self.gyro_mdps, self.mag_mgauss
        text = (
            f"TimeStamp: {self.timestamp_ms}\r\n"
            f" Acc_X: {a[0]}, Acc_Y: {a[1]}, Acc_Z :{a[2]}\r\n"
            f" Gyro_X:{g[0]}, Gyro_Y:{g[1]}, Gyro_Z:{g[2]}\r\n"
            f" Magn_X:{m[0]}, Magn_Y:{m[1]}, Magn_Z:{m[2]}\r\n"
            f" Press:{self.pressure_hpa:5.2f}, Temp:{self.temperature_c:5.2f}, "
            f"Hum:{self.humidity_pct:4.1f}\r\n"
        )
        return text.encode("ascii")


@dataclass(frozen=True)
class BadRecord:
    """Lines that did not form a record, and why."""

    reason: str
    text: bytes


def _ints(values: tuple[str, ...]) -> tuple[int, int, int]:
    return (int(values[0]), int(values[1]), int(values[2]))


class DataLogParser:
    """Incremental parser: ``feed(bytes)`` yields :class:`DataLogRecord` / :class:`BadRecord`.

    Any line out of order, unparsable or over-long discards the partial record (one
    :class:`BadRecord`); parsing restarts at the next ``TimeStamp:`` line. Bytes before
    the first ``TimeStamp:`` line after opening are skipped silently (``skipped_lines``).
    """

    def __init__(self) -> None:
        self._line = bytearray()
        self._fields: dict[str, tuple[str, ...]] = {}
        self._raw = bytearray()
        self._synced = False
        self.records = 0
        self.bad_records = 0
        self.skipped_lines = 0

    def reset(self) -> None:
        self._line.clear()
        self._fields.clear()
        self._raw.clear()
        self._synced = False

    def feed(self, data: bytes) -> Iterator[DataLogRecord | BadRecord]:
        start = 0
        while True:
            end = data.find(b"\n", start)
            if end < 0:
                self._line += data[start:]
                if len(self._line) > MAX_LINE_LEN:
                    self._line.clear()
                    bad = self._fail("line longer than the longest DataLog line")
                    if bad is not None:
                        yield bad
                return
            self._line += data[start : end + 1]
            start = end + 1
            line = bytes(self._line)
            self._line.clear()
            out = self._line_done(line)
            if out is not None:
                yield out

    def _fail(self, reason: str) -> BadRecord | None:
        had = bool(self._fields) or self._synced
        raw = bytes(self._raw)
        self._fields.clear()
        self._raw.clear()
        self._synced = False
        if not had:
            return None
        self.bad_records += 1
        return BadRecord(reason, raw)

    def _line_done(self, line: bytes) -> DataLogRecord | BadRecord | None:
        try:
            text = line.decode("ascii").strip()
        except UnicodeDecodeError:
            text = "\x00"  # matches no pattern
        if not text:
            return None
        expected = _ORDER[len(self._fields)]
        pattern = dict(_LINE_PATTERNS)[expected]
        match = pattern.match(text)
        bad: BadRecord | None = None
        if match is None:
            time_match = _LINE_PATTERNS[0][1].match(text)
            if self._fields or self._synced:
                bad = self._fail(f"expected the {expected!r} line, got {text[:40]!r}")
            else:
                self.skipped_lines += 1
            if time_match is None:
                return bad
            match, expected = time_match, "time"
        self._synced = True
        self._raw += line
        self._fields[expected] = match.groups()
        if len(self._fields) < len(_ORDER):
            return bad
        f = self._fields
        try:
            record = DataLogRecord(
                timestamp_ms=int(f["time"][0]),
                accel_mg=_ints(f["acc"]),
                gyro_mdps=_ints(f["gyro"]),
                mag_mgauss=_ints(f["mag"]),
                pressure_hpa=float(f["env"][0]),
                temperature_c=float(f["env"][1]),
                humidity_pct=float(f["env"][2]),
            )
        except ValueError as exc:  # a float where an integer belongs
            return self._fail(f"bad number in record: {exc}")
        self._fields.clear()
        self._raw.clear()
        self.records += 1
        return record if bad is None else bad
