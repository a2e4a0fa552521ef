"""Exports (issue 13): one channel to a Stable32 / allantools data file
(``convert OUT.dat --channel``) and whole recordings to HDF5 (``.h5``), each read back by
the one reader to the same values, rate, gaps and metadata."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from imubench.batch import Batch, Gap
from imubench.errors import RecordingError
from imubench.recording import NativeWriter, convert, load_recording

RATE_HZ = 104.0


def _recording(path: Path, *, holes: bool, raw: bool = False) -> Path:
    """2000 samples of noise at 104 Hz (gx..az, temp), optionally with two holes (5
    samples lost to a declared FIFO overrun, 3 unexplained), and raw counts."""
    rng = np.random.default_rng(3)
    idx = np.arange(2000, dtype=np.int64)
    if holes:
        idx = np.delete(idx, [*range(500, 505), *range(1500, 1503)])
    n = len(idx)
    counts = rng.integers(-2000, 2000, (n, 6)).astype(np.int16)
    values = counts * np.array([0.00875] * 3 + [0.000061] * 3)
    meta = {"odr_hz": RATE_HZ, "chip": "lsm6dsl", "start_utc": "2026-11-24T12:00:00Z",
            "storage": "raw_int16" if raw else "float64", "gyro_sensitivity_dps": 0.00875,
            "accel_sensitivity_g": 0.000061, "source_config": {"seed": 3, "model": "m"}}
    with NativeWriter(path, meta) as w:
        w.write(Batch(idx, idx / RATE_HZ, values, 25.0 + rng.normal(0, 0.1, n),
                      counts if raw else None, (Gap(505, 5, "fifo_overrun"),) if holes else ()))
    return path


@pytest.mark.parametrize("holes", [False, True])
def test_stable32_export_reads_back_to_the_same_values(tmp_path: Path, holes: bool) -> None:
    src = load_recording(_recording(tmp_path / "r.imbr", holes=holes))
    out = tmp_path / "gx.dat"
    convert(src.path, out, channel="gx")
    text = out.read_text().splitlines()
    comments = [line for line in text if line.startswith("#")]
    data = [line for line in text if not line.startswith("#")]
    assert text[: len(comments)] == comments  # comments first, then only data lines
    assert len(data) == len(src) and all(len(d.split()) == (2 if holes else 1) for d in data)
    back = load_recording(out)
    assert back.rate_hz == RATE_HZ and back.channels == ["gx"]
    assert back.lost_samples == src.lost_samples == (8 if holes else 0)
    np.testing.assert_array_equal(back.channel("gx"), src.channel("gx"))  # bit for bit
    if not holes:  # allantools' reader: skip '#' lines, one float per line
        np.testing.assert_array_equal(np.loadtxt(out, comments="#"), src.channel("gx"))
    else:  # MJD tags from start_utc (2026-11-24 12:00 UTC = MJD 61368.5)
        assert float(data[0].split()[0]) == pytest.approx(61368.5, abs=1e-9)


def test_stable32_export_of_an_accelerometer_channel_reads_back_as_that_channel(
        tmp_path: Path) -> None:
    src = load_recording(_recording(tmp_path / "r.imbr", holes=False))
    convert(src.path, tmp_path / "az.dat", channel="az")
    back = load_recording(tmp_path / "az.dat")
    assert back.channels == ["az"]
    np.testing.assert_array_equal(back.channel("az"), src.channel("az"))


def test_stable32_export_needs_a_channel_and_never_overwrites(tmp_path: Path) -> None:
    src = _recording(tmp_path / "r.imbr", holes=False)
    with pytest.raises(RecordingError, match="--channel gx"):
        convert(src, tmp_path / "x.dat")
    (tmp_path / "x.dat").write_text("keep me\n")
    with pytest.raises(RecordingError, match="exists already"):
        convert(src, tmp_path / "x.dat", channel="gx")
    assert (tmp_path / "x.dat").read_text() == "keep me\n"
    with pytest.raises(RecordingError, match="--channel is for a Stable32"):
        convert(src, tmp_path / "x.csv", channel="gx")


@pytest.mark.parametrize("raw", [False, True])
def test_hdf5_round_trip_keeps_values_gaps_raw_counts_and_metadata(tmp_path: Path,
                                                                  raw: bool) -> None:
    src = load_recording(_recording(tmp_path / "r.imbr", holes=True, raw=raw))
    convert(src.path, tmp_path / "r.h5")
    back = load_recording(tmp_path / "r.h5")
    np.testing.assert_array_equal(back.index, src.index)
    np.testing.assert_array_equal(back.t_s, src.t_s)
    np.testing.assert_array_equal(back.values, src.values)
    np.testing.assert_array_equal(back.temp_c, src.temp_c)
    if raw:
        assert back.raw is not None and src.raw is not None
        np.testing.assert_array_equal(back.raw, src.raw)
    else:
        assert back.raw is None
    assert sorted(back.gaps, key=lambda g: g.at) == sorted(src.gaps, key=lambda g: g.at)
    assert back.lost_samples == src.lost_samples == 8
    assert back.complete
    for key in ("odr_hz", "chip", "start_utc", "source_config", "gyro_sensitivity_dps"):
        assert back.metadata[key] == src.metadata[key], key
    assert back.metadata["converted_from"] == str(src.path)
    convert(tmp_path / "r.h5", tmp_path / "again.imbr")  # and back to native
    np.testing.assert_array_equal(load_recording(tmp_path / "again.imbr").values, src.values)


def test_hdf5_datasets_are_chunked_compressed_checksummed_and_carry_units(
        tmp_path: Path) -> None:
    import h5py

    src = _recording(tmp_path / "r.imbr", holes=True, raw=True)
    convert(src, tmp_path / "r.h5")
    with h5py.File(tmp_path / "r.h5", "r") as f:
        assert f.attrs["odr_hz"] == RATE_HZ
        assert json.loads(f.attrs["source_config"].decode()) == {"seed": 3, "model": "m"}
        units = {}
        for name in ("index", "t_s", "gyro_dps", "accel_g", "temp_c", "raw"):
            ds = f[name]
            assert ds.chunks is not None and ds.compression == "gzip" and ds.fletcher32
            assert ds.maxshape[0] is None
            units[name] = ds.attrs["units"].decode()
        assert units["t_s"] == "s" and units["gyro_dps"] == "dps" and units["accel_g"] == "g"
        assert units["temp_c"] == "degC"
        assert [r.decode() for r in f["gaps/reason"][()]] == ["fifo_overrun", "unexplained"]
        assert list(f["gaps/lost"][()]) == [5, 3]
        assert f["gaps/lost"].attrs["units"].decode() == "samples"


def test_a_damaged_or_foreign_hdf5_file_is_refused_naming_it(tmp_path: Path) -> None:
    import h5py

    convert(_recording(tmp_path / "r.imbr", holes=False), tmp_path / "r.h5")
    data = (tmp_path / "r.h5").read_bytes()
    cut = tmp_path / "cut.h5"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(RecordingError, match=f"^{cut}: cannot read the HDF5 file"):
        load_recording(cut)
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f["x"] = np.arange(3)
    with pytest.raises(RecordingError, match=f"^{other}: .*not an imubench recording"):
        load_recording(other)
    flipped = bytearray(data)  # a byte of the compressed gyro data: the checksum sees it
    with h5py.File(tmp_path / "r.h5", "r") as f:
        offset = f["gyro_dps"].id.get_offset() if f["gyro_dps"].chunks is None else (
            f["gyro_dps"].id.get_chunk_info(0).byte_offset)
    flipped[offset + 10] ^= 0x01
    bad = tmp_path / "flipped.h5"
    bad.write_bytes(bytes(flipped))
    with pytest.raises(RecordingError, match=f"^{bad}: cannot read"):
        load_recording(bad)


def _calibration_file(path: Path) -> Path:
    """A gyro calibration: offset (0.1, -0.2, 0.3) dps, x scale +2 %."""
    from imubench.calibration import Calibration, SensorCalibration

    gyro = SensorCalibration(unit="dps", method="test", temp_ref_c=25.0,
                             offset=np.array([0.1, -0.2, 0.3]),
                             matrix=np.diag([1.02, 1.0, 1.0]))
    prov = {"serial": "B7", "date_utc": "2026-11-20T10:00:00Z", "station": "bench-1"}
    Calibration(prov, gyro=gyro).save(path)
    return path


@pytest.mark.parametrize("suffix", [".imbr", ".csv", ".h5"])
def test_convert_with_a_calibration_file_corrects_values_and_keeps_raw_counts(
        tmp_path: Path, suffix: str) -> None:
    src = load_recording(_recording(tmp_path / "r.imbr", holes=True, raw=True))
    cal = _calibration_file(tmp_path / "cal.toml")
    out = tmp_path / f"c{suffix}"
    convert(src.path, out, calibration=cal)
    back = load_recording(out)
    want_g = (src.values[:, :3] - [0.1, -0.2, 0.3]) / [1.02, 1.0, 1.0]
    rtol = 1e-8 if suffix == ".csv" else 1e-15  # CSV prints 9 significant digits
    np.testing.assert_allclose(back.values[:, :3], want_g, rtol=rtol)
    np.testing.assert_allclose(back.values[:, 3:], src.values[:, 3:], rtol=rtol)
    header = back.metadata["calibration"]
    assert header["applied"] and header["path"] == str(cal)
    assert header["provenance"]["serial"] == "B7"
    if suffix != ".csv":  # CSV holds no raw counts
        assert back.raw is not None and src.raw is not None
        np.testing.assert_array_equal(back.raw, src.raw)
    with pytest.raises(RecordingError, match="applied already; drop --calibration"):
        convert(out, tmp_path / f"twice{suffix}", calibration=cal)


def test_convert_drops_secrets_of_an_old_header_and_says_so(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """A header as the first daemon wrote it: the whole configuration, the MQTT password
    in clear (and one in a broker URL); a current header's mask is kept."""
    secret = "pw-Zq8v1K-never-echo"
    meta = {"odr_hz": RATE_HZ, "storage": "float64",
            "config": {"mqtt": {"host": "127.0.0.1", "username": "imu", "password": secret},
                       "web": {"password": "**********"},
                       "sensors": [{"uri": f"mqtt://imu:{secret}@broker:1883/x"}]}}
    src = tmp_path / "old.imbr"
    with NativeWriter(src, meta) as w:
        w.write(Batch(np.arange(10), np.arange(10) / RATE_HZ, np.ones((10, 6)),
                      np.full(10, 25.0)))
    for suffix in (".csv", ".imbr", ".h5"):
        out = tmp_path / f"new{suffix}"
        with caplog.at_level("WARNING", logger="imubench.recording"):
            convert(src, out)
        assert secret.encode() not in out.read_bytes()
        cfg = load_recording(out).metadata["config"]
        assert "password" not in cfg["mqtt"] and cfg["mqtt"]["username"] == "imu"
        assert cfg["web"]["password"] == "**********"
        assert cfg["sensors"][0]["uri"] == "mqtt://imu@broker:1883/x"
    said = [r.getMessage() for r in caplog.records if "secret" in r.getMessage()]
    assert len(said) == 3 and "config.mqtt.password" in said[0]
    assert secret not in " ".join(said)


