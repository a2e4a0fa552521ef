"""Which column of a foreign table is which channel, and in which unit.

Header names are normalised (lower case; a leading ``#`` or ``%``, a ``field.`` prefix
and a unit in brackets or parentheses removed and kept as the column's unit; ``.``,
``-`` and spaces become ``_``) and looked up in :data:`ALIASES`, which covers imubench's
own CSV, common logger headers (``timestamp,gyro_x,...,acc_x``), ROS ``rostopic echo -p``
exports of ``sensor_msgs/Imu`` (``%time,field.header.stamp,...,
field.angular_velocity.x,...,field.linear_acceleration.x``) and EuRoC / TUM-VI
``imu0/data.csv`` (``#timestamp [ns],w_RS_S_x [rad s^-1],...,a_RS_S_x [m s^-2]``).

Units come, in this order, from ``--units`` / ``--time-unit``, from the header (a unit
in brackets, or the format: ROS and EuRoC are SI with times in ns), from imubench's own
column names (``gx``.. in dps, ``ax``.. in g, ``t`` in s). A foreign gyro or
accelerometer column whose unit nothing states is refused with the ``--units`` fix,
never guessed.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Collection
from dataclasses import dataclass

from imubench.batch import CHANNELS

_GYRO_STEMS = ("g", "gyro", "gyr", "gyroscope", "w", "omega", "angular_velocity", "w_rs_s",
               "rate", "gyro_rate")
_ACCEL_STEMS = ("a", "acc", "accel", "accelerometer", "acceleration", "linear_acceleration",
                "a_rs_s")
_TIME_NAMES = ("t", "time", "timestamp", "stamp", "time_s", "t_s", "header_stamp",
               "seconds", "sec", "time_stamp", "elapsed", "elapsed_time", "sample_time",
               "zeit")
_TIME_SUFFIXES = {"_ms": "ms", "_us": "us", "_ns": "ns", "_s": "s", "_sec": "s",
                  "_min": "min", "_h": "h"}
_VALUE_SUFFIXES = {"_dps": "dps", "_degs": "dps", "_deg_s": "dps", "_degps": "dps",
                   "_mdps": "mdps", "_rads": "rad/s", "_radps": "rad/s", "_rad_s": "rad/s",
                   "_mrads": "mrad/s", "_mradps": "mrad/s", "_mrad_s": "mrad/s",
                   "_g": "g", "_mg": "mg", "_mps2": "m/s2", "_ms2": "m/s2", "_m_s2": "m/s2"}
"""Unit suffixes of a gyro or accelerometer column's name (``gyro_x_dps``, ``ax_g``,
``acc_x_mps2``): the unit, and the name without it."""
_TEMP_SUFFIXES = {"_k": "K", "_kelvin": "K", "_f": "degF", "_degf": "degF"}
"""Unit suffixes of a temperature column's name (``temp_K``: left out unread before, an
outside reviewer's file); ``temp_c`` and ``temp_degc`` are names of their own."""


def _aliases() -> dict[str, str]:
    out: dict[str, str] = {}
    for axis in "xyz":
        for stem in _GYRO_STEMS:
            for sep in ("", "_"):
                out[f"{stem}{sep}{axis}"] = f"g{axis}"
        for stem in _ACCEL_STEMS:
            for sep in ("", "_"):
                out[f"{stem}{sep}{axis}"] = f"a{axis}"
    for name in _TIME_NAMES:
        out[name] = "t"
        for suffix in _TIME_SUFFIXES:
            out[name + suffix] = "t"
    for stem in ("imu", "die", "chip", "sensor", "board", "gyro", "accel"):
        for word in ("temp", "temperature"):
            out[f"{stem}_{word}"] = out[f"{stem}{word}"] = "temp"
    out.update({"temp": "temp", "temperature": "temp", "temperatur": "temp", "temp_c": "temp",
                "temperature_c": "temp", "temp_degc": "temp",
                "index": "index", "sample": "index", "sample_index": "index"})
    return out


ALIASES: dict[str, str] = _aliases()
"""Normalised header name -> channel (``t``, ``index``, ``gx``..``az``, ``temp``)."""
OWN_NAMES = frozenset({"t", "index", "temp", *CHANNELS})
"""imubench's own CSV header names (their units are fixed: s, dps, g, degC)."""

_UNIT_WORDS = {
    "rad s^-1": "rad/s", "rad/s": "rad/s", "rad s-1": "rad/s", "rads": "rad/s",
    "deg/s": "dps", "dps": "dps", "deg s^-1": "dps", "°/s": "dps", "mdps": "mdps",
    "deg/h": "deg/h", "deg/hr": "deg/h", "°/h": "deg/h", "dph": "deg/h", "deg h^-1": "deg/h",
    "m/s²": "m/s2", "ug": "ug", "µg": "ug",
    "m s^-2": "m/s2", "m/s^2": "m/s2", "m/s2": "m/s2", "m s-2": "m/s2", "g": "g", "mg": "mg",
    "s": "s", "sec": "s", "ms": "ms", "us": "us", "µs": "us", "ns": "ns", "min": "min",
    "h": "h",
    "degc": "degC", "°c": "degC", "c": "degC",
    # spellings seen in loggers' exports
    "deg/sec": "dps", "º/s": "dps", "degrees/s": "dps", "deg s-1": "dps",
    "rad/sec": "rad/s", "mrad/s": "mrad/s", "mrad/sec": "mrad/s",
    "ms^-2": "m/s2", "ms-2": "m/s2", "m.s^-2": "m/s2", "m.s-2": "m/s2", "mps2": "m/s2",
    "cm/s^2": "cm/s2", "cm/s2": "cm/s2", "cm/s²": "cm/s2", "gal": "cm/s2",
    "radps": "rad/s", "°/sec": "dps", "º/sec": "dps", "rpm": "rpm",
    "mm/s^2": "mm/s2", "mm/s2": "mm/s2", "mm/s²": "mm/s2",
}


