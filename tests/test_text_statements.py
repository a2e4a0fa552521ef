"""What a text file states about how to read it is used, or the file refused naming it:
rate and period keys other tools write, a headerless file's unit, its text encoding, and
number spellings (Fortran exponents, decimal commas in one column)."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest

from imubench.errors import RecordingError
from imubench.recording import InputOptions, load_recording

PLAIN = InputOptions(default_rate_hz=1.0)
"""What ``imubench allan`` reads with: a file that states no rate is in samples (1 Hz)."""


def _values(n: int = 400, seed: int = 3) -> np.ndarray:
    return np.random.default_rng(seed).normal(0.0, 0.01, n)


@pytest.mark.parametrize(("line", "rate"), [
    ("# rate_hz: 100", 100.0), ("# sample_rate: 200", 200.0), ("# Sampling Rate: 1 kHz", 1e3),
    ("# fs: 50 Hz", 50.0), ("# tau0_s: 0.01", 100.0), ("# tau0: 0.25", 4.0),
    ("# dt: 10 ms", 100.0), ("# odr_hz: 104", 104.0)])
def test_a_stated_rate_or_period_is_the_rate(tmp_path: Path, line: str, rate: float) -> None:
    """``# rate_hz: 100`` over a one-column file was ignored: read at 1 Hz, every tau 100x
    too long (and an ARW from it 10x off)."""
    x = _values()
    p = tmp_path / "one.txt"
    p.write_text(line + "\n" + "".join(f"{v:.6f}\n" for v in x))
    rec = load_recording(p, PLAIN)
    assert rec.rate_hz == pytest.approx(rate)
    np.testing.assert_allclose(rec.channel("gx"), x, atol=5e-7)


@pytest.mark.parametrize(("lines", "words"), [
    ("# rate_hz: 100\n# tau0_s: 0.02\n", "rate_hz and tau0_s disagree"),
    ("# sample_rate: fast\n", "sample_rate 'fast' is not a number"),
    ("# rate_hz: 100 furlongs\n", "unit 'furlongs' is not one of"),
    ("# dt: -0.01\n", "must be a positive number"),
    ("# unit: parsec/s\n", "unit 'parsec/s' is not a gyro unit"),
])
def test_a_statement_that_cannot_be_read_is_refused_naming_it(
        tmp_path: Path, lines: str, words: str) -> None:
    p = tmp_path / "one.txt"
    p.write_text(lines + "".join(f"{v:.6f}\n" for v in _values()))
    with pytest.raises(RecordingError, match=words) as err:
        load_recording(p, PLAIN)
    assert str(p) in str(err.value)


def test_a_headerless_file_in_deg_per_hour_is_read_in_deg_per_hour(tmp_path: Path) -> None:
    """``# unit: deg/h`` was not a known unit and the values were read as dps (3600x)."""
    x = _values()
    p = tmp_path / "dph.txt"
    p.write_text("# tau0_s: 0.01\n# unit: deg/h\n" + "".join(f"{v:.6f}\n" for v in x))
    rec = load_recording(p, PLAIN)
    np.testing.assert_allclose(rec.channel("gx"), x / 3600.0, atol=1e-9)
    hdr = tmp_path / "dph.csv"  # and as a header unit
    hdr.write_text("t,gyro_x [deg/h]\n" + "".join(f"{i / 100:.2f},{v:.6f}\n"
                                                   for i, v in enumerate(x)))
    np.testing.assert_allclose(load_recording(hdr).channel("gx"), x / 3600.0, atol=1e-9)


@pytest.mark.parametrize("encoding", ["utf-16", "cp1252", "utf-8-sig"])
@pytest.mark.parametrize("gz", [False, True])
def test_windows_encodings_are_read_with_their_units(tmp_path: Path, encoding: str,
                                                     gz: bool) -> None:
    """A UTF-16 file (Windows "Unicode" text) had every line unreadable ("not a
    recording"); a Windows-1252 ``[°/s]`` became ``[\ufffd/s]``, "not a gyro unit"."""
    x = _values()
    text = "t,gyro_x [°/s],temp [°C]\n" + "".join(f"{i / 100:.2f},{v:.6f},25.5\n"
                                                  for i, v in enumerate(x))
    p = tmp_path / ("w.csv.gz" if gz else "w.csv")
    data = text.encode(encoding)
    p.write_bytes(gzip.compress(data) if gz else data)
    rec = load_recording(p)
    assert rec.rate_hz == pytest.approx(100.0)
    np.testing.assert_allclose(rec.channel("gx"), x, atol=5e-7)
    assert np.nanmean(rec.temp_c) == pytest.approx(25.5)