def test_every_secret_field_of_the_configuration_is_a_secret_key() -> None:
    """The rule :mod:`imubench.recording.secrets` applies to old headers covers every
    field the configuration keeps secret."""
    from pydantic import BaseModel, SecretStr

    from imubench.config import Config
    from imubench.recording.secrets import is_secret_key

    def secret_fields(model: type[BaseModel], where: str) -> list[str]:
        out = []
        for name, f in model.model_fields.items():
            ann = f.annotation
            args = getattr(ann, "__args__", (ann,))
            if SecretStr in args:
                out.append(f"{where}{name}")
            for a in args:
                if isinstance(a, type) and issubclass(a, BaseModel):
                    out += secret_fields(a, f"{where}{name}.")
        return out

    found = secret_fields(Config, "")
    assert "mqtt.password" in found and "web.password" in found
    assert all(is_secret_key(path.rsplit(".", 1)[-1]) for path in found), found


def test_convert_command_shows_progress_and_says_what_it_wrote(tmp_path: Path) -> None:
    import subprocess
    import sys

    src = _recording(tmp_path / "r.imbr", holes=False)
    p = subprocess.run([sys.executable, "-m", "imubench", "convert", str(src),
                        str(tmp_path / "gy.dat"), "--channel", "gy", "--progress", "on"],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert "Stable32 data file of gy in dps, 2000 values, tau0 0.00961538 s" in p.stdout
    assert "convert" in p.stderr and "100%" in p.stderr  # the bar, on stderr only


def test_stable32_export_counts_and_places_the_gaps_at_either_end(tmp_path: Path) -> None:
    """A recording that starts and ends in a declared gap: the .dat said lost_samples 0
    and, one value per line from the header's start_utc, put every sample 30 periods
    (0.288 s) early; a calibrated or damaged source was not stated."""
    rng = np.random.default_rng(4)
    idx = np.arange(30, 1990, dtype=np.int64)
    meta = {"odr_hz": RATE_HZ, "chip": "lsm6dsl", "start_utc": "2026-11-24T12:00:00Z",
            "storage": "float64"}
    path = tmp_path / "ends.imbr"
    with NativeWriter(path, meta) as w:
        w.write(Batch(idx, idx / RATE_HZ, rng.normal(0, 0.01, (len(idx), 6)),
                      np.full(len(idx), 25.0), None, (Gap(30, 30, "chip reset"),)))
        w.write(Batch.empty(gaps=(Gap(2000, 10, "chip reset"),)))
    src = load_recording(path)
    assert src.lost_samples == 40
    out = tmp_path / "gx.dat"
    convert(path, out, channel="gx")
    head = {line[2:].split(": ", 1)[0]: json.loads(line.split(": ", 1)[1])
            for line in out.read_text().splitlines()[1:] if line.startswith("# ")}
    assert head["lost_samples"] == 40
    assert head["start_utc"] == "2026-11-24T12:00:00.288461Z"  # the first line's time
    first_tag = float(next(line for line in out.read_text().splitlines()
                           if not line.startswith("#")).split()[0])
    assert first_tag == pytest.approx(61368.5 + 30 / RATE_HZ / 86400.0, abs=1e-11)
    back = load_recording(out)
    assert back.metadata["start_utc"] == head["start_utc"]
    assert back.t_s[0] == 0.0 and back.t_s[1] == pytest.approx(1 / RATE_HZ, rel=1e-4)
    np.testing.assert_array_equal(back.channel("gx"), src.channel("gx"))


def test_a_stable32_export_of_unix_stamped_data_keeps_its_start(tmp_path: Path) -> None:
    """A CSV of Unix-second stamps converted to .dat said "states no start", its MJD tags
    from 2000-01-01; the first stamp is its start."""
    from imubench.cli import main

    src = tmp_path / "u.csv"
    src.write_text("timestamp,gyro_x [dps]\n" + "\n".join(
        f"{1700000000 + k / 100:.2f},{k % 5}" for k in range(3000)) + "\n")
    out = tmp_path / "u.dat"
    assert main(["convert", str(src), str(out), "--channel", "gx"]) == 0
    text = out.read_text()
    assert '# start_utc: "2023-11-14T22:13:20' in text
