"""Recordings from elsewhere (issue 13, acceptance 1 and 2): the corpus in
``tests/data/foreign`` (written by its ``make_corpus.py``, which says where each layout
comes from) is read to the right rate, channels and values in dps and g, or refused with
one line naming the file and the fix; no command prints a traceback on any of them nor
on random truncations and byte flips of each; one recording written in every format
gives the same ``allan``, ``fit`` and ``gap`` results."""

from __future__ import annotations

import filecmp
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from imubench.errors import RecordingError
from imubench.recording import InputOptions, load_recording

CORPUS = Path(__file__).parent / "data" / "foreign"
sys.path.insert(0, str(CORPUS))
import make_corpus  # noqa: E402
from recording_damage import fuzz  # noqa: E402

TRUTH = make_corpus.truth()
ALL6 = ("gx", "gy", "gz", "ax", "ay", "az")

READ: dict[str, tuple[InputOptions, float, tuple[str, ...], float]] = {
    # file: (options, rate Hz, channels with data, value tolerance (printed digits))
    "imubench_meta.csv": (InputOptions(), 104.0, (*ALL6, "temp"), 1e-8),
    "imubench_native.imbr": (InputOptions(), 104.0, (*ALL6, "temp"), 1e-12),
    "imubench_rounded_t.csv": (InputOptions(), 104.0, ALL6, 1e-6),
    "imubench_rounded_t.csv.gz": (InputOptions(), 104.0, ALL6, 1e-6),
    "logger_units_in_header.csv": (InputOptions(), 104.0, ALL6, 1e-7),
    "logger_no_units.csv": (InputOptions(gyro_unit="dps", accel_unit="g"), 104.0, ALL6,
                            1e-8),
    "spreadsheet_semicolon.csv": (InputOptions(), 104.0, (*ALL6, "temp"), 1e-6),
    "tab_separated.tsv": (InputOptions(), 104.0, ALL6, 1e-8),
    "whitespace_aligned.dat": (InputOptions(), 104.0, ("gx", "gy", "gz"), 1e-6),
    "ros_imu_echo.csv": (InputOptions(), 104.0, ALL6, 1e-9),
    "euroc_imu0_data.csv": (InputOptions(), 104.0, ALL6, 1e-12),
    "stable32_one_column.txt": (InputOptions(rate_hz=104.0), 104.0, ("gx",), 1e-8),
    "stable32_mjd_value.txt": (InputOptions(), 104.0, ("gx",), 1e-8),
    "imubench_t_in_ms.csv": (InputOptions(time_unit="ms"), 104.0, ALL6, 1e-6),
    "headerless_three_columns.txt": (InputOptions(columns={"t": "1", "gx": "2", "gy": "3"}),
                                     104.0, ("gx", "gy"), 1e-6),
    "ros2_bag": (InputOptions(), 104.0, ALL6, 1e-12),
    "ros2_imu.mcap": (InputOptions(topic="/imu/data"), 104.0, ALL6, 1e-12),
}
BINARY = ("imubench_native.imbr", "ros2_bag", "ros2_imu.mcap")
"""Compared by content with what the script writes now (they hold write times)."""
REFUSED: dict[str, str] = {
    # file (read without options): the fix the one-line error must name
    "imubench_t_in_ms.csv": "--time-unit ms",
    "logger_no_units.csv": "--units",
    "headerless_three_columns.txt": "--columns",
    "binary_junk.csv": "not a recording",
    "stable32_one_column.txt": "--rate",
}


def test_the_corpus_is_what_its_script_writes(tmp_path: Path) -> None:
    assert len(READ) >= 12 and set(REFUSED) - set(READ) == {"binary_junk.csv"}
    files = sorted(p.name for p in CORPUS.iterdir()
                   if p.name not in ("make_corpus.py", "__pycache__"))
    assert files == sorted(set(READ) | set(REFUSED))
    copy = tmp_path / "corpus"
    copy.mkdir()
    shutil.copy(CORPUS / "make_corpus.py", copy)
    subprocess.run([sys.executable, str(copy / "make_corpus.py")], check=True)
    for f in files:
        if f in BINARY:
            a, b = load_recording(CORPUS / f), load_recording(copy / f)
            np.testing.assert_array_equal(a.values, b.values)
        else:
            assert filecmp.cmp(CORPUS / f, copy / f, shallow=False), f