def test_fortran_exponents_are_numbers(tmp_path: Path) -> None:
    """``3.4D-03`` (Fortran's double precision) made the first line a header and the
    file "no channel found"."""
    x = _values()
    p = tmp_path / "f.dat"
    p.write_text("".join(f"{v:.6E}\n".replace("E", "D") for v in x))
    np.testing.assert_allclose(load_recording(p, PLAIN).channel("gx"), x, rtol=1e-6)


@pytest.mark.parametrize("offset", [0.0, 12.0])
def test_one_column_with_decimal_commas_is_one_column(tmp_path: Path, offset: float) -> None:
    """``0,012345`` per line was read as time tag 0 and value 12345 ("the time column
    never increases"); around 12 with no leading zero after the comma as well."""
    x = np.round(_values() + offset, 4) + 0.00011  # no fraction ends in 0
    p = tmp_path / "comma.txt"
    p.write_text("".join(f"{v:.5f}\n".replace(".", ",") for v in x))
    rec = load_recording(p, PLAIN)
    np.testing.assert_allclose(rec.channel("gx"), x, atol=1e-9)
    assert rec.rate_hz == 1.0


def test_time_tags_with_integer_values_stay_two_columns(tmp_path: Path) -> None:
    """Two comma-separated integers whose first increases are (time tag, value)."""
    p = tmp_path / "tags.txt"
    p.write_text("".join(f"{i},{5 + i % 7}\n" for i in range(400)))
    rec = load_recording(p, InputOptions(default_rate_hz=1.0, time_unit="s"))
    np.testing.assert_array_equal(rec.channel("gx"), [5 + i % 7 for i in range(400)])
    assert rec.rate_hz == 1.0


def test_a_time_column_in_seconds_that_gives_a_slow_rate_says_so(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """``time_s`` holding milliseconds was read at 0.1 Hz without a word."""
    p = tmp_path / "ms.csv"
    p.write_text("time_s,gyro_x [dps]\n" + "".join(f"{i * 10},{v:.6f}\n"
                                                   for i, v in enumerate(_values())))
    with caplog.at_level("WARNING"):
        rec = load_recording(p)
    assert rec.rate_hz == pytest.approx(0.1)
    assert "if the column holds ms (100 Hz), give --time-unit ms" in caplog.text


def test_a_modified_julian_date_column_dates_the_recording(tmp_path: Path) -> None:
    """Stable32's MJD time tags state when the data were taken: ``start_utc`` was null."""
    p = tmp_path / "mjd.txt"
    mjd0 = 60_000.5  # 2023-02-25 12:00 UTC
    p.write_text("".join(f"{mjd0 + i / 86_400:.8f} {v:.6f}\n"
                         for i, v in enumerate(_values())))
    rec = load_recording(p, PLAIN)
    assert rec.rate_hz == pytest.approx(1.0, rel=1e-4)
    assert rec.metadata["start_utc"] == "2023-02-25T12:00:00.000000Z"


@pytest.mark.parametrize(("where", "jump_s"), [(-1, 1e6), (-2, 86_400_000.0), (0, -1e6),
                                               (1, -5e5)])
def test_a_stray_stamp_at_an_end_costs_its_row_not_a_giant_hole(
        tmp_path: Path, where: int, jump_s: float) -> None:
    """A last stamp with a wrong digit (1e6 s on) made a 3000-row file a 1e8-sample hole:
    5 GB and 21 s in ``allan``, every tau up to 1.7e5 s computed on nothing."""
    x = _values(3000)
    t = 1.7e9 + np.arange(3000) / 100
    if where >= 0:
        t[: where + 1] += jump_s  # the first row(s) too early
    else:
        t[where:] += jump_s  # the last row(s) too late
    p = tmp_path / "stray.csv"
    p.write_text("timestamp,gyro_x [dps]\n" + "".join(f"{a:.2f},{v:.6f}\n"
                                                      for a, v in zip(t, x, strict=True)))
    rec = load_recording(p)
    n_stray = abs(where) if where < 0 else where + 1
    assert len(rec) == 3000 - n_stray and rec.lost_samples == 0
    assert rec.damage is not None and "stray at an end" in rec.damage


def test_a_recording_that_resumes_after_a_pause_keeps_both_runs(tmp_path: Path) -> None:
    """A real pause (five times the run before it) is a hole, not a stray end."""
    t = np.concatenate([np.arange(1000), 6000 + np.arange(1000)]) / 100
    p = tmp_path / "pause.csv"
    p.write_text("t,gyro_x [dps]\n" + "".join(f"{a:.2f},0.01\n" for a in t))
    rec = load_recording(p)
    assert len(rec) == 2000 and rec.lost_samples == 5000
