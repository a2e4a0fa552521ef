"""Every sample of a damaged or unusual recording accounted: samples read + lost in
declared gaps = samples produced, each loss at its true place with a reason (native
records skipped as damaged, ``# gap`` lines of a CSV, a recording of no samples)."""

from __future__ import annotations

import logging
import random
import struct
from pathlib import Path

import numpy as np
import pytest

from imubench.batch import UNEXPLAINED, Batch, Gap
from imubench.cli import main
from imubench.errors import RecordingError
from imubench.recording import load_recording, open_writer
from imubench.recording.native import _PREAMBLE, _REC, DAMAGED_RECORD

SENS = np.array([8.75e-3] * 3 + [0.061e-3] * 3)
BLOCK = 100
"""Samples per data record of :func:`write_resets`."""
PRODUCED = 2000
"""Sample indices 0..1999 of :func:`write_resets`."""
RESETS = (3, 8, 10)
"""Blocks of :func:`write_resets` lost to a chip reset (declared gaps)."""


def meta(**kw: object) -> dict[str, object]:
    return {"chip": "lsm6dsl", "odr_hz": 104.0, "gyro_sensitivity_dps": 8.75e-3,
            "accel_sensitivity_g": 0.061e-3, "storage": "raw_int16", **kw}


def write_resets(path: Path, storage: str = "raw_int16") -> None:
    """A native recording of 2000 samples in records of 100, blocks 3, 8 and 10 lost to
    chip resets: 1700 samples, 300 lost in 3 gap records, each written before the data
    record after its hole (as ``acquire`` writes a chip that resets)."""
    rng = np.random.default_rng(1)
    with open_writer(path, meta(storage=storage)) as w:
        for k in range(PRODUCED // BLOCK):
            if k in RESETS:
                continue
            idx = np.arange(k * BLOCK, (k + 1) * BLOCK, dtype=np.int64)
            raw = rng.integers(-2000, 2000, size=(BLOCK, 6)).astype(np.int16)
            gaps = (Gap(int(idx[0]), BLOCK, "chip reset"),) if k - 1 in RESETS else ()
            w.write(Batch(idx, idx / 104.0, raw * SENS, np.full(BLOCK, 25.0), raw, gaps))


def records(path: Path) -> list[tuple[int, bytes, int]]:
    """(byte offset, kind, payload length) of each record of an intact native file."""
    data = path.read_bytes()
    (hlen,) = struct.unpack_from("<I", data, len(_PREAMBLE))
    pos = len(_PREAMBLE) + 4 + hlen + 4
    out = []
    while pos < len(data):
        kind, length, _ = _REC.unpack_from(data, pos)
        out.append((pos, kind, length))
        pos += _REC.size + length
    return out


def data_record(path: Path, k: int) -> tuple[int, bytes, int]:
    """The ``k``-th data record (0: the first) of ``path``."""
    return [r for r in records(path) if r[1] == b"D"][k]


def flip(path: Path, offset: int) -> None:
    data = bytearray(path.read_bytes())
    data[offset] ^= 0xFF
    path.write_bytes(bytes(data))


def cut_end_record(path: Path) -> None:
    """Drop the end record: a writer that was killed."""
    end = next(pos for pos, kind, _ in records(path) if kind == b"E")
    path.write_bytes(path.read_bytes()[:end])


def spans(gaps: list[Gap]) -> list[tuple[int, int, str]]:
    """(first, last, reason) of every gap, sorted; gaps sharing ``at`` are adjacent holes,
    the one listed first the earlier (as :func:`imubench.batch.gaps_before` reads them)."""
    groups: dict[int, list[Gap]] = {}
    for g in gaps:
        groups.setdefault(g.at, []).append(g)
    out = []
    for at, group in groups.items():
        start = at - sum(g.lost for g in group)
        for g in group:
            out.append((start, start + g.lost - 1, g.reason))
            start += g.lost
    return sorted(out)


def accounted(rec: object) -> None:
    """Samples read + lost = produced, and the gaps' lost is the lost count."""
    assert len(rec) + rec.lost_samples == PRODUCED  # type: ignore[arg-type, attr-defined]
    assert sum(g.lost for g in rec.gaps) == rec.lost_samples  # type: ignore[attr-defined]


RESET_SPANS = [(300, 399, "chip reset"), (800, 899, "chip reset"),
               (1000, 1099, "chip reset")]


@pytest.mark.parametrize("end_record", [True, False])
def test_a_damaged_first_data_record_is_a_gap_before_the_first_sample(
        tmp_path: Path, end_record: bool) -> None:
    """The first data record fails its CRC: its 100 samples were counted nowhere (read
    1600 + lost 300 of 2000); now a ``damaged record`` gap of 0-99, counted from the end
    record, or without one from the record's own length."""
    path = tmp_path / "r.imbr"
    write_resets(path)
    if not end_record:
        cut_end_record(path)
    offset, _, length = data_record(path, 0)
    flip(path, offset + _REC.size + length // 2)
    rec = load_recording(path)
    assert rec.damage is not None and "CRC mismatch" in rec.damage
    assert len(rec) == 1600 and int(rec.index[0]) == 100
    accounted(rec)
    assert spans(rec.gaps) == [(0, 99, DAMAGED_RECORD), *RESET_SPANS]


def test_a_damaged_record_between_two_gaps_is_placed_between_them(tmp_path: Path) -> None:
    """Block 9 (samples 900-999) damaged between the resets of blocks 8 and 10: the hole
    800-1099 is reset, damaged, reset, in that order, in the recording and in a CSV
    converted from it (the hole was lost from the gaps, and the CSV said 800-899 reset,
    900-999 reset, 1000-1099 ``unexplained``)."""
    path = tmp_path / "r.imbr"
    write_resets(path)
    offset, _, _ = data_record(path, 7)  # blocks 0-2, 4-7, then 9
    flip(path, offset + _REC.size + 10)
    rec = load_recording(path)
    accounted(rec)
    assert spans(rec.gaps) == [(300, 399, "chip reset"), (800, 899, "chip reset"),
                               (900, 999, DAMAGED_RECORD), (1000, 1099, "chip reset")]
    out = tmp_path / "r.csv"
    assert main(["convert", str(path), str(out), "--progress", "off"]) == 0
    back = load_recording(out)
    assert UNEXPLAINED not in {g.reason for g in back.gaps}
    assert spans(back.gaps) == spans(rec.gaps)
    accounted(back)


def test_a_damaged_gap_record_leaves_its_hole_declared(tmp_path: Path) -> None:
    """A gap record that fails its CRC: its hole (800-899) is in the indices but was in
    no gap (lost_samples 300, the gaps' 200); now a ``damaged record`` gap, its reason
    lost with it."""
    path = tmp_path / "r.imbr"
    write_resets(path)
    offset, _, _ = [r for r in records(path) if r[1] == b"G"][1]
    flip(path, offset + _REC.size + 2)
    rec = load_recording(path)
    accounted(rec)
    assert spans(rec.gaps) == [(300, 399, "chip reset"), (800, 899, DAMAGED_RECORD),
                               (1000, 1099, "chip reset")]


@pytest.mark.parametrize("end_record", [True, False])
def test_a_damaged_last_data_record_is_a_gap_after_the_last_sample(
        tmp_path: Path, end_record: bool) -> None:
    path = tmp_path / "r.imbr"
    write_resets(path, storage="float64")
    if not end_record:
        cut_end_record(path)
    offset, _, _ = data_record(path, -1)
    flip(path, offset + _REC.size + 5)
    rec = load_recording(path)
    assert int(rec.index[-1]) == 1899
    accounted(rec)
    assert spans(rec.gaps) == [*RESET_SPANS, (1900, 1999, DAMAGED_RECORD)]


def test_a_damaged_length_field_costs_one_record_not_the_file(tmp_path: Path) -> None:
    """A flipped bit in a record's length that points past the end of the file was read
    as a crashed writer's tail: every record after it was lost, uncounted. Whole records
    follow, so it is damage: that record is skipped and counted (by the end record)."""
    path = tmp_path / "r.imbr"
    write_resets(path)
    offset, _, _ = data_record(path, 0)
    flip(path, offset + 3)  # the third byte of the length: + 16 MB
    rec = load_recording(path)
    assert rec.damage is not None and "damaged length" in rec.damage
    assert len(rec) == 1600
    accounted(rec)
    assert spans(rec.gaps)[0] == (0, 99, DAMAGED_RECORD)


def test_damage_that_cannot_be_counted_is_said(tmp_path: Path) -> None:
    """No end record and the first record's length damaged: how many samples it held is
    not known; the damage says so, not a silent count."""
    path = tmp_path / "r.imbr"
    write_resets(path)
    cut_end_record(path)
    offset, _, _ = data_record(path, 0)
    flip(path, offset + 3)
    rec = load_recording(path)
    assert len(rec) == 1600
    assert rec.damage is not None and "before sample 100 are not counted" in rec.damage
    assert sum(g.lost for g in rec.gaps) == rec.lost_samples == 300


def test_random_damage_keeps_every_sample_accounted(tmp_path: Path) -> None:
    """200 copies with 1-8 random bytes changed after the header (the end record intact
    or damaged): read + lost = produced, the gaps count every loss, none unexplained."""
    path = tmp_path / "r.imbr"
    write_resets(path)
    data = path.read_bytes()
    first = records(path)[0][0]
    end = next(pos for pos, kind, _ in records(path) if kind == b"E")
    rng = random.Random(7)
    for i in range(200):
        out = bytearray(data)
        for _ in range(rng.randint(1, 8)):
            j = rng.randrange(first, end)  # keep the end record: the count is exact
            out[j] = rng.randrange(256)
        p = tmp_path / f"{i}.imbr"
        p.write_bytes(bytes(out))
        rec = load_recording(p)
        assert len(rec) + rec.lost_samples == PRODUCED, (i, rec.damage)
        assert sum(g.lost for g in rec.gaps) == rec.lost_samples, (i, rec.damage)
        assert UNEXPLAINED not in {g.reason for g in rec.gaps}
        p.unlink()


def good_csv(tmp_path: Path) -> Path:
    src = tmp_path / "r.imbr"
    write_resets(src)
    out = tmp_path / "good.csv"
    assert main(["convert", str(src), str(out), "--progress", "off"]) == 0
    return out


def with_line(csv: Path, after_index: int, line: str) -> tuple[Path, int]:
    """A copy of ``csv`` with ``line`` after the data line of sample ``after_index``; and
    the new line's number."""
    lines = csv.read_text().splitlines()
    k = next(n for n, text in enumerate(lines)
             if not text.startswith("#") and text.endswith(f",{after_index}"))
    lines.insert(k + 1, line)
    out = csv.with_name("x.csv")
    out.write_text("\n".join(lines) + "\n")
    return out, k + 2


@pytest.mark.parametrize(("line", "field"), [
    ("# gap at_index=49 lost=-5 reason=test", "field lost is '-5'"),
    ("# gap at_index=49 lost=0 reason=test", "field lost is '0'"),
    ("# gap at_index=abc lost=5", "field at_index is 'abc'"),
    ("# gap at_index=49 lost=5x", "field lost is '5x'"),
    ("# gap lost=5 at_index=49", "a gap line must read"),
])
def test_a_malformed_gap_line_is_refused_naming_file_line_and_field(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], line: str, field: str) -> None:
    """Such a line was skipped as a comment: '1700 samples, 3 gaps', exit 0."""
    path, lineno = with_line(good_csv(tmp_path), 49, line)
    capsys.readouterr()
    with pytest.raises(RecordingError, match=f"^{path}:{lineno}: .*{field}"):
        load_recording(path)
    assert main(["convert", str(path), str(tmp_path / "o.imbr"), "--progress", "off"]) == 2
    assert f"{path}:{lineno}:" in capsys.readouterr().err


def test_a_gap_line_the_index_column_contradicts_is_warned_of_and_not_taken(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """``lost=5`` before sample 49 where samples 44-48 are data lines: the index column is
    the truth; the line was kept silently (the gaps counted 5 samples more than lost)."""
    path, lineno = with_line(good_csv(tmp_path), 49, "# gap at_index=49 lost=5 reason=x")
    with caplog.at_level(logging.WARNING, logger="imubench.recording"):
        rec = load_recording(path)
    assert f"{path}:{lineno}: gap line at_index=49 declares samples 44-48 lost" in caplog.text
    assert "the gap is not taken" in caplog.text
    accounted(rec)
    assert spans(rec.gaps) == RESET_SPANS


def test_a_gap_line_larger_than_its_hole_is_cut_to_it(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """A gap line declaring samples 1950-2149 lost after the last sample (1999): the 50
    that are data lines are not lost, the 150 after them are."""
    path, lineno = with_line(good_csv(tmp_path), 1999,
                             "# gap at_index=2150 lost=200 reason=stopped")
    with caplog.at_level(logging.WARNING, logger="imubench.recording"):
        rec = load_recording(path)
    assert f"{path}:{lineno}: gap line at_index=2150 declares samples 1950-2149" in caplog.text
    assert "read as 150 lost" in caplog.text
    assert spans(rec.gaps) == [*RESET_SPANS, (2000, 2149, "stopped")]
    assert sum(g.lost for g in rec.gaps) == rec.lost_samples == 450


def test_a_recording_of_no_samples_round_trips_through_csv(tmp_path: Path) -> None:
    """A native file cut after its header reads as 0 samples, and ``convert`` wrote a CSV
    of 0 samples that the reader refused ("no readable data lines"); now read as a
    recording of no samples, as the native and HDF5 files are."""
    src = tmp_path / "r.imbr"
    write_resets(src)
    src.write_bytes(src.read_bytes()[:records(src)[0][0] + 20])
    assert len(load_recording(src)) == 0
    csv = tmp_path / "r.csv"
    assert main(["convert", str(src), str(csv), "--progress", "off"]) == 0
    rec = load_recording(csv)
    assert len(rec) == 0 and rec.lost_samples == 0 and rec.rate_hz == 104.0
    back = tmp_path / "back.imbr"
    assert main(["convert", str(csv), str(back), "--progress", "off"]) == 0
    assert len(load_recording(back)) == 0


def test_a_csv_of_gap_lines_only_is_a_recording_of_lost_samples(tmp_path: Path) -> None:
    path = tmp_path / "g.csv"
    path.write_text("# odr_hz: 100\nt,gx,index\n# gap at_index=50 lost=50 reason=x\n")
    rec = load_recording(path)
    assert len(rec) == 0 and rec.lost_samples == 50 and rec.gaps == [Gap(50, 50, "x")]


@pytest.mark.parametrize("text", [
    "t,gx,gy,gz\n",  # a foreign header: no index column
    "t,gx,index\n",  # imubench's columns, but no rate stated
])
def test_other_header_only_files_are_still_refused(tmp_path: Path, text: str) -> None:
    path = tmp_path / "h.csv"
    path.write_text(text)
    with pytest.raises(RecordingError, match="no readable data lines"):
        load_recording(path)


def test_an_index_that_is_not_a_whole_number_is_refused_naming_the_line(
        tmp_path: Path) -> None:
    """An index column value 49.5 was rounded in silence (an outside reviewer)."""
    good = good_csv(tmp_path)
    lines = good.read_text().splitlines()
    k = next(n for n, text in enumerate(lines)
             if not text.startswith("#") and text.endswith(",49"))
    lines[k] = lines[k][:-len("49")] + "49.5"
    path = tmp_path / "half.csv"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(RecordingError, match=rf"^{path}:{k + 1}: index 49.5 is not a whole"):
        load_recording(path)


@pytest.mark.parametrize("where", ["json", "crc"])
def test_a_file_cut_inside_its_header_is_called_truncated(tmp_path: Path, where: str) -> None:
    """A native file cut inside its JSON header (or its CRC) read as "header damaged
    (byte offset 8)", as a flipped bit does (an outside reviewer); the two are told
    apart."""
    path = tmp_path / "r.imbr"
    write_resets(path)
    data = path.read_bytes()
    hlen = int.from_bytes(data[8:12], "little")  # after the 8-byte preamble
    cut = 12 + hlen // 2 if where == "json" else 12 + hlen + 2
    path.write_bytes(data[:cut])
    with pytest.raises(RecordingError, match=rf"truncated header \({cut} of \d+ bytes"):
        load_recording(path)
    damaged = bytearray(data)
    damaged[50] ^= 0xFF
    path.write_bytes(bytes(damaged))
    with pytest.raises(RecordingError, match=r"header damaged \(byte offset 8\)"):
        load_recording(path)


def test_values_the_sensor_cannot_output_are_warned_of(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """gx = 1e300 in a file that states 250 dps was read without a word (an outside
    reviewer); a saturated sample (32767 LSB, 286.7 dps) is one the sensor does output."""
    src = tmp_path / "r.imbr"
    with open_writer(src, meta(fs_dps=250.0, fs_g=2.0)) as w:
        raw = np.zeros((50, 6), np.int16)
        raw[10, 0] = 32767  # saturated: the sensor's own largest output
        idx = np.arange(50)
        w.write(Batch(idx, idx / 104.0, raw * np.array([8.75e-3] * 3 + [0.061e-3] * 3),
                      np.full(50, 25.0), raw, ()))
    good = tmp_path / "g.csv"
    assert main(["convert", str(src), str(good), "--progress", "off"]) == 0
    with caplog.at_level(logging.WARNING, logger="imubench.recording"):
        load_recording(good)
    assert "beyond what the sensor can output" not in caplog.text
    lines = good.read_text().splitlines()
    k = next(n for n, text in enumerate(lines) if not text.startswith("#")
             and text.endswith(",20"))
    fields = lines[k].split(",")
    fields[1] = "1e300"
    lines[k] = ",".join(fields)
    bad = tmp_path / "b.csv"
    bad.write_text("\n".join(lines) + "\n")
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="imubench.recording"):
        load_recording(bad)
    assert (f"{bad}:{k + 1}: 1 row(s) hold values beyond what the sensor can output "
            "(286.72 dps at the stated full scale 250 dps)") in caplog.text
