"""What a text recording's ``# key: value`` lines state about how to read it: the sample
rate (or period) and the unit of a headerless file's values, under the names loggers and
other tools write them; and the text encoding of the file.

A rate or unit that a file states is never ignored: one this module cannot read (an
unknown unit, a value that is no number, two keys that disagree) is refused, naming the
key, rather than read at a default rate of 1 Hz (a ``# rate_hz: 100`` file had every
tau 100x long) or in a default unit (``# unit: deg/h`` was read as dps).
"""

from __future__ import annotations

import codecs
import math
import re
from collections.abc import Mapping
from typing import Any

from imubench.errors import RecordingError
from imubench.recording.columns import unit_word
from imubench.recording.options import ACCEL_UNITS_G, GYRO_UNITS_DPS

RATE_KEYS_HZ = frozenset({
    "odr_hz", "odr", "rate_hz", "rate", "sample_rate", "sample_rate_hz", "sampling_rate",
    "sampling_rate_hz", "sampling_frequency", "sampling_frequency_hz", "sample_frequency",
    "sample_frequency_hz", "fs", "fs_hz", "data_rate", "data_rate_hz", "output_data_rate"})
"""Metadata keys (normalised: lower case, ``_`` for blanks and ``-``) stating a rate in Hz
(imubench writes ``odr_hz``)."""
PERIOD_KEYS_S = frozenset({
    "tau0", "tau0_s", "tau_0", "tau_0_s", "dt", "dt_s", "ts", "sample_period",
    "sample_period_s", "sampling_period", "sampling_period_s", "sample_interval",
    "sample_interval_s", "sampling_interval", "sampling_interval_s", "tau", "period",
    "interval", "sampling_time", "sample_time"})
"""Metadata keys stating the sample period in seconds (Stable32's tau0)."""
UNIT_KEYS = frozenset({"unit", "units"})
"""Metadata keys stating the unit of a headerless file's values."""

_RATE_UNITS = {"": 1.0, "hz": 1.0, "khz": 1e3, "mHz": 1e-3, "MHz": 1e6, "s/s": 1.0,
               "sps": 1.0, "samples/s": 1.0, "sa/s": 1.0, "/s": 1.0}
"""Rate units (lower case but for mHz and MHz, told apart by their case: ``# rate: 500 mHz``
was read as 500 MHz)."""
RATE_MAX_HZ = 1e6
"""Largest rate a metadata line may state (as a time column may give, TIME_RATE_HZ)."""
_PERIOD_UNITS = {"": 1.0, "s": 1.0, "sec": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6,
                 "ns": 1e-9}
_VALUE = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([^\s\d].*?)?\s*$")


def normalise_key(key: str) -> str:
    """``Sample Rate`` -> ``sample_rate``."""
    return re.sub(r"[\s\-]+", "_", key.strip().lower())


def split_key_unit(key: str) -> tuple[str, str]:
    """``"Sample Rate (Hz)"`` -> ``("Sample Rate", "Hz")``; a key without a bracketed
    unit -> ``(key, "")``."""
    m = re.match(r"^\s*(.*?)\s*[(\[]\s*([^)\]]*?)\s*[)\]]\s*$", key)
    return (m.group(1), m.group(2)) if m and m.group(1) else (key.strip(), "")


_NUMBER_START = re.compile(r"^(.*?)\s+([-+]?(?:\d|\.\d).*)$")


def rate_line(text: str) -> tuple[str, str] | None:
    """(key, value) of a comment line that states the rate or period in another form than
    ``key: value``: ``Fs=100``, ``fs = 100``, ``sample rate = 100 Hz``, ``rate 100``,
    ``Sample Rate (Hz) = 100``, ``interval 10 ms`` (MATLAB's ``%`` too, the caller strips
    the comment character); None for any other line. Such lines were ignored and the file
    read at 1 Hz without a word."""
    sep = re.search(r"[:=]", text)
    if sep is not None:
        key, value = text[:sep.start()], text[sep.end():]
    else:
        m = _NUMBER_START.match(text.strip())
        if m is None:
            return None
        key, value = m.group(1), m.group(2)
    key, unit = split_key_unit(key)
    value = value.strip()
    if normalise_key(key) not in RATE_KEYS_HZ | PERIOD_KEYS_S or not _VALUE.match(value):
        return None
    return key, value + (f" {unit}" if unit else "")