@pytest.mark.parametrize("name", sorted(READ))
def test_each_file_reads_to_its_rate_channels_and_values(name: str) -> None:
    options, rate, channels, tol = READ[name]
    rec = load_recording(CORPUS / name, options)
    assert rec.rate_hz == pytest.approx(rate, rel=1e-6), name
    assert tuple(rec.channels) == channels
    assert len(rec) == make_corpus.N and rec.lost_samples == 0 and rec.damage is None
    for ch in channels:  # (temperature is stored as float32 in .imbr)
        atol = max(tol * 10, 1e-5) if ch == "temp" else tol * 10
        np.testing.assert_allclose(rec.channel(ch), TRUTH[ch], rtol=0, atol=atol,
                                   err_msg=f"{name} {ch}")


@pytest.mark.parametrize("name", sorted(REFUSED))
def test_refusals_are_one_line_naming_the_file_and_the_fix(name: str) -> None:
    with pytest.raises(RecordingError) as err:
        load_recording(CORPUS / name)
    text = str(err.value)
    assert "\n" not in text and text.startswith(str(CORPUS / name))
    assert REFUSED[name] in text


def test_commands_name_the_file_and_never_print_a_traceback() -> None:
    for name in ("logger_no_units.csv", "binary_junk.csv", "imubench_rounded_t.csv"):
        for cmd in (["allan", "--stat", "oadev", "--column", "gx"],
                    ["fit", "-o", "/dev/null", "--channels", "gx", "--terms", "white"]):
            p = subprocess.run([sys.executable, "-m", "imubench", cmd[0],
                                str(CORPUS / name), *cmd[1:]], capture_output=True,
                               text=True, timeout=300)
            assert "Traceback" not in p.stderr, p.stderr
            if name != "imubench_rounded_t.csv":
                assert p.returncode == 2 and f"{CORPUS / name}:" in p.stderr
            else:
                assert p.returncode == 0, p.stderr
                assert "rate 104 Hz (from t (least squares))" in p.stderr


def test_fuzzed_corpus_never_raises_anything_but_a_named_error(tmp_path: Path) -> None:
    counts = fuzz(READ, 60, tmp_path)
    assert sum(counts.values()) == 60 * len(READ)
    assert counts["refused"] and counts["damage reported"] and counts["read"]


@pytest.mark.slow
def test_fuzzed_corpus_1000_each(tmp_path: Path) -> None:
    counts = fuzz(READ, 1000, tmp_path)
    assert sum(counts.values()) == 1000 * len(READ)


def test_a_flipped_bit_in_a_native_record_loses_that_record_only(tmp_path: Path) -> None:
    from imubench.batch import Batch
    from imubench.recording import NativeWriter

    path = tmp_path / "r.imbr"
    with NativeWriter(path, {"odr_hz": 100.0, "storage": "float64"}) as w:
        for b in range(10):
            idx = np.arange(b * 100, (b + 1) * 100)
            w.write(Batch(idx, idx / 100.0, np.ones((100, 6)), np.full(100, 25.0)))
    data = bytearray(path.read_bytes())
    whole = load_recording(path)
    start = len(data) // 2
    data[start] ^= 0x10
    path.write_bytes(bytes(data))
    rec = load_recording(path)
    assert rec.damage is not None and "resumed at byte" in rec.damage
    assert len(whole) - len(rec) == 100 and rec.lost_samples == 100
    assert rec.complete  # the end record after the damage was read


def write_mcap(path: Path, t_s: np.ndarray, values: np.ndarray) -> None:
    """``sensor_msgs/msg/Imu`` messages (rad/s, m/s^2) in a standalone MCAP file, as the
    corpus script writes them."""
    import tempfile

    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    t = ts.types
    imu, vec = t["sensor_msgs/msg/Imu"], t["geometry_msgs/msg/Vector3"]
    with tempfile.TemporaryDirectory() as tmp:
        with Writer(Path(tmp) / "b", version=8, storage_plugin=StoragePlugin.MCAP) as w:
            conn = w.add_connection("/imu", imu.__msgtype__, typestore=ts)
            for ts_s, row in zip(t_s, values, strict=True):
                ns = 1_700_000_000 * 10**9 + round(ts_s * 1e9)
                w_, a_ = np.deg2rad(row[:3]), row[3:] * 9.80665
                msg = imu(header=t["std_msgs/msg/Header"](
                    stamp=t["builtin_interfaces/msg/Time"](sec=ns // 10**9,
                                                           nanosec=ns % 10**9),
                    frame_id="imu"),
                    orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                    orientation_covariance=np.zeros(9),
                    angular_velocity=vec(x=w_[0], y=w_[1], z=w_[2]),
                    angular_velocity_covariance=np.zeros(9),
                    linear_acceleration=vec(x=a_[0], y=a_[1], z=a_[2]),
                    linear_acceleration_covariance=np.zeros(9))
                w.write(conn, ns, ts.serialize_cdr(msg, imu.__msgtype__))
        shutil.copyfile(next((Path(tmp) / "b").glob("*.mcap")), path)


