"""Native recordings and CSV: round trips, gaps, crash tolerance, clear errors."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from small_disk import small_tmpfs

from imubench.batch import Batch, Gap
from imubench.cli import main
from imubench.errors import RecordingError
from imubench.recording import InputOptions, load_recording, open_writer, segment_path

SENS = np.array([8.75e-3] * 3 + [0.061e-3] * 3)


def make_batches(n: int = 1000, hole_at: int = 400, lost: int = 7, seed: int = 0) -> list[Batch]:
    rng = np.random.default_rng(seed)
    idx = np.arange(n, dtype=np.int64)
    idx[hole_at:] += lost
    raw = rng.integers(-2000, 2000, size=(n, 6)).astype(np.int16)
    temp = 25 + rng.normal(size=n) * 0.01
    out = []
    for lo in range(0, n, 128):
        sl = slice(lo, lo + 128)
        here = lost and lo <= hole_at < lo + 128
        gaps = (Gap(hole_at + lost, lost, "fifo overrun"),) if here else ()
        out.append(Batch(idx[sl], idx[sl] / 104.0, raw[sl] * SENS, temp[sl], raw[sl], gaps))
    return out


def meta(**kw: object) -> dict[str, object]:
    return {"chip": "lsm6dsl", "odr_hz": 104.0, "gyro_sensitivity_dps": 8.75e-3,
            "accel_sensitivity_g": 0.061e-3, **kw}


def test_native_round_trip_raw_keeps_counts_and_gaps(tmp_path: Path) -> None:
    batches = make_batches()
    path = tmp_path / "r.imbr"
    with open_writer(path, meta(storage="raw_int16")) as w:
        for b in batches:
            w.write(b)
    rec = load_recording(path)
    ref = Batch.concat(batches)
    assert rec.complete and rec.damage is None
    np.testing.assert_array_equal(rec.raw, ref.raw)
    np.testing.assert_array_equal(rec.index, ref.index)
    np.testing.assert_allclose(rec.values, ref.values, rtol=0, atol=0)
    assert [(g.at, g.lost) for g in rec.gaps] == [(407, 7)]
    gx = rec.channel("gx")
    assert len(gx) == 1007 and np.isnan(gx[400:407]).all() and not np.isnan(gx[:400]).any()
    assert rec.metadata["chip"] == "lsm6dsl" and rec.rate_hz == 104.0


def test_truncated_tail_of_a_crashed_writer_keeps_earlier_data(tmp_path: Path) -> None:
    path = tmp_path / "crash.imbr"
    w = open_writer(path, meta(storage="raw_int16"))
    for b in make_batches(hole_at=999, lost=0):
        w.write(b)
    w._fh.flush()  # type: ignore[union-attr]  # simulate a crash: no close, no end record
    size = path.stat().st_size
    with open(path, "r+b") as fh:
        fh.truncate(size - 100)  # the last record is cut in the middle
    rec = load_recording(path)
    assert not rec.complete
    assert rec.damage and "truncated record" in rec.damage
    assert len(rec) == 1000 - 104  # 7 full records of 128 samples + none of the last 104


@pytest.mark.parametrize("how", ["repeated", "swapped"])
def test_a_record_out_of_order_is_damage_not_data(tmp_path: Path, how: str) -> None:
    """A data record written twice, or two records swapped (a copy tool's fault): the
    record that does not follow the last one taken is skipped and named, its samples
    count as lost, so kept + lost = produced (the copy was read as 288 duplicated
    samples with a lost count off by 288)."""
    batches = make_batches(hole_at=999, lost=0)
    order = ([*batches[:4], batches[3], *batches[4:]] if how == "repeated"
             else [*batches[:3], batches[4], batches[3], *batches[5:]])
    path = tmp_path / "r.imbr"
    with open_writer(path, meta(storage="raw_int16")) as w:
        for b in order:
            w._write(b, len(b))  # the writer itself refuses this order: forge the file
    rec = load_recording(path)
    assert rec.damage is not None and "repeated or out of order" in rec.damage
    assert len(rec) + rec.lost_samples == 1000
    assert len(rec) == (1000 if how == "repeated" else 1000 - 128)
    assert np.all(np.diff(rec.index) > 0)


def test_csv_round_trip_and_convert_cli(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    src = tmp_path / "a.imbr"
    with open_writer(src, meta(storage="raw_int16")) as w:
        for b in make_batches():
            w.write(b)
    assert main(["convert", str(src), str(tmp_path / "a.csv")]) == 0
    assert main(["convert", str(tmp_path / "a.csv"), str(tmp_path / "b.imbr")]) == 0
    a, c, b = (load_recording(tmp_path / n) for n in ("a.imbr", "a.csv", "b.imbr"))
    np.testing.assert_array_equal(c.index, a.index)
    np.testing.assert_allclose(c.values, a.values, rtol=1e-8)
    np.testing.assert_array_equal(b.index, a.index)
    assert [(g.at, g.lost) for g in c.gaps] == [(407, 7)]
    header = (tmp_path / "a.csv").read_text().splitlines()
    assert "t,gx,gy,gz,ax,ay,az,temp,index" in header
    assert not any(line.startswith("# format:") for line in header)  # not the source's
    assert b.metadata["format"] == "imubench-native"
    assert "1000 samples, 1 gaps" in capsys.readouterr().out


def test_csv_subset_of_columns_and_rate_inference(tmp_path: Path) -> None:
    p = tmp_path / "s.csv"
    t = np.arange(50) / 10.0
    t[30:] += 0.2  # two lost samples
    p.write_text("t,gz,temp\n" + "".join(f"{v:.3f},{i * 0.01},{20 + i * 0.001}\n"
                                          for i, v in enumerate(t)))
    rec = load_recording(p)
    assert rec.rate_hz == pytest.approx(10.0)
    assert rec.channels == ["gz", "temp"]
    assert rec.lost_samples == 2
    assert np.isnan(rec.channel("gx")).all()


@pytest.mark.parametrize("jitter", [0.0, 0.3, 0.45])
@pytest.mark.parametrize("rate", [None, 100.0])
@pytest.mark.parametrize("holes", [0, 1, 30])
def test_jittered_time_stamps_keep_every_row_and_its_sample(tmp_path: Path, jitter: float,
                                                             rate: float | None,
                                                             holes: int) -> None:
    """A logger that stamps each sample when it reads it (uniform jitter up to 0.45 of a
    period, the stamps still increasing), with ``holes`` runs of 1-19 missing samples
    (one of them among the first rows): every row is kept at its own sample, the rate is
    the true one, and each hole is found where it is. (With a median-step rate and the
    first stamp as the origin, +-0.45 periods lost 15 % of the rows as out of time order
    and read 99.9965 Hz; exact stamps with one missing sample in the first rows were
    misread when the first line was the row numbers' alone.)"""
    n, fs = 200_000, 100.0
    rng = np.random.default_rng(7 + holes)
    index = np.arange(n)
    where = np.sort(np.r_[[5] if holes else [], rng.integers(1, n, max(holes - 1, 0))])
    for h in where.astype(int):
        index[h:] += rng.integers(1, 20)
    t = 1234.5 + index / fs + rng.uniform(-jitter, jitter, n) / fs
    p = tmp_path / "jitter.csv"
    np.savetxt(p, np.column_stack([t, index * 1e-3]), fmt=("%.6f", "%.6f"), delimiter=",",
               header="t,gx", comments="")
    rec = load_recording(p, InputOptions(rate_hz=rate))
    assert rec.damage is None
    assert rec.rate_hz == pytest.approx(fs, rel=1e-7)
    assert len(rec) == n and rec.lost_samples == index[-1] + 1 - n
    gx = rec.channel("gx")
    assert np.array_equal(np.nonzero(np.isfinite(gx))[0], index)
    np.testing.assert_allclose(gx[index], index * 1e-3, rtol=0, atol=1e-9)


def test_csv_damaged_lines_are_skipped_counted_and_named(tmp_path: Path,
                                                         caplog: pytest.LogCaptureFixture
                                                         ) -> None:
    """An unreadable line (a flipped byte, a wrong field count, a partial last line)
    costs that line only: skipped, counted in ``damage`` and in the warning, its sample a
    hole in the indices (lost), never a traceback nor the rest of the file."""
    rows = [f"{i / 100:.2f},{i * 0.5},{0.01 * i}" for i in range(40)]
    rows[5] = "0.05,abc,0.05"  # not a number
    rows[12] = "0.12,6.0"  # a field short
    p = tmp_path / "bad.csv"
    p.write_text("t,gx,ax\n" + "\n".join(rows) + "\n0.4,20.")  # + a partial last line
    rec = load_recording(p, InputOptions(gyro_unit="dps", accel_unit="g"))
    assert rec.rate_hz == pytest.approx(100.0)
    assert len(rec) == 38 and rec.lost_samples == 2  # rows 5 and 12 are holes
    assert rec.damage is not None and rec.damage.startswith("3 data line(s) skipped")
    assert "first line 7" in rec.damage
    assert f"{p}:7: damaged: 3 data line(s)" in caplog.text
    assert rec.channel("gx")[4] == 2.0 and np.isnan(rec.channel("gx")[5])


@pytest.mark.parametrize(
    ("text", "where"),
    [
        ("t,gyro_x\n" + "".join(f"{i / 100},{i}\n" for i in range(5)),
         ": the unit of column 'gyro_x' is not stated; give --units"),
        ("t,bogus\n0,1\n0.1,2\n", ": no channel found among the columns t, bogus"),
        ("t,gx\n0,1\n", ": 1 row(s) are too few to infer the rate; give --rate"),
        ("t,gx\n" + "".join(f"{i * 0.5},{i}\n" for i in range(5)),
         ": the time column's median step 0.5 is 2 Hz in seconds or 2000 Hz in "
         "milliseconds; give --time-unit s|ms or --rate HZ"),
        ("t,gx\n" + "".join(f"{i * 5},{i}\n" for i in range(5)),
         ": column t steps by 5: 0.2 Hz if in seconds (as imubench writes it), 200 Hz if "
         "in ms; give --time-unit ms or --time-unit s"),
        ("timestamp,gx\n" + "".join(f"{i},{i}\n" for i in range(5)),
         ": the time column's median step 1 is 1 Hz in seconds or 1000 Hz in "
         "milliseconds; give --time-unit s|ms or --rate HZ"),
        ("time,gx\n" + "".join(f"{i * 10**11},{i}\n" for i in range(5)),
         ": cannot tell the unit of the time column (median step 1e+11)"),
        ("".join(f"{i},{i},{i}\n" for i in range(5)),
         ": 3 columns without a header; name them with --columns"),
    ],
)
def test_text_refusals_name_the_file_and_the_fix(tmp_path: Path, text: str,
                                                 where: str) -> None:
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(RecordingError) as err:
        load_recording(p)
    assert str(p) + where in str(err.value)


def test_never_overwrites_and_rejects_unknown_suffix(tmp_path: Path) -> None:
    p = tmp_path / "x.imbr"
    open_writer(p, meta()).close()
    with pytest.raises(RecordingError, match="exists already"):
        open_writer(p, meta())
    with pytest.raises(RecordingError, match="cannot write this format"):
        open_writer(tmp_path / "x.xyz", meta())


def test_not_a_recording(tmp_path: Path) -> None:
    p = tmp_path / "junk.imbr"
    p.write_bytes(b"hello world")
    with pytest.raises(RecordingError, match="bad magic"):
        load_recording(p)


@pytest.mark.parametrize("suffix", [".imbr", ".csv"])
def test_lost_samples_count_gaps_before_first_and_after_last_sample(
    tmp_path: Path, suffix: str
) -> None:
    """A stream that starts after lost samples and ends in a gap (a finite acquisition
    whose last samples were lost) keeps every lost sample in ``Recording.lost_samples``."""
    batches = make_batches()  # indices 0..1006 with 7 lost before index 407
    shifted = [
        Batch(b.index + 5, b.t_s, b.values, b.temp_c, b.raw,
              (Gap(5, 5, "chip reset"),) if i == 0 else tuple(
                  Gap(g.at + 5, g.lost, g.reason) for g in b.gaps))
        for i, b in enumerate(batches)
    ]
    path = tmp_path / f"r{suffix}"
    storage = {"storage": "raw_int16"} if suffix == ".imbr" else {}
    with open_writer(path, meta(**storage)) as w:
        for b in shifted:
            w.write(b)
        w.write_gap(1012 + 30, 30, "chip reset")  # indices 1012..1041 lost at the end
    rec = load_recording(path)
    assert (int(rec.index[0]), int(rec.index[-1])) == (5, 1011)
    assert rec.lost_samples == 5 + 7 + 30
    assert len(rec) + rec.lost_samples == 1042  # every index below the end accounted for
    assert sum(g.lost for g in rec.gaps) == rec.lost_samples


@pytest.mark.parametrize("suffix", [".imbr", ".csv"])
def test_full_disk_cuts_the_failed_batch_off_and_keeps_whole_ones(tmp_path: Path,
                                                                  suffix: str) -> None:
    """A batch that hits a full disk is taken back whole: the file reads without damage,
    holds exactly the batches the writer reported written, and every sample is either
    in the file or in the batch that failed."""
    with small_tmpfs(tmp_path) as disk:
        path = disk / f"r{suffix}"
        batches = make_batches(n=20000, hole_at=5000, lost=9)
        written = 0
        w = open_writer(path, meta(storage="raw_int16"), fsync_interval_s=0.0)
        with pytest.raises(OSError):
            for b in batches:
                w.write(b)
                written += len(b)
        assert w.samples == written
        with pytest.raises(RecordingError, match="closed"):
            w.write(batches[-1])
        w.close()
        rec = load_recording(path)
        assert rec.damage is None
        assert len(rec.index) == written
        np.testing.assert_array_equal(rec.index, Batch.concat(batches).index[:written])


@pytest.mark.parametrize(("t0", "step", "rate"), [(1.7e9, 0.2, 5.0), (1.7e12, 1000 / 104, 104.0),
                                                  (1.7e18, 1e9, 1.0)])
def test_absolute_unix_times_give_their_unit_by_magnitude(tmp_path: Path, t0: float,
                                                          step: float, rate: float) -> None:
    """Unix time stamps (s, ms, ns) give their unit by their size, so a slow logger in
    seconds is not taken for a fast one in milliseconds."""
    p = tmp_path / "abs.csv"
    p.write_text("timestamp,gx\n" + "".join(f"{t0 + i * step:.17g},{i % 7}\n"
                                            for i in range(50)))
    rec = load_recording(p, InputOptions(gyro_unit="dps", accel_unit="g"))
    assert rec.rate_hz == pytest.approx(rate, rel=1e-6)


@pytest.mark.parametrize(("az", "units", "fix"), [
    (9.81, ("dps", "g"), "m/s2 read as g (--units); give --units dps,m/s2"),
    # without --units the fix does not guess the gyro's unit (rad/s read as dps is 57x)
    (1000.0, None, "mg read as g; give --units GYRO,mg (GYRO: the gyroscope's unit, dps or "
                   "rad/s; it is read as dps now, which nothing in the file states)"),
    (1.0, ("dps", "m/s2"), "g read as m/s2 (--units); give --units dps,g"),
])
def test_accelerometer_unit_contradicted_by_gravity_is_refused(
        tmp_path: Path, az: float, units: tuple[str, str] | None, fix: str) -> None:
    """1 g at rest checks the accelerometer unit, also when --units gives it."""
    p = tmp_path / "acc.csv"
    rng = np.random.default_rng(1)
    p.write_text("t,gx,gy,gz,ax,ay,az\n" + "".join(
        f"{i / 104:.6f},0,0,0,{rng.normal() * 1e-3},0,{az}\n" for i in range(300)))
    opts = InputOptions() if units is None else InputOptions(gyro_unit=units[0],
                                                             accel_unit=units[1])
    with pytest.raises(RecordingError, match="at rest") as err:
        load_recording(p, opts)
    assert str(err.value).startswith(f"{p}: ") and fix in str(err.value)


def test_options_that_contradict_the_header_warn_or_refuse(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """--units against a header unit is obeyed with a warning naming both; a
    --time-unit that turns the header's ns stamps into an impossible rate is refused."""
    import logging

    p = tmp_path / "data.csv"
    p.write_text("#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1]\n"
                 + "".join(f"{1403636579758555392 + i * 5_000_000},{i % 3},0,0\n"
                           for i in range(200)))
    with caplog.at_level(logging.WARNING, logger="imubench.recording"):
        rec = load_recording(p, InputOptions(gyro_unit="dps", accel_unit="g"))
    assert rec.rate_hz == pytest.approx(200.0)
    assert "column 'w_RS_S_x [rad s^-1]' says rad/s, read as dps (--units)" in caplog.text
    with pytest.raises(RecordingError, match=r"gives 0\.0002 Hz with t in ms"):
        load_recording(p, InputOptions(time_unit="ms"))


def test_convert_prints_the_gaps_it_writes_for_a_damaged_input(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """A damaged .imbr's skipped records become holes: the summary counts the ``# gap``
    lines written, not the (zero) gap records of the input."""
    src = tmp_path / "flip.imbr"
    with open_writer(src, meta(storage="raw_int16")) as w:
        for b in make_batches(hole_at=999, lost=0):
            w.write(b)
    data = bytearray(src.read_bytes())
    data[len(data) // 2] ^= 0xFF
    src.write_bytes(bytes(data))
    out = tmp_path / "out.csv"
    assert main(["convert", str(src), str(out)]) == 0
    written = [ln for ln in out.read_text().splitlines() if ln.startswith("# gap")]
    assert written
    lost = sum(int(ln.split("lost=")[1].split()[0]) for ln in written)
    assert f"{len(written)} gaps ({lost} samples lost)" in capsys.readouterr().out


def test_convert_refuses_a_missing_output_directory(tmp_path: Path,
                                                     capsys: pytest.CaptureFixture) -> None:
    src = tmp_path / "a.imbr"
    with open_writer(src, meta(storage="raw_int16")) as w:
        for b in make_batches():
            w.write(b)
    for name in ("x.csv", "x.imbr", "x.h5"):
        out = tmp_path / "nodir" / name
        assert main(["convert", str(src), str(out)]) == 2
        err = capsys.readouterr().err
        assert f"{tmp_path / 'nodir'} does not exist" in err and len(err.splitlines()) == 1
        assert not (tmp_path / "nodir").exists()
    assert main(["convert", str(src), str(tmp_path / "nodir" / "x.dat"), "--channel",
                 "gx"]) == 2
    assert not (tmp_path / "nodir").exists()


@pytest.mark.parametrize("name", ["x.mcap", "x.txt", "x.xyz", "x.db3"])
def test_convert_bad_output_suffix_lists_writable_formats_only(
        tmp_path: Path, name: str, capsys: pytest.CaptureFixture) -> None:
    src = tmp_path / "a.imbr"
    with open_writer(src, meta(storage="raw_int16")) as w:
        for b in make_batches():
            w.write(b)
    assert main(["convert", str(src), str(tmp_path / name)]) == 2
    err = capsys.readouterr().err
    assert ".imbr, .csv, .csv.gz or .h5" in err and ".dat with --channel" in err
    assert "mcap" not in err.replace(name, "") and "ROS" not in err


def test_csv_keeps_epoch_time_stamps_exactly(tmp_path: Path) -> None:
    """EuRoC / ROS exports stamp in epoch seconds (~1.4e9): ``t`` must survive a CSV round
    trip (it was cut to 9 significant digits: one stamp per 10 s, step 0)."""
    src = tmp_path / "euroc.csv"
    t_ns = 1403636579758555392 + np.arange(3000, dtype=np.int64) * 5_000_000
    lines = ["#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
             "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]"]
    lines += [f"{t},0.01,0.02,0.03,0.1,0.2,9.81" for t in t_ns.tolist()]
    src.write_text("\n".join(lines) + "\n")
    a = load_recording(src)
    out = tmp_path / "out.csv"
    assert main(["convert", str(src), str(out)]) == 0
    b = load_recording(out)
    assert b.rate_hz == pytest.approx(200.0, rel=1e-9)
    np.testing.assert_array_equal(b.t_s, a.t_s)
    np.testing.assert_array_equal(b.index, a.index)
    # a 30-day log at 1 kHz: the last stamps keep sub-sample resolution
    last = 30 * 86400.0 - np.arange(3)[::-1] * 1e-3
    w_path = tmp_path / "long.csv"
    with open_writer(w_path, meta()) as w:
        n = len(last)
        w.write(Batch(np.arange(n, dtype=np.int64) + 2_592_000_000 - n, last,
                      np.zeros((n, 6)), np.full(n, 25.0)))
    rows = [ln.split(",") for ln in w_path.read_text().splitlines()
            if ln[:1].isdigit()]
    assert [float(r[0]) for r in rows] == last.tolist()
    assert [int(r[-1]) for r in rows] == list(range(2_592_000_000 - 3, 2_592_000_000))


def test_repeated_time_stamps_are_a_clear_error(tmp_path: Path,
                                                capsys: pytest.CaptureFixture) -> None:
    """A file written by the old 9-digit writer: most stamps repeat (step 0). One line
    naming the file and --rate, exit 2 (was a ZeroDivisionError traceback, exit 70)."""
    p = tmp_path / "old.csv"
    rows = [f"{1403636579.758555 + i * 0.005:.9g},0.1,0.2,0.3,0,0,1,25,{i}"
            for i in range(5000)]
    p.write_text("t,gx,gy,gz,ax,ay,az,temp,index\n" + "\n".join(rows) + "\n")
    assert main(["convert", str(p), str(tmp_path / "o.csv")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(p) in err[0] and "--rate HZ" in err[0], err
    with pytest.raises(RecordingError, match="--rate HZ"):
        load_recording(p)
    rec = load_recording(p, InputOptions(rate_hz=200.0))  # the fix the message names
    assert len(rec) == 5000 and rec.rate_hz == 200.0


@pytest.mark.parametrize("rate", [50.0, 100.5, 200.0])
def test_a_rate_that_contradicts_the_time_column_is_refused(tmp_path: Path,
                                                           rate: float) -> None:
    """``--rate`` against stamps 100 Hz apart: read at 50 Hz every second row fell on
    the sample before it (half the file 'damaged'), at 100.5 Hz 2000 rows left 10 holes;
    now it is an error naming both rates."""
    p = tmp_path / "t.csv"
    p.write_text("t,gx\n" + "".join(f"{i / 100:.2f},{i * 1e-3:.3f}\n" for i in range(2000)))
    with pytest.raises(RecordingError, match=rf"--rate {rate:g} Hz contradicts the time "
                                             r"column, which gives 100 Hz"):
        load_recording(p, InputOptions(rate_hz=rate))
    assert load_recording(p, InputOptions(rate_hz=100.0)).lost_samples == 0


@pytest.mark.parametrize("n", [400, 10_000])
def test_a_repeated_line_costs_that_line_only(tmp_path: Path, n: int) -> None:
    """A logger that wrote one line twice: the copy is skipped as damaged, every other row
    keeps its sample and the rate is exact (the copy once shifted the first line's row
    numbers: 104.0267 Hz and 7116 of 10 000 rows on the wrong sample)."""
    rows = [f"{i / 104:.6f},{i}" for i in range(n)]
    rows.insert(n // 3, rows[n // 3])
    p = tmp_path / "dup.csv"
    p.write_text("t,gx\n" + "\n".join(rows) + "\n")
    rec = load_recording(p, InputOptions(gyro_unit="dps"))
    assert rec.rate_hz == pytest.approx(104.0, rel=1e-9)
    assert len(rec) == n and rec.lost_samples == 0
    assert rec.damage is not None and rec.damage.startswith("1 data line(s) skipped")
    np.testing.assert_array_equal(rec.channel("gx"), np.arange(n))


@pytest.mark.parametrize("header", ["timestamp,gyro_x [deg/s]", "gyro_x [deg/s],timestamp"])
def test_a_byte_order_mark_hides_no_column(tmp_path: Path, header: str) -> None:
    """A UTF-8 byte-order mark before the header (Excel's CSV export) is not part of the
    first column's name."""
    first_t = header.startswith("timestamp")
    rows = [(f"{i / 100:.2f},{i * 0.5}" if first_t else f"{i * 0.5},{i / 100:.2f}")
            for i in range(50) if i != 20]
    p = tmp_path / "bom.csv"
    p.write_bytes(b"\xef\xbb\xbf" + (header + "\n" + "\n".join(rows) + "\n").encode())
    rec = load_recording(p)
    assert rec.rate_hz == pytest.approx(100.0) and rec.lost_samples == 1
    assert rec.channel("gx")[19] == 9.5 and np.isnan(rec.channel("gx")[20])


def test_an_uptime_counter_is_not_taken_for_unix_seconds(tmp_path: Path) -> None:
    """Milliseconds since boot after 15 days (1.3e9) have the size of Unix seconds: read
    as such, 100 Hz data became 0.1 Hz. Both readings are plausible: refused with the
    fix; the given unit reads it."""
    p = tmp_path / "uptime.csv"
    p.write_text("timestamp,gyro_x [deg/s]\n" + "".join(
        f"{1_300_000_000 + 10 * i},{i % 5}\n" for i in range(500)))
    with pytest.raises(RecordingError, match=r"read as Unix times in s give 0\.1 Hz; in ms"):
        load_recording(p)
    fast = tmp_path / "uptime2k.csv"  # 2 kHz: read as 2 Hz before
    fast.write_text("timestamp,gyro_x [deg/s]\n" + "".join(
        f"{1_300_000_000 + 0.5 * i},{i % 5}\n" for i in range(500)))
    with pytest.raises(RecordingError, match=r"give 2 Hz; in ms \(a counter since boot\?\) "
                                             r"2000 Hz"):
        load_recording(fast)
    assert load_recording(p, InputOptions(time_unit="ms")).rate_hz == pytest.approx(100.0)


def _indexed(tmp_path: Path, index: list[int], t: list[float]) -> Path:
    p = tmp_path / "idx.csv"
    p.write_text("sample,timestamp,gyro_x [deg/s]\n" + "".join(
        f"{i},{s:.6f},{k * 0.1}\n" for k, (i, s) in enumerate(zip(index, t, strict=True))))
    return p


def test_an_index_column_that_contradicts_the_time_stamps(tmp_path: Path) -> None:
    """A sample-index column is checked against the stamps: a counter of rows written
    beside a 1 s hole in the stamps (read as 97 Hz, nothing lost) and a wrapping 8-bit
    counter (1744 of 2000 rows 'damaged') are refused naming the line; one row whose index
    has a wrong digit (a 90 000-sample hole) is that row's damage only."""
    n = 600
    t = [k / 100 + (1.0 if k >= 300 else 0.0) for k in range(n)]
    with pytest.raises(RecordingError, match=r"disagree at line 302: t advances 1\.01 s while "
                                             r"the index advances 1 samples"):
        load_recording(_indexed(tmp_path, list(range(n)), t))
    with pytest.raises(RecordingError, match=r"goes back at line 258 \(255 -> 0\) and counts up"):
        load_recording(_indexed(tmp_path, [k % 256 for k in range(n)],
                                [k / 100 for k in range(n)]))
    index = list(range(n))
    index[-1] += 90_000
    rec = load_recording(_indexed(tmp_path, index, [k / 100 for k in range(n)]))
    assert len(rec) == n - 1 and rec.lost_samples == 0 and rec.rate_hz == pytest.approx(100)
    assert rec.damage is not None and rec.damage.startswith("1 data line(s) skipped")
    index = list(range(n))
    index[200] = 2_000  # one wrong digit inside the record: that row only
    rec = load_recording(_indexed(tmp_path, index, [k / 100 for k in range(n)]))
    assert len(rec) == n - 1 and rec.lost_samples == 1


def test_a_corrupt_gzip_is_refused_and_a_cut_one_keeps_its_rows(tmp_path: Path) -> None:
    """A flipped bit inside a .csv.gz decodes into wrong text that only the CRC at the
    end reveals: no row is kept. A stream cut short (a writer that crashed) keeps every
    whole row before the cut."""
    import gzip

    text = "t,gx\n" + "".join(f"{i / 100:.2f},{(i * 7919) % 1000 * 1e-3:.3f}\n"
                              for i in range(20_000))
    data = bytearray(gzip.compress(text.encode()))
    data[len(data) // 2] ^= 0x10
    bad = tmp_path / "flip.csv.gz"
    bad.write_bytes(bytes(data))
    with pytest.raises(RecordingError, match="compressed data are corrupt"):
        load_recording(bad, InputOptions(gyro_unit="dps"))
    cut = tmp_path / "cut.csv.gz"
    cut.write_bytes(gzip.compress(text.encode())[:-5000])
    rec = load_recording(cut, InputOptions(gyro_unit="dps"))
    assert 0 < len(rec) < 20_000 and rec.damage is not None
    np.testing.assert_allclose(rec.channel("gx")[:100],
                               [(i * 7919) % 1000 * 1e-3 for i in range(100)])


@pytest.mark.parametrize(("t_head", "t_scale", "temp_head", "temp", "want"), [
    ("time [min]", 1 / 60, "temperature [K]", 299.15, 26.0),
    ("time [s]", 1.0, "temp [F]", 78.8, 26.0),
    ("time [s]", 1.0, "temp [degC]", 26.0, 26.0),
    ("time_h", 1 / 3600, "temp_c", 26.0, 26.0),
    ("t_min", 1 / 60, "temp", 26.0, 26.0),
])
def test_header_units_of_time_and_temperature_are_applied(
        tmp_path: Path, t_head: str, t_scale: float, temp_head: str, temp: float,
        want: float) -> None:
    """``time [min]`` was read as seconds (100 Hz as 6000 Hz), ``temperature [K]`` as
    298.15 degC, and ``time_h`` was no time column: the header's unit (in brackets or
    as a suffix) is applied, or the file refused."""
    p = tmp_path / "u.csv"
    p.write_text(f"{t_head},gyro_x [deg/s],{temp_head}\n" + "".join(
        f"{i / 100 * t_scale:.9f},{i % 3},{temp}\n" for i in range(300)))
    rec = load_recording(p)
    assert rec.rate_hz == pytest.approx(100.0, rel=1e-6)
    assert np.nanmean(rec.temp_c) == pytest.approx(want)


def test_unknown_time_and_temperature_units_are_refused(tmp_path: Path) -> None:
    for head, words in (("time [fortnights],gyro_x [deg/s]", "imubench reads s, ms"),
                        ("t,gyro_x [deg/s],temp [R]", "imubench reads degC, K or degF")):
        p = tmp_path / "u.csv"
        p.write_text(head + "\n" + "".join(
            f"{i / 100},{i % 3}" + (",20\n" if "temp" in head else "\n")
            for i in range(50)))
        with pytest.raises(RecordingError, match=words):
            load_recording(p)


def test_convert_keeps_the_start_time_and_never_invents_it(tmp_path: Path) -> None:
    """``start_utc`` is the source's: stated, else its first Unix time stamp, else
    unknown (null), never the time of the conversion (which dated a 2023 acquisition
    2026 in its Stable32 export)."""
    from imubench.recording import convert

    epoch = tmp_path / "epoch.csv"
    epoch.write_text("timestamp,gyro_x [deg/s]\n" + "".join(
        f"{1_700_000_000 + i / 100:.2f},{i % 3}\n" for i in range(300)))
    plain = tmp_path / "plain.csv"
    plain.write_text("t,gyro_x [deg/s]\n" + "".join(f"{i / 100:.2f},{i % 3}\n"
                                                    for i in range(300)))
    for src, want in ((epoch, "2023-11-14T22:13:20.000000Z"), (plain, None)):
        for suffix in (".imbr", ".csv"):
            dst = tmp_path / f"{src.stem}_out{suffix}"
            convert(src, dst)
            assert load_recording(dst).metadata.get("start_utc") == want, dst


@pytest.mark.parametrize(("text", "rows"), [
    ('"t","gyro_x [deg/s]"\n' + "".join(f'"{i / 100:.2f}","{i * 0.5}"\n' for i in range(50)),
     50),  # every field quoted (a spreadsheet's export)
    ("t,gyro_x [deg/s]\n" + "".join(f"{i / 100:.2f},{i * 0.5},\n" for i in range(50)), 50),
    ("t\tgyro_x [deg/s]\n" + "".join(f"{i / 100:.2f}\t{i * 0.5}\n".replace(".", ",")
                                     for i in range(50)), 50),  # tabs, decimal commas
    ("t,gyro_x [deg/s]\n" + "".join(f"{i / 100:.2f},{'inf' if i == 7 else i * 0.5}\n"
                                    for i in range(50)), 49),  # an inf cell: damaged
])
def test_spreadsheet_exports_read_to_their_values(tmp_path: Path, text: str,
                                                  rows: int) -> None:
    p = tmp_path / ("x.tsv" if "\t" in text else "x.csv")
    p.write_text(text)
    rec = load_recording(p)
    assert len(rec) == rows and rec.rate_hz == pytest.approx(100.0)
    gx = rec.channel("gx")
    assert gx[3] == 1.5 and gx[49] == 24.5
    assert (rec.damage is None) == (rows == 50)


def test_a_whitespace_comment_header_names_the_columns(tmp_path: Path) -> None:
    """``# time gx gy gz`` above whitespace-separated data (docs: a leading # is removed)
    was '4 columns without a header'; prose in a comment is still no header."""
    p = tmp_path / "ws.txt"
    p.write_text("# time gx gy gz\n" + "".join(f"{i / 100:.2f} {i} 0 0\n" for i in range(60)))
    rec = load_recording(p)
    assert rec.channels == ["gx", "gy", "gz"] and rec.rate_hz == pytest.approx(100.0)
    q = tmp_path / "prose.txt"
    q.write_text("# logged with the gx gy rig\n" + "".join(f"{i * 0.5}\n" for i in range(60)))
    assert len(load_recording(q, InputOptions(rate_hz=10.0))) == 60


def test_iso_date_times_are_read_as_utc_seconds(tmp_path: Path) -> None:
    """A logger's (or pandas') ISO 8601 time column, with a 3-sample hole."""
    import datetime as dt

    t0 = dt.datetime(2024, 5, 1, 12, 0, 0)
    stamp = [(t0 + dt.timedelta(milliseconds=10 * i)).isoformat(sep=" ", timespec="milliseconds")
             for i in range(400)]
    rows = [f"{stamp[i]},{i}" for i in range(400) if not 100 <= i < 103]
    p = tmp_path / "iso.csv"
    p.write_text("timestamp,gyro_x [deg/s]\n" + "\n".join(rows) + "\n")
    rec = load_recording(p)
    assert rec.rate_hz == pytest.approx(100.0) and rec.lost_samples == 3
    assert rec.t_s[0] == pytest.approx(t0.replace(tzinfo=dt.UTC).timestamp())
    assert rec.channel("gx")[103] == 103


def test_a_whitespace_header_keeps_units_after_a_space(tmp_path: Path) -> None:
    """``time gyro_x [rad/s]`` separated by spaces: the bracket is the column's unit, not
    a column of its own (the file was 'no readable data lines')."""
    p = tmp_path / "ws.txt"
    p.write_text("time gyro_x [rad/s] gyro_y [rad/s]\n" + "".join(
        f"{i / 100:.2f}  {i * 0.01}  0\n" for i in range(60)))
    rec = load_recording(p)
    assert rec.channels == ["gx", "gy"]
    assert rec.channel("gx")[10] == pytest.approx(0.1 * 180 / math.pi)


@pytest.mark.parametrize("seed", range(24))
def test_time_base_recovers_every_sample_of_random_jittered_holed_stamps(seed: int) -> None:
    """Random records (rate 10 Hz-4 kHz, Unix or zero origin, jitter up to 0.45 periods,
    up to 30 holes of 1-50 samples anywhere, printed to 1 us): every row lands on its own
    sample and the rate is the least-squares one. (The previous time base misread 203 of
    344 such timebases; 900 further random seeds of this recipe: 0 misread.)"""
    from imubench.recording.timebase import timebase_from_times

    rng = np.random.default_rng(seed)
    rate = float(rng.choice([10.0, 104.0, 416.0, 1660.0, 4000.0]))
    n = int(rng.integers(3_000, 60_000))
    index = np.arange(n)
    for h in rng.integers(1, n, int(rng.integers(0, 31))):
        index[h:] += int(rng.integers(1, 51))
    jitter = float(rng.choice([0.0, 0.2, 0.45]))
    origin = float(rng.choice([0.0, 1.7e9]))
    t = np.round(origin + (index + rng.uniform(-jitter, jitter, n)) / rate, 6)
    if rate > 1000 and origin > 0:  # 1 us print steps are >= 0.4 % of a period there
        t = origin + (index + rng.uniform(-jitter, jitter, n)) / rate
    tb = timebase_from_times(t, "x")
    assert tb.keep.all()
    np.testing.assert_array_equal(tb.index, index - index[0])
    assert tb.rate_hz == pytest.approx(rate, rel=2e-5)  # least squares over >= 3000 rows


@pytest.mark.parametrize("damage", ["swapped", "digit", "repeated"])
def test_an_index_column_with_a_few_rows_out_of_order_costs_those_rows(
        tmp_path: Path, damage: str) -> None:
    """Two swapped line pairs, two index cells damaged downward, or two repeated lines:
    those rows are skipped as damaged, the others kept on their samples (this sitting's
    first index check refused such files as a wrapping counter)."""
    n = 5_000
    index = list(range(n))
    t = [i / 100 for i in range(n)]
    lines = [f"{i},{s:.2f},{i * 0.01:.2f}" for i, s in zip(index, t, strict=True)]
    if damage == "swapped":
        for k in (1_000, 3_000):
            lines[k], lines[k + 1] = lines[k + 1], lines[k]
    elif damage == "digit":
        for k in (1_000, 3_000):
            lines[k] = f"{k - 900},{t[k]:.2f},{k * 0.01:.2f}"
    else:
        for k in (3_000, 1_000):
            lines.insert(k, lines[k])
    p = tmp_path / "idx.csv"
    p.write_text("sample,timestamp,gyro_x [deg/s]\n" + "\n".join(lines) + "\n")
    rec = load_recording(p)
    assert rec.damage is not None and rec.rate_hz == pytest.approx(100.0)
    kept = n - (2 if damage in ("swapped", "digit") else 0)
    assert len(rec) == kept
    gx = rec.channel("gx")
    ok = np.isfinite(gx)
    np.testing.assert_allclose(gx[ok], np.nonzero(ok)[0] * 0.01, atol=1e-9)


def _stamped(tmp_path: Path, name: str, stamps: list[str], head: str) -> Path:
    p = tmp_path / name
    rng = np.random.default_rng(3)
    p.write_text(f"{head},gyro_x [dps]\n" + "".join(
        f"{s},{rng.normal():.4f}\n" for s in stamps))
    return p


def test_stamps_rounded_near_the_sample_period_are_read_at_their_rate(
        tmp_path: Path) -> None:
    """An Arduino's millis() at 833 Hz (steps 1, 1, 1, 1, 2 ms) was read as 1000 Hz with
    every sixth sample a hole, and --rate 833 refused; MJD tags with 5 decimals at 1 s as
    1.157 Hz. Rounded stamps are read at their mean spacing, with a note; a 1 kHz grid
    whose holes fall at random keeps its rate and its holes."""
    n = 4000
    p = _stamped(tmp_path, "millis.csv",
                 [str(int(123456 + k * 1000.0 / 833.0)) for k in range(n)], "timestamp_ms")
    rec = load_recording(p)
    assert rec.rate_hz == pytest.approx(833.0, rel=1e-4) and rec.lost_samples == 0
    assert load_recording(p, InputOptions(rate_hz=833.0)).lost_samples == 0
    rng = np.random.default_rng(5)
    k = np.sort(rng.choice(int(n * 1.2), n, replace=False))
    holes = load_recording(_stamped(tmp_path, "holes.csv", [str(123456 + v) for v in k],
                                    "timestamp_ms"))
    assert holes.rate_hz == pytest.approx(1000.0) and holes.lost_samples == k[-1] - k[0] + 1 - n
    mjd = _stamped(tmp_path, "mjd.txt", [f"{60000.5 + s / 86400:.5f}" for s in range(n)],
                   "# mjd")
    assert load_recording(mjd).rate_hz == pytest.approx(1.0, rel=1e-4)


def test_stamps_rounded_coarser_than_the_period_are_refused_with_the_fix(
        tmp_path: Path) -> None:
    """millis() at 1666 Hz: rows share stamps. It was read as 1000 Hz with 40 % of the
    rows skipped as damaged; now refused, and --rate with --columns t=- reads every row
    in order."""
    p = _stamped(tmp_path, "fast.csv",
                 [str(int(123456 + k * 1000.0 / 1666.0)) for k in range(3000)], "timestamp_ms")
    with pytest.raises(RecordingError, match=r"rounded to 0\.001 s.*--columns t=-"):
        load_recording(p)
    rec = load_recording(p, InputOptions(rate_hz=1666.0, columns={"t": "-"}))
    assert len(rec) == 3000 and rec.rate_hz == 1666.0 and rec.lost_samples == 0


def test_a_time_column_is_found_by_its_unit_or_named_in_the_refusal(tmp_path: Path) -> None:
    """``Zeit [s]`` was dropped and `allan` read the table at 1 Hz with its taus labelled
    in seconds (100x wrong at 100 Hz): a column whose header states a time unit is the
    time; a table with a header and no time column is never read at allan's 1 Hz, and
    the refusal names the columns it did not read."""
    body = "".join(f"{k / 100:.2f},{k % 7 * 0.01:.3f}\n" for k in range(500))
    p = tmp_path / "zeit.csv"
    p.write_text("Zeit [s],gyro_x [dps]\n" + body)
    assert load_recording(p).rate_hz == pytest.approx(100.0)
    q = tmp_path / "unknown.csv"
    q.write_text("Uhr,gyro_x [dps]\n" + body)
    with pytest.raises(RecordingError, match=r"--columns t=NAME \(columns not read: Uhr\)"):
        load_recording(q, InputOptions(default_rate_hz=1.0))


def test_a_convert_that_fails_midway_leaves_no_partial_file(tmp_path: Path) -> None:
    """A convert that failed on a full disk left the samples written so far, which then
    read as a complete shorter recording, and blocked a retry ("exists already")."""
    from imubench.recording import CONVERT_BLOCK, convert

    rec = tmp_path / "r.imbr"
    seconds = str(2.5 * CONVERT_BLOCK / 104)
    assert main(["sim", "--chip", "lsm6dsl", "--duration-s", seconds, "--out", str(rec)]) == 0

    def fail(done: int, total: int) -> None:
        if done < total:
            raise OSError(28, "No space left on device")

    for name in ("p.csv", "p.imbr", "p.csv.gz"):
        with pytest.raises(RecordingError, match=f"{name}: No space left on device; nothing"):
            convert(rec, tmp_path / name, on_progress=fail)
        assert not (tmp_path / name).exists()
    convert(rec, tmp_path / "p.csv")  # the retry works
    assert len(load_recording(tmp_path / "p.csv")) == len(load_recording(rec))


def test_a_recording_without_its_end_record_is_read_with_a_warning(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """An .imbr from a killed writer (no end record) was read and converted without a
    word; the converted copy kept no trace that it was cut."""
    from imubench.recording import convert

    rec = tmp_path / "r.imbr"
    assert main(["sim", "--chip", "lsm6dsl", "--duration-s", "2", "--out", str(rec)]) == 0
    whole = load_recording(rec)
    assert whole.complete
    data = rec.read_bytes()
    cut = tmp_path / "cut.imbr"
    cut.write_bytes(data[:-5])  # the end record, cut
    with caplog.at_level("WARNING"):
        got = load_recording(cut)
    assert not got.complete and len(got) == len(whole)
    assert "cut.imbr: no end record: the writer did not close this file" in caplog.text
    convert(cut, tmp_path / "c.csv")
    assert "source_incomplete" in load_recording(tmp_path / "c.csv").metadata
    convert(rec, tmp_path / "w.csv")
    assert "source_incomplete" not in load_recording(tmp_path / "w.csv").metadata


def test_an_upper_case_gz_name_is_compressed(tmp_path: Path) -> None:
    """``OUT.CSV.GZ`` was written as plain text under a gzip name (the writer compared
    the suffix case-sensitively, the reader did not): no reader could open it."""
    from imubench.recording import convert

    rec = tmp_path / "r.imbr"
    assert main(["sim", "--chip", "lsm6dsl", "--duration-s", "1", "--out", str(rec)]) == 0
    convert(rec, tmp_path / "OUT.CSV.GZ")
    assert (tmp_path / "OUT.CSV.GZ").read_bytes()[:2] == b"\x1f\x8b"
    assert len(load_recording(tmp_path / "OUT.CSV.GZ")) == len(load_recording(rec))


@pytest.mark.parametrize("suffix", [".imbr", ".csv", ".h5"])
def test_a_rate_that_contradicts_the_stamps_of_imubench_files_is_refused(
        tmp_path: Path, suffix: str) -> None:
    """``--rate 52`` on imubench's own 104 Hz files was taken without a word (every tau
    twice as long); a foreign CSV's time column was already checked."""
    from imubench.recording import convert

    rec = tmp_path / "r.imbr"
    assert main(["sim", "--chip", "lsm6dsl", "--duration-s", "12", "--out", str(rec)]) == 0
    path = rec if suffix == ".imbr" else tmp_path / f"c{suffix}"
    if path != rec:
        convert(rec, path)
    with pytest.raises(RecordingError, match=r"--rate 52 Hz contradicts the recording's "
                                             r"time stamps, which give 104 Hz"):
        load_recording(path, InputOptions(rate_hz=52.0))
    assert load_recording(path, InputOptions(rate_hz=100.0)).rate_hz == 100.0  # a crystal
    with pytest.raises(RecordingError, match="contradicts"):
        convert(rec, tmp_path / "x.csv", InputOptions(rate_hz=52.0))


def test_a_temperature_column_named_by_its_sensor_is_read(tmp_path: Path) -> None:
    """``imu_temp`` was dropped without a word (only listed in the read-as line)."""
    for name in ("imu_temp", "die_temperature", "chip_temp [degC]", "temperature_c"):
        p = tmp_path / "x.csv"
        p.write_text(f"t,gyro_z [dps],{name}\n" + "".join(
            f"{i / 104:.6f},{0.001 * (i % 7):.4f},{25 + i * 1e-3:.3f}\n" for i in range(500)))
        rec = load_recording(p)
        assert rec.channels == ["gz", "temp"], name
        assert rec.temp_c[10] == pytest.approx(25.01)
        p.unlink()


def test_a_convert_to_hdf5_is_refused_before_it_can_fill_the_disk(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """h5py on a full disk printed seven tracebacks, then a segmentation fault, and left a
    corrupt file. The free space is checked first (a full tmpfs needs root to make: the
    disk's answer is replaced here)."""
    import shutil

    from imubench.recording import convert

    rec = tmp_path / "r.imbr"
    assert main(["sim", "--chip", "lsm6dsl", "--duration-s", "5", "--out", str(rec)]) == 0
    real = shutil.disk_usage

    def full(path: str) -> object:
        u = real(path)
        return type(u)(u.total, u.total - 1000, 1000)

    monkeypatch.setattr(shutil, "disk_usage", full)
    with pytest.raises(RecordingError, match=r"r\.h5: 0\.0 MB free on its disk, .* nothing "
                                             "was written"):
        convert(rec, tmp_path / "r.h5")
    assert not (tmp_path / "r.h5").exists()
    monkeypatch.setattr(shutil, "disk_usage", real)
    convert(rec, tmp_path / "r.h5")
    assert len(load_recording(tmp_path / "r.h5")) == len(load_recording(rec))


@pytest.mark.parametrize("suffix", [".imbr", ".csv"])
def test_a_recording_in_segments_reads_whole_from_its_first_file(
        tmp_path: Path, suffix: str, caplog: pytest.LogCaptureFixture) -> None:
    """A recorder that met a full disk goes on in ``NAME.part2.SUFFIX`` (its header names
    the segment before it, and its gap records the samples not recorded): reading
    ``NAME.SUFFIX`` gives every segment, ``NAME.part2.SUFFIX`` that segment alone, and a
    file of that name that does not continue it is not joined."""
    batches = make_batches(n=1024, lost=0)
    first, second = Batch.concat(batches[:4]), Batch.concat(batches[4:])
    base = tmp_path / f"run{suffix}"
    part2 = segment_path(base, 2)
    assert part2.name == f"run.part2{suffix}"
    with open_writer(base, meta(storage="raw_int16")) as w:
        w.write(first)
    later = Batch(second.index + 300, second.t_s + 300 / 104.0, second.values,
                  second.temp_c, second.raw, (Gap(512 + 300, 300, "disk full: not recorded"),))
    with open_writer(part2, meta(storage="raw_int16", segment=2,
                                 previous_segment=str(base))) as w:
        w.write(later)
    with caplog.at_level("INFO"):
        rec = load_recording(base)
    assert "read with its 1 later segment(s): run.part2" in caplog.text
    assert len(rec) == 1024 and rec.lost_samples == 300
    assert rec.metadata["segments"] == [base.name, part2.name]
    np.testing.assert_array_equal(rec.index, np.r_[first.index, later.index])
    np.testing.assert_allclose(rec.values, np.r_[first.values, later.values], rtol=1e-6)
    gx = rec.channel("gx")
    assert len(gx) == 1324 and np.isnan(gx[512:812]).all()
    alone = load_recording(part2)
    assert len(alone) == 512 and "segments" not in alone.metadata
    other = tmp_path / f"other{suffix}"
    with open_writer(other, meta(storage="raw_int16")) as w:
        w.write(first)
    part2.rename(segment_path(other, 2))
    with caplog.at_level("WARNING"):
        assert len(load_recording(other)) == 512
    assert "not read as a segment of" in caplog.text
    # a leftover segment of another run (another ODR) is not joined either
    caplog.clear()
    stale = segment_path(base, 2)
    with open_writer(stale, meta(storage="raw_int16", odr_hz=416.0, segment=2,
                                 previous_segment=str(base))) as w:
        w.write(later)
    with caplog.at_level("WARNING"):
        assert len(load_recording(base)) == 512
    assert "its odr_hz is 416.0" in caplog.text
    # a missing segment 2 is said when a segment 3 lies beside the first
    caplog.clear()
    stale.rename(segment_path(base, 3))
    with caplog.at_level("WARNING"):
        assert len(load_recording(base)) == 512
    assert f"run.part2{suffix} is missing, so the later segment(s) run.part3{suffix}" \
        in caplog.text
    # a batch over the folder analyses a joined recording once, not its parts again
    from imubench.batchrun.runner import expand_inputs

    segment_path(base, 3).rename(segment_path(base, 2))
    assert segment_path(base, 2) not in expand_inputs(tmp_path)


def test_replace_text_on_a_full_disk_leaves_the_old_file_and_no_partial_one(
        tmp_path: Path) -> None:
    """A jig's result.json on a full disk was left cut at byte 8192 (invalid JSON) while
    its junit.xml read as a pass: a small file is written whole or not at all."""
    from imubench.recording.commit import replace_text

    with small_tmpfs(tmp_path) as disk:
        target = disk / "result.json"
        replace_text(target, '{"verdict": "PASS"}\n')
        (disk / "filler").write_bytes(b"\0" * (60 * 1024))
        with pytest.raises(OSError):
            replace_text(target, "x" * (200 * 1024))
        assert target.read_text() == '{"verdict": "PASS"}\n'
        assert sorted(p.name for p in disk.iterdir()) == ["filler", "result.json"]


def test_hdf5_units_missing_datasets_and_transposed_ones_are_named(tmp_path: Path) -> None:
    """An imubench-format HDF5 file whose /gyro_dps states units rad/s was read as dps
    (57x low); a missing dataset read as "damaged or not HDF5", a transposed one as
    "damaged"."""
    import h5py

    path = tmp_path / "r.h5"
    with open_writer(path, meta(storage="raw_int16")) as w:
        for b in make_batches(n=500, lost=0):
            w.write(b)
    assert len(load_recording(path)) == 500
    with h5py.File(path, "r+") as f:
        f["gyro_dps"].attrs["units"] = "rad/s"
    with pytest.raises(RecordingError, match=r"/gyro_dps states units 'rad/s'"):
        load_recording(path)
    with h5py.File(path, "r+") as f:
        f["gyro_dps"].attrs["units"] = "dps"
        data = f["accel_g"][()]
        del f["accel_g"]
        f["accel_g"] = data.T
    with pytest.raises(RecordingError, match=r"/accel_g is \(3, 500\), transposed"):
        load_recording(path)
    with h5py.File(path, "r+") as f:
        del f["accel_g"]
    with pytest.raises(RecordingError, match=r"no dataset /accel_g: an imubench HDF5"):
        load_recording(path)