def _quantity(value: Any, key: str, units: Mapping[str, float], where: str) -> float:
    """A metadata value as a number times its unit's factor (``100``, ``"1 kHz"``,
    ``"10 ms"``); RecordingError naming the key otherwise."""
    if isinstance(value, bool):
        value = str(value)
    if isinstance(value, int | float):
        number, unit = float(value), ""
    else:
        text = str(value).split("#")[0].strip().rstrip(";").strip()  # `100; % Hz`, `100 # Hz`
        m = _VALUE.match(text)
        if not m:
            raise RecordingError(f"{where}: metadata {key} {value!r} is not a number")
        unit = (m.group(2) or "").strip()
        if units is _RATE_UNITS and unit.lower() == "mhz" and unit not in ("mHz", "MHz"):
            raise RecordingError(f"{where}: metadata {key} {value!r}: write mHz "
                                 "(millihertz) or MHz (megahertz)")
        number, unit = float(m.group(1)), unit if unit in ("mHz", "MHz") else unit.lower()
    if unit not in units:
        raise RecordingError(f"{where}: metadata {key} {value!r}: unit {unit!r} is not one "
                             f"of {', '.join(u for u in units if u)}")
    out = number * units[unit]
    if not (math.isfinite(out) and out > 0):
        raise RecordingError(f"{where}: metadata {key} {value!r} must be a positive number")
    hz = out if units is _RATE_UNITS else 1.0 / out
    if hz > RATE_MAX_HZ:
        raise RecordingError(f"{where}: metadata {key} {value!r} states {hz:.4g} Hz, not a "
                             "rate an IMU records at; give --rate HZ")
    return out


def stated_rate(meta: Mapping[str, Any], where: str) -> tuple[float, str] | None:
    """(rate in Hz, the key that states it) from a file's metadata, or None; a period key
    (``tau0``, ``dt``) gives 1/period. RecordingError when a value cannot be read or two
    keys disagree by more than 1e-6 (relative)."""
    found: list[tuple[float, str]] = []
    for key, value in meta.items():
        name = normalise_key(key)
        if name in RATE_KEYS_HZ:
            found.append((_quantity(value, key, _RATE_UNITS, where), key))
        elif name in PERIOD_KEYS_S:
            found.append((1.0 / _quantity(value, key, _PERIOD_UNITS, where), key))
    if not found:
        return None
    rate, key = found[0]
    for other, other_key in found[1:]:
        if abs(other / rate - 1.0) > 1e-6:
            raise RecordingError(
                f"{where}: metadata {key} and {other_key} disagree ({rate:.8g} Hz against "
                f"{other:.8g} Hz); give --rate HZ")
    return rate, key


def stated_unit(meta: Mapping[str, Any], channel: str, where: str) -> tuple[float, str] | None:
    """(factor to dps or g, unit) that a headerless file's ``# unit:`` line states for its
    values (channel ``channel``), or None; RecordingError for a unit that is not one of
    that channel's (a gyro file in ``deg/h`` is read in deg/h, never as dps)."""
    for key, value in meta.items():
        if normalise_key(key) not in UNIT_KEYS:
            continue
        table = GYRO_UNITS_DPS if channel.startswith("g") else ACCEL_UNITS_G
        text = str(value).strip()
        unit = unit_word(text)
        if unit not in table:
            kind = "a gyro" if channel.startswith("g") else "an accelerometer"
            raise RecordingError(
                f"{where}: metadata {key} {text!r} is not {kind} unit ({', '.join(table)}) "
                f"for channel {channel}; give --units GYRO,ACCEL")
        return table[unit], unit
    return None


SNIFF_BYTES = 1 << 16
"""Bytes read at the start of a text file to tell its encoding."""


def text_encoding(head: bytes) -> str:
    """The encoding of a text file from its first bytes: ``utf-16`` after a UTF-16
    byte-order mark (Windows' "Unicode" text), ``utf-8-sig`` when the bytes are UTF-8 (a
    multi-byte character cut at the end of ``head`` allowed), else ``cp1252`` (a Windows
    logger's ``°/s`` is one byte, 0xB0, that UTF-8 cannot decode)."""
    if head.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        return "utf-16"
    try:
        codecs.getincrementaldecoder("utf-8")().decode(head, final=False)
    except UnicodeDecodeError:
        return "cp1252"
    return "utf-8-sig"