SAME_SECONDS = 300
"""Length of the recording written in every format (a few minutes: enough taus for fit
and gap, a few seconds per command)."""


def same_recording_in_every_format(tmp: Path) -> dict[str, tuple[Path, list[str]]]:
    """One simulated recording as .imbr, CSV with metadata, CSV without metadata with t
    rounded to 6 decimals, .csv.gz, MCAP (sensor_msgs/Imu) and Stable32 one-column text
    of gx; each with the command-line options it needs."""
    from imubench.recording import convert

    src = tmp / "sim.imbr"
    subprocess.run([sys.executable, "-m", "imubench", "sim", "--chip", "lsm6dsl",
                    "--odr-hz", "104", "--duration-s", str(SAME_SECONDS), "--model",
                    "datasheet:lsm6dsl", "--seed", "5", "--out", str(src)],
                   check=True, capture_output=True)
    rec = load_recording(src)
    convert(src, tmp / "meta.csv")
    convert(src, tmp / "meta.csv.gz")
    lines = ["t,gx,gy,gz,ax,ay,az"] + [
        f"{(i - rec.index[0]) / rec.rate_hz:.6f}," + ",".join(f"{v:.9g}" for v in row)
        for i, row in zip(rec.index, rec.values, strict=True)]
    (tmp / "plain.csv").write_text("\n".join(lines) + "\n")
    (tmp / "gx.txt").write_text("".join(f"{v:.17g}\n" for v in rec.channel("gx")))
    write_mcap(tmp / "rec.mcap", rec.index / rec.rate_hz, rec.values)
    return {"imbr": (src, []), "csv": (tmp / "meta.csv", []),
            "plain": (tmp / "plain.csv", []), "csv.gz": (tmp / "meta.csv.gz", []),
            "mcap": (tmp / "rec.mcap", []), "stable32": (tmp / "gx.txt", ["--rate", "104"])}


def _command_json(argv: list[str], out: Path) -> dict:
    """Run ``imubench ARGV --json OUT`` in this process; its JSON."""
    from imubench.cli import main

    assert main([*argv, "--progress", "off", "--json", str(out)]) == 0, argv
    return json.loads(out.read_text())


def test_one_recording_in_every_format_gives_the_same_results(tmp_path: Path) -> None:
    """Acceptance 2: the same rate (1e-6 relative), ADEV, fitted parameters and gap
    verdict from each format. The CSVs print values to 9 significant digits, so numbers
    agree to ~1e-8 relative, not exactly; tolerances say how far."""
    files = same_recording_in_every_format(tmp_path)
    got: dict[str, dict[str, dict]] = {}
    for kind, (path, opts) in files.items():
        rec = load_recording(path, InputOptions(rate_hz=104.0) if opts else InputOptions())
        assert rec.rate_hz == pytest.approx(104.0, rel=1e-6), kind
        assert len(rec) == SAME_SECONDS * 104 and rec.lost_samples == 0, kind
        d = tmp_path / kind.replace(".", "_")
        d.mkdir()
        got[kind] = {
            "allan": _command_json(["allan", str(path), "--stat", "oadev", "--column", "gx",
                                    *opts], d / "allan.json"),
            "fit": _command_json(["fit", str(path), "-o", str(d / "model.toml"),
                                  "--channels", "gx", "--terms", "white,flicker,random_walk",
                                  *opts], d / "fit.json"),
            "gap": _command_json(["gap", str(path), "--model", "datasheet:lsm6dsl",
                                  "--channels", "gx", "--realisations", "4",
                                  "--effects", "flicker,random_walk,quantization", *opts],
                                 d / "gap.json"),
        }
    ref = got["imbr"]
    for kind, res in got.items():
        a, r = res["allan"], ref["allan"]
        assert a["rate_hz"] == pytest.approx(104.0, rel=1e-6), kind
        np.testing.assert_allclose(a["tau_s"], r["tau_s"], rtol=1e-6, err_msg=kind)
        np.testing.assert_allclose(a["dev"], r["dev"], rtol=1e-6, err_msg=kind)
        f, fr = res["fit"]["channels"]["gx"], ref["fit"]["channels"]["gx"]
        assert f["present"] == fr["present"], kind
        for key, value in f["params"].items():
            assert value == pytest.approx(fr["params"][key], rel=1e-5, abs=1e-12), (kind, key)
        g, gr = res["gap"]["channels"]["gx"], ref["gap"]["channels"]["gx"]
        assert g["verdict"] == gr["verdict"], kind
        assert [e["effect"] for e in g["effects"]] == [e["effect"] for e in gr["effects"]]
        for key in ("gap_before", "gap_after"):
            assert g[key] == pytest.approx(gr[key], rel=1e-5), (kind, key)