def unit_word(text: str) -> str:
    """A unit as written (``[°/s]``'s ``°/s``, ``deg/hr``) in the spelling of the unit
    tables (``dps``, ``deg/h``); an unknown unit is returned as written."""
    return _UNIT_WORDS.get(text.strip().lower(), text.strip())


def near_alias(name: str, taken: Collection[str] = ()) -> str | None:
    """The channel (``t``, ``temp``, ``gx``..), not among ``taken`` (the channels other
    columns give), whose header name ``name`` (normalised) is most likely a misspelling
    of (difflib ratio at least 0.7 to a name of :data:`ALIASES`), or None: ``tmep`` ->
    ``temp`` beside a time column (an outside reviewer's header, whose temperature went
    unread and untested with nothing said)."""
    close = difflib.get_close_matches(name, ALIASES, n=20, cutoff=0.7)
    return next((ALIASES[c] for c in close if ALIASES[c] not in taken), None)


TIME_UNIT_WORDS = frozenset({"s", "ms", "us", "ns", "min", "h"})
"""Units (after :data:`_UNIT_WORDS`) that make a column a time column."""


@dataclass(frozen=True)
class Column:
    """One header column: its text, normalised name, channel (or None) and unit."""

    text: str
    name: str
    channel: str | None
    unit: str | None


def normalise(text: str) -> tuple[str, str | None]:
    """(normalised name, unit from brackets or a time suffix, or None)."""
    s = text.strip().strip('"').strip()
    unit = None
    m = re.search(r"[\[(]([^\])]*)[\])]\s*$", s)
    if m:
        unit = unit_word(m.group(1))
        s = s[: m.start()]
    s = s.strip().lstrip("#%").strip().lower()
    s = re.sub(r"[.\-\s]+", "_", s)
    if s.startswith("field_"):
        s = s[len("field_"):]
    if unit is None:
        for suffix, u in _TIME_SUFFIXES.items():
            if s.endswith(suffix) and ALIASES.get(s) == "t":
                unit = u
                break
    if unit is None:
        for suffix, u in _VALUE_SUFFIXES.items():
            stem = s[: -len(suffix)]
            if s.endswith(suffix) and ALIASES.get(stem, "t") not in ("t", "temp", "index"):
                return stem, u
        for suffix, u in _TEMP_SUFFIXES.items():
            stem = s[: -len(suffix)]
            if s.endswith(suffix) and ALIASES.get(stem) == "temp":
                return stem, u
    return s, unit


def is_ros_export(names: list[str]) -> bool:
    """A ``rostopic echo -p`` table (``%time`` and ``field.*`` columns)."""
    return any(n.startswith("%time") for n in names) or any(
        n.startswith("field.") for n in names)


def is_euroc(names: list[str]) -> bool:
    """A EuRoC / TUM-VI ``imu0/data.csv`` header."""
    return any("w_RS_S" in n for n in names) or any("a_RS_S" in n for n in names)


def map_columns(header: list[str]) -> list[Column]:
    """Each header column with the channel its name stands for (first one wins; a ROS
    export's ``%time`` (receipt) yields to ``field.header.stamp`` (the sensor's time))."""
    cols = []
    taken: set[str] = set()
    names = [normalise(h) for h in header]
    stamp = any(n == "header_stamp" for n, _ in names)
    timelike = [k for k, (n, u) in enumerate(names)
                if ALIASES.get(n) == "t" or u in TIME_UNIT_WORDS or n in _UNIT_NAMED_TIME]
    for k, (text, (name, unit)) in enumerate(zip(header, names, strict=True)):
        channel = ALIASES.get(name)
        if channel == "t" and stamp and name != "header_stamp":
            channel = None
        if channel == "t" and capital_t(text) and (
                unit in _TEMPERATURE_WORDS or (unit is None and any(j != k for j in timelike))):
            channel = "temp"  # ``T``: a temperature beside a time column, or in degC
        if channel in taken:
            channel = None
        if channel is not None:
            taken.add(channel)
        cols.append(Column(text, name, channel, unit))
    if "t" not in taken:  # a column whose header states a time unit is the time
        for k, c in enumerate(cols):
            if c.channel is None and (c.unit in TIME_UNIT_WORDS or c.name in _UNIT_NAMED_TIME):
                cols[k] = Column(c.text, c.name, "t", c.unit or _UNIT_NAMED_TIME[c.name])
                break
    return cols


_UNIT_NAMED_TIME = {"ms": "ms", "millis": "ms", "us": "us", "micros": "us", "ns": "ns"}
"""Header names that are a time unit alone (an Arduino log's ``ms`` or ``millis``)."""
_TEMPERATURE_WORDS = frozenset({"degC", "°C", "C", "K", "degF", "F", "°F"})


def capital_t(text: str) -> bool:
    """Whether a header is a capital ``T`` (with or without a unit): a temperature in
    many loggers, where ``t`` is time."""
    return re.sub(r"\s*[\[(].*$", "", text.strip().strip('"')) == "T"
