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

from imubench.batch import Batch
from imubench.errors import RecordingError
from imubench.recording import InputOptions, load_recording, open_writer

CORPUS = Path(__file__).parent / "data" / "foreign"
sys.path.insert(0, str(CORPUS))
import make_corpus  # noqa: E402
from recording_damage import (  # noqa: E402
    CHEAP_COMMANDS,
    COMMANDS,
    check_command,
    cli_flags,
    command_argv,
    fuzz,
    run_command,
)

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
    "imubench_hdf5.h5": (InputOptions(), 104.0, (*ALL6, "temp"), 1e-12),
    "imubench_stable32_export.dat": (InputOptions(), 104.0, ("gx",), 1e-16),
}
BINARY = ("imubench_native.imbr", "ros2_bag", "ros2_imu.mcap", "imubench_hdf5.h5")
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


NO_ACCEL = {"stable32_one_column.txt", "stable32_mjd_value.txt",
            "headerless_three_columns.txt", "whitespace_aligned.dat",
            "imubench_stable32_export.dat"}
"""Corpus files without accelerometer channels: ``tilt`` refuses them, naming the file."""
REPORT_SAMPLE = ("imubench_native.imbr", "euroc_imu0_data.csv", "stable32_mjd_value.txt",
                 "ros2_bag")
"""``report`` draws plots (seconds per file): these by default, every file with -m slow."""


def _command_on_corpus(command: str, names: tuple[str, ...] | list[str], tmp: Path) -> None:
    """``command`` on each named corpus file (with its options) gives the file's rate and
    channels, or refuses it with an error naming it; on each refused file (without
    options), an error naming the file and the fix."""
    for name in names:
        options, rate, channels, _ = READ[name]
        out = tmp / f"ok-{name}"
        out.mkdir()
        path = CORPUS / name
        status = check_command(command_argv(command, path, out) + cli_flags(options), path)
        if command == "gap" or (command == "tilt" and name in NO_ACCEL):
            assert status == 2, (command, name)  # gap: 2 s are too few to compare ADEVs
            continue
        assert status == 0, (command, name)
        if command == "convert":
            rec = load_recording(out / "converted.imbr")
            assert rec.rate_hz == pytest.approx(rate, rel=1e-6)
            assert tuple(rec.channels) == channels and len(rec) == make_corpus.N
        elif command == "report":
            assert (out / "report" / "index.html").is_file()
        else:
            doc = json.loads((out / f"{command}.json").read_text())
            got = doc["odr_hz" if command == "tilt" else "rate_hz"]
            assert got == pytest.approx(rate, rel=1e-6), (command, name)
            if command == "fit":
                assert list(doc["channels"]) == ["gx"]
            if command == "tilt":
                assert len(doc["t_s"]) == make_corpus.N // 16
    for name, fix in REFUSED.items():
        if command == "report" and name not in (*REPORT_SAMPLE, "binary_junk.csv"):
            continue
        out = tmp / f"refused-{name}"
        out.mkdir()
        path = CORPUS / name
        status, _, err = run_command(command_argv(command, path, out))
        if command == "allan" and name == "stable32_one_column.txt":
            assert status == 0  # as Stable32: no rate, tau in samples (1 Hz)
            assert json.loads((out / "allan.json").read_text())["rate_hz"] == 1.0
            continue
        errors = [line for line in err.splitlines() if "error:" in line]
        assert status == 2 and "Traceback" not in err, err
        assert len(errors) == 1, err
        assert errors[0].startswith(f"imubench {command}: error: {path}") and fix in errors[0]


@pytest.mark.parametrize("command", [*CHEAP_COMMANDS,
                                     pytest.param("report", marks=pytest.mark.slow)])
def test_every_command_reads_every_corpus_file_or_names_it_and_the_fix(
        command: str, tmp_path: Path) -> None:
    names = REPORT_SAMPLE if command == "report" else sorted(READ)
    _command_on_corpus(command, names, tmp_path)


@pytest.mark.slow
def test_report_reads_every_corpus_file(tmp_path: Path) -> None:
    _command_on_corpus("report", sorted(READ), tmp_path)


def test_a_folder_of_foreign_recordings_runs_as_a_batch(tmp_path: Path) -> None:
    """A directory with a ROS 2 bag folder, an MCAP file, imubench's and EuRoC's files and
    junk: each recording is one row (the bag folder too, not a directory to descend
    into); the junk is a failed row naming it."""
    folder = tmp_path / "in"
    folder.mkdir()
    for name in ("ros2_bag", "ros2_imu.mcap", "imubench_native.imbr", "euroc_imu0_data.csv",
                 "binary_junk.csv"):
        src = CORPUS / name
        if src.is_dir():
            shutil.copytree(src, folder / name)
        else:
            shutil.copy(src, folder)
    status, _, err = run_command(["fit", str(folder), "--channels", "gx", "--terms", "white",
                                  "--out-dir", str(tmp_path / "out")])
    assert "Traceback" not in err and status == 2, err  # 2: one recording failed
    assert f"imubench fit: error: {folder / 'binary_junk.csv'}: 14 of 14" in err
    table = json.loads((tmp_path / "out" / "fit.json").read_text())
    assert table["failed"] == 1
    rows = {Path(r["recording"]).name: r for r in table["rows"]}
    assert set(rows) == {"ros2_bag", "ros2_imu.mcap", "imubench_native.imbr",
                         "euroc_imu0_data.csv", "binary_junk.csv"}
    for name, row in rows.items():
        if name == "binary_junk.csv":
            assert "not a recording" in row["error"]
        else:
            assert row["rate_hz"] == pytest.approx(104.0, rel=1e-6) and not row.get("error")
    status, _, err = run_command(["allan", str(CORPUS / "ros2_bag"), "--stat", "oadev",
                                  "--column", "gx", "--json", str(tmp_path / "bag.json")])
    assert status == 0, err  # one bag folder is one recording, not a batch


def test_fuzzed_corpus_never_raises_anything_but_a_named_error(
        tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    """60 damaged copies of each file through the reader, every 10th also through a
    command; nothing printed outside the log (the MCAP decoder's own prints become one
    warning on ``imubench.recording``)."""
    counts = fuzz(READ, 60, tmp_path, command_every=10)
    reads = counts["read"] + counts["damage reported"] + counts["refused"]
    assert reads == 60 * len(READ)
    assert counts["command ok"] + counts["command refused"] == 60 * len(READ) // 10
    assert counts["refused"] and counts["damage reported"] and counts["read"]
    assert counts["command ok"] and counts["command refused"]
    assert capfd.readouterr() == ("", "")


@pytest.mark.slow
@pytest.mark.timeout(2400)
def test_fuzzed_corpus_1000_each(tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    """Acceptance 1's count: 1000 damaged copies of each file through the reader, every
    50th through a command (``report`` included; 380 commands)."""
    counts = fuzz(READ, 1000, tmp_path, command_every=50, commands=COMMANDS)
    reads = counts["read"] + counts["damage reported"] + counts["refused"]
    assert reads == 1000 * len(READ)
    assert counts["command ok"] + counts["command refused"] == 1000 * len(READ) // 50
    assert capfd.readouterr() == ("", "")


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


SAME_SECONDS = 120
"""Length of the recording written in every format (two minutes: enough taus for fit
and gap; each format's reader, the MCAP one most, takes time in proportion)."""


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


def write_bag(path: Path, stamps_ns: list[int], frames: list[str] | None = None,
              gyro_cov0: float = 0.0) -> None:
    """A ROS 2 bag (SQLite) of ``sensor_msgs/msg/Imu`` messages with the given header
    stamps, written in list order (receipt order) as ``ros2 bag`` would."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    t = ts.types
    imu, vec = t["sensor_msgs/msg/Imu"], t["geometry_msgs/msg/Vector3"]
    cov = np.zeros(9)
    cov[0] = gyro_cov0
    with Writer(path, version=8, storage_plugin=StoragePlugin.SQLITE3) as w:
        conn = w.add_connection("/imu", imu.__msgtype__, typestore=ts)
        for i, ns in enumerate(stamps_ns):
            msg = imu(header=t["std_msgs/msg/Header"](
                stamp=t["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9),
                frame_id=frames[i] if frames else "imu"),
                orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=np.zeros(9),
                angular_velocity=vec(x=0.01 * i, y=0.0, z=0.0),
                angular_velocity_covariance=cov.copy(),
                linear_acceleration=vec(x=0.0, y=0.0, z=9.80665),
                linear_acceleration_covariance=np.zeros(9))
            w.write(conn, 1_700_000_000 * 10**9 + i * 5_000_000,
                    ts.serialize_cdr(msg, imu.__msgtype__))


def test_bag_messages_are_read_in_stamp_order_with_their_start_time(tmp_path: Path) -> None:
    """Every 100th pair of stamps swapped (received out of order): 19 messages were
    skipped and every ADEV from 0.32 s on was empty; the start time was lost in
    ``convert`` (stamps counted from the first)."""
    t0 = 1_717_243_200 * 10**9
    stamps = [t0 + i * 5_000_000 for i in range(2000)]
    for k in range(100, 1999, 100):
        stamps[k], stamps[k + 1] = stamps[k + 1], stamps[k]
    write_bag(tmp_path / "b", stamps)
    rec = load_recording(tmp_path / "b")
    assert len(rec) == 2000 and rec.lost_samples == 0 and rec.damage is None
    assert rec.rate_hz == pytest.approx(200.0)
    gx = rec.channel("gx")  # value i belongs to stamp i: in stamp order after the sort
    assert np.degrees(0.01 * 101) == pytest.approx(gx[100])
    assert rec.t_s[0] == pytest.approx(1_717_243_200.0)


def test_bag_with_several_frames_or_no_gyro_estimate(tmp_path: Path) -> None:
    """Two IMUs on one topic told apart by frame_id were merged (ADEV 28.5 dps against
    0.057); a gyro covariance[0] of -1 (no estimate, sensor_msgs/Imu) was read as zeros."""
    stamps = [1_717_243_200 * 10**9 + i * 5_000_000 for i in range(400)]
    write_bag(tmp_path / "two", stamps, frames=["imu_a", "imu_b"] * 200)
    with pytest.raises(RecordingError, match=r"2 frame ids .*several IMUs on one topic"):
        load_recording(tmp_path / "two")
    write_bag(tmp_path / "acc", stamps, gyro_cov0=-1.0)
    rec = load_recording(tmp_path / "acc")
    assert rec.channels == ["ax", "ay", "az"]
    assert np.isnan(rec.channel("gx")).all()


def test_bag_stamped_once_per_burst_reads_in_order_at_the_given_rate(tmp_path: Path) -> None:
    """A driver that stamps each FIFO burst of 4 once: 1500 of 2000 messages were lost;
    with --rate and --columns t=- every message is read, in order."""
    stamps = [1_717_243_200 * 10**9 + (i // 4) * 10_000_000 for i in range(2000)]
    write_bag(tmp_path / "b", stamps)
    with pytest.raises(RecordingError, match="--columns t=-"):
        load_recording(tmp_path / "b")
    rec = load_recording(tmp_path / "b", InputOptions(rate_hz=400.0, columns={"t": "-"}))
    assert len(rec) == 2000 and rec.rate_hz == 400.0 and rec.lost_samples == 0


def _stamped(path: Path, rate_line: str, stamp_hz: float, n: int = 8000,
             index: bool = False) -> Path:
    rng = np.random.default_rng(4)
    t = np.arange(n) / stamp_hz
    y = rng.normal(0.0, 0.5, n)
    head = "index,t,gx" if index else "t,gx"
    rows = [f"{k},{t[k]:.6f},{y[k]:.6f}" if index else f"{t[k]:.6f},{y[k]:.6f}"
            for k in range(n)]
    path.write_text(f"{rate_line}\n{head}\n" + "\n".join(rows) + "\n")
    return path


def test_a_stated_rate_is_checked_against_the_time_stamps(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """``# odr_hz: 104`` over stamps 3.75 % slower (no index column) was read on the
    104 Hz grid: rows slipped off their samples as fake holes (311 in 8000 at 100.1 Hz,
    every ADEV from 1 s NaN) or as "damaged" lines. Within 10 % the stamps' rate is read,
    with a warning; beyond, the file is refused (which of the two is right cannot be
    told), with an index column too."""
    with caplog.at_level("WARNING"):
        rec = load_recording(_stamped(tmp_path / "a.csv", "# odr_hz: 104", 100.1))
    assert len(rec) == 8000 and rec.lost_samples == 0 and rec.damage is None
    assert rec.rate_hz == pytest.approx(100.1, rel=1e-6)
    assert "states 104 Hz (# odr_hz) but its time stamps give 100.1 Hz" in caplog.text
    with pytest.raises(RecordingError, match=r"states 200 Hz .* stamps give 100 Hz"):
        load_recording(_stamped(tmp_path / "b.csv", "# sample_rate: 200", 100.0))
    with pytest.raises(RecordingError, match=r"states 200 Hz but the time stamps give 100 Hz"):
        load_recording(_stamped(tmp_path / "c.csv", "# odr_hz: 200", 100.0, index=True))
    # a file under 10 s is judged too (it was read at twice its stamps' rate)
    with pytest.raises(RecordingError, match=r"states 200 Hz but the time stamps give 100 Hz"):
        load_recording(_stamped(tmp_path / "s.csv", "# odr_hz: 200", 100.0, n=900,
                                index=True))
    # stamps on the stated rate: read as before, no warning about them
    caplog.clear()
    rec = load_recording(_stamped(tmp_path / "d.csv", "# odr_hz: 100", 100.0))
    assert rec.rate_hz == 100.0 and len(rec) == 8000 and "stamps give" not in caplog.text


def test_a_chip_clock_30_percent_slow_is_measured_in_a_native_file(tmp_path: Path) -> None:
    """imubench's own files are stamped from the chip's counter: a part 30 % slow (the
    driver measures up to 50 %) was read at its nominal ODR, every tau 30 % long."""
    n = 3000
    idx = np.arange(n, dtype=np.int64)
    raw = np.zeros((n, 6), np.int16)
    b = Batch(idx, idx / 72.8, raw * 1.0, np.full(n, 25.0), raw)
    path = tmp_path / "slow.imbr"
    with open_writer(path, {"chip": "lsm6dsl", "odr_hz": 104.0, "storage": "raw_int16",
                            "gyro_sensitivity_dps": 8.75e-3,
                            "accel_sensitivity_g": 0.061e-3}) as w:
        w.write(b)
    assert load_recording(path).rate_hz == pytest.approx(72.8, rel=1e-6)


@pytest.mark.parametrize("line", [
    "# Fs=100", "# fs = 100", "# odr_hz=100", "# sample rate = 100 Hz", "# rate 100",
    "% Fs = 100;", "# fs: 100 # Hz", "# rate: 100 S/s", "# rate: 100 samples/s",
    "# rate_hz 100", "% fs: 100", "# Sample Rate (Hz): 100", "# tau: 0.01",
    "# period: 0.01", "# interval: 10 ms", "# rate: 100000 mHz", "# rate: 0.0001 MHz"])
def test_rate_lines_in_other_forms_are_read(tmp_path: Path, line: str) -> None:
    """A rate or period line not in the ``# key: value`` form (or in ``%`` MATLAB
    comments, or with the unit in brackets) was ignored and the series read at 1 Hz
    without a word; ``mHz`` was read as MHz (rate 5e8 Hz for ``500 mHz``)."""
    path = tmp_path / "s.txt"
    y = np.random.default_rng(1).normal(size=300)
    path.write_text(line + "\n" + "\n".join(f"{v:.6f}" for v in y) + "\n")
    rec = load_recording(path, InputOptions(default_rate_hz=1.0))
    assert rec.rate_hz == pytest.approx(100.0)


def test_an_unread_comment_is_named_when_the_rate_is_assumed(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    path = tmp_path / "s.txt"
    path.write_text("# frequency: 100 Hz\n" + "\n".join(str(k % 7) for k in range(50)))
    with caplog.at_level("WARNING"):
        assert load_recording(path, InputOptions(default_rate_hz=1.0)).rate_hz == 1.0
    assert "no rate in its comment lines ('# frequency: 100 Hz'" in caplog.text
    path.write_text("# rate: 100 mhz\n1\n2\n3\n")
    with pytest.raises(RecordingError, match=r"write mHz .* or MHz"):
        load_recording(path, InputOptions(default_rate_hz=1.0))


@pytest.mark.parametrize(("header", "level", "match"), [
    ("t,ax,az", 9.80665, r"ax and az read 9\.81 g at rest, which is m/s2 read as g"),
    ("t,az", 9.80665, r"az read 9\.81 g at rest, which is m/s2 read as g"),
    ("t,ax,ay,az", 16384.0, r"reads 1\.638e\+04 g at rest in g, beyond any "
                            r"accelerometer's range \(raw counts\?\)"),
    ("t,ax,ay,az", 0.001, r"reads 0\.001 g at rest in g, not 1 g")])
def test_an_accelerometer_level_no_unit_explains_is_refused(
        tmp_path: Path, header: str, level: float, match: str) -> None:
    """The gravity check needed all three axes (``t,ax,az`` in m/s^2 read as 9.8 g), and
    raw counts (16384 per g under ``ax,ay,az``) or a level 1000x off under names whose
    unit nothing states were read without a word. (A stated unit may hold gravity-free
    linear acceleration: test below.)"""
    n = header.count(",")
    rng = np.random.default_rng(0)
    rows = [header] + [f"{k / 100:.2f}," + ",".join(
        f"{(level if j == n - 1 else 0.0) + rng.normal(0, level * 1e-3):.6f}"
        for j in range(n)) for k in range(500)]
    path = tmp_path / "acc.csv"
    path.write_text("\n".join(rows) + "\n")
    with pytest.raises(RecordingError, match=match):
        load_recording(path)


def test_a_decimated_sample_counter_is_read_at_the_logged_rate(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """A log of every 10th value of a sample counter (t at 100 Hz) was read at 1000 Hz
    with 90 % of the samples lost and every Allan deviation NaN; a hole stays a hole."""
    rng = np.random.default_rng(0)
    keep = [k for k in range(3000) if not 1000 <= k < 1010]
    rows = ["sample,t,gx [dps]"] + [f"{10 * k},{k / 100:.2f},{rng.normal(0, 0.5):.5f}"
                                    for k in keep]
    path = tmp_path / "dec.csv"
    path.write_text("\n".join(rows) + "\n")
    with caplog.at_level("WARNING"):
        rec = load_recording(path)
    assert rec.rate_hz == pytest.approx(100.0) and len(rec) == 2990
    assert rec.lost_samples == 10 and "steps by multiples of 10" in caplog.text


def test_a_units_row_under_the_header_is_read(tmp_path: Path) -> None:
    """``t,gx`` then ``s,rad/s``: the units row was skipped as a damaged line and rad/s
    read as dps (57x low). A row of words that are no units is still damage."""
    rng = np.random.default_rng(2)
    y = rng.normal(0.0, 0.01, 2000)  # rad/s
    body = "\n".join(f"{k / 100:.2f},{v:.8f}" for k, v in enumerate(y))
    path = tmp_path / "u.csv"
    path.write_text("t,gx\ns,rad/s\n" + body + "\n")
    rec = load_recording(path)
    assert len(rec) == 2000 and rec.damage is None
    np.testing.assert_allclose(rec.channel("gx"), np.degrees(np.round(y, 8)), rtol=1e-9)
    path.write_text("t,gx\nfoo,bar\n" + body + "\n")
    rec = load_recording(path)
    assert rec.damage is not None and rec.metadata["units_assumed"] == ["gx"]


@pytest.mark.parametrize("header", ["T,gyro_x [dps],ms", "T [°C],gyro_x [dps],time",
                                    "time,T,gyro_x [dps]"])
def test_a_capital_t_beside_a_time_column_is_the_temperature(tmp_path: Path,
                                                              header: str) -> None:
    """``T`` (a temperature in many loggers) was taken for the time: 3902 of 4000 lines
    "damaged" and the ADEV printed from 98 samples, or the file refused because the time
    column was in degC. Beside a time column (``ms`` alone is one), or with a temperature
    unit, it is the temperature."""
    rng = np.random.default_rng(5)
    names = [h.strip() for h in header.split(",")]
    rows = []
    for k in range(2000):
        cell = {"T": f"{25 + rng.normal(0, 0.01):.4f}",
                "gyro_x [dps]": f"{rng.normal(0, 0.5):.6f}"}
        t = {"ms": f"{10.0 * k:.1f}", "time": f"{k / 100:.2f}"}
        rows.append(",".join(cell.get(n.split(" [")[0], t.get(n, "")) if n.startswith("T")
                             else cell.get(n, t.get(n, "")) for n in names))
    path = tmp_path / "T.csv"
    path.write_text(header + "\n" + "\n".join(rows) + "\n")
    rec = load_recording(path)
    assert len(rec) == 2000 and rec.damage is None and rec.rate_hz == pytest.approx(100.0)
    assert abs(float(np.nanmean(rec.channel("temp"))) - 25.0) < 0.01


@pytest.mark.parametrize("zone", ["+02:00", "+0200", "-05:30", "Z", ""])
def test_iso_times_with_a_utc_offset_are_read(tmp_path: Path, zone: str) -> None:
    """pandas writes a time-zone-aware index as ``2024-05-01 00:00:00.010000+00:00``:
    such files were refused ("no readable data lines"). The offset is applied: the start
    is the same instant in UTC whatever the zone it was written in."""
    local = {"+02:00": 14, "+0200": 14, "-05:30": 6, "Z": 12, "": 12}[zone]
    minute = 30 if zone == "-05:30" else 0
    rows = [f"2024-05-01T{local:02d}:{minute:02d}:00.{k * 10000:06d}{zone},{k % 5}"
            for k in range(100)]
    path = tmp_path / "iso.csv"
    path.write_text("time,gyro_x [dps]\n" + "\n".join(rows) + "\n")
    rec = load_recording(path)
    assert len(rec) == 100 and rec.rate_hz == pytest.approx(100.0)
    assert rec.t_s[0] == pytest.approx(1714564800.0)  # 2024-05-01T12:00:00Z


def test_dotted_day_first_dates_are_read_as_utc_seconds(tmp_path: Path) -> None:
    """``01.05.2024 23:59:59.990`` (DIN 5008, European loggers' and Excel's exports) was
    refused as "no number"; dotted dates are day first wherever they are written. Across
    midnight the day changes and the stamps run on (a month-first misreading would jump a
    month there)."""
    import datetime

    t0 = datetime.datetime(2024, 5, 1, 23, 59, 59)
    rows = [(t0 + datetime.timedelta(seconds=k / 100)).strftime("%d.%m.%Y %H:%M:%S.%f")[:-3]
            + f",{k % 5}" for k in range(300)]
    path = tmp_path / "dotted.csv"
    path.write_text("Zeit,gyro_x [dps]\n" + "\n".join(rows) + "\n")
    rec = load_recording(path)
    assert len(rec) == 300 and rec.damage is None and rec.rate_hz == pytest.approx(100.0)
    assert rec.t_s[0] == pytest.approx(1714607999.0)  # 2024-05-01T23:59:59Z


def test_slashed_dates_and_matlab_date_numbers_are_refused_with_the_fix(tmp_path: Path
                                                                      ) -> None:
    """A slashed date is month first in the US and day first elsewhere: refused, with the
    value and the forms imubench reads. A MATLAB date number (days) has no unit that
    gives an IMU's rate: the refusal says what it looks like and how to write seconds."""
    def refusal(name: str, times: list[str]) -> str:
        path = tmp_path / name
        path.write_text("time,gyro_x [dps]\n"
                        + "\n".join(f"{t},{k % 5}" for k, t in enumerate(times)) + "\n")
        with pytest.raises(RecordingError) as e:
            load_recording(path)
        return str(e.value)

    msg = refusal("slashed.csv", [f"05/01/2024 12:00:{k // 100:02d}.{k % 100:02d}0"
                                  for k in range(300)])
    assert "slashed.csv:2:" in msg and "'05/01/2024 12:00:00.000'" in msg
    assert "ISO 8601" in msg and "01.05.2024" in msg and "--columns t=-" in msg
    # a ';' export's decimal comma is quoted as written, in both places the value is named
    path = tmp_path / "slashed_semicolon.csv"
    path.write_text("time;gyro_x [dps]\n" + "\n".join(
        f"05/01/2024 12:00:{k // 100:02d},{k % 100:02d}0;{k % 5},5" for k in range(300)) + "\n")
    with pytest.raises(RecordingError) as e:
        load_recording(path)
    assert str(e.value).count("'05/01/2024 12:00:00,000'") == 2, str(e.value)
    msg = refusal("datenum.csv", [f"{739008.5 + k / 100 / 86400:.15g}" for k in range(300)])
    assert "MATLAB date numbers" in msg and "719529" in msg
    # 15 significant digits stamp to 86 us: the median step reads 99.8 Hz
    assert 99.0 < float(msg.split("(days; ")[1].split(" Hz")[0]) < 101.0


@pytest.mark.parametrize("style", ["semicolon", "quoted"])
def test_thousands_separators_are_read(tmp_path: Path, style: str) -> None:
    """``-1.234,567`` in a ``;`` export and ``"-1,234.567"`` in a comma-separated one:
    every value of 1000 and over was dropped as a damaged line (the deviation 11 % low)."""
    rng = np.random.default_rng(6)
    y = rng.normal(0.0, 800.0, 3000)  # mdps, a third of them beyond 1000

    def cell(v: float) -> str:
        text = f"{v:,.3f}"
        return text.replace(",", "_").replace(".", ",").replace("_", ".") \
            if style == "semicolon" else f'"{text}"'

    sep = ";" if style == "semicolon" else ","
    t = (lambda k: f"{k / 100:.2f}".replace(".", ",")) if style == "semicolon" else \
        (lambda k: f"{k / 100:.2f}")
    path = tmp_path / "th.csv"
    path.write_text(f"time{sep}gyro_x [mdps]\n"
                    + "\n".join(f"{t(k)}{sep}{cell(v)}" for k, v in enumerate(y)) + "\n")
    rec = load_recording(path)
    assert len(rec) == 3000 and rec.damage is None
    np.testing.assert_allclose(rec.channel("gx"), np.round(y, 3) * 1e-3, atol=1e-9)


def test_quoted_decimal_commas_in_a_comma_file_are_read_or_refused(tmp_path: Path) -> None:
    """A spreadsheet with a German locale told to separate by commas writes
    ``"0,010","1,480","-0,032"``: read as thousands commas every value was 1000x too large
    with nothing said (an outside reviewer: white 3.98 for 0.004 dps/sqrt(Hz), a bias of
    1500 for 1.5). A comma no thousands grouping writes (``0,010``, ``-0,032``) settles
    the file; where every number reads either way, or both ways occur, it is refused."""
    rng = np.random.default_rng(8)
    y = 1.5 + rng.normal(0.0, 0.04, 3000)  # dps
    path = tmp_path / "de.csv"

    def write(values: np.ndarray, fmt: str = "{:.3f}") -> None:
        path.write_text("time [s],gx [dps]\n" + "\n".join(
            '"' + f"{k / 100:.3f}".replace(".", ",") + '","'
            + fmt.format(v).replace(".", ",") + '"' for k, v in enumerate(values)) + "\n")

    write(y)
    rec = load_recording(path)
    assert len(rec) == 3000 and rec.damage is None and rec.rate_hz == pytest.approx(100.0)
    np.testing.assert_allclose(rec.channel("gx"), np.round(y, 3), atol=1e-9)
    write(y + 10.0)  # 11,480: only the time column's 0,010 settles it
    np.testing.assert_allclose(load_recording(path).channel("gx"), np.round(y + 10.0, 3),
                               atol=1e-9)
    path.write_text("t_ms,gx [dps]\n" + "\n".join(
        f'{10 * k},"1,{480 + k % 100:03d}"' for k in range(3000)) + "\n")
    with pytest.raises(RecordingError, match=r"de.csv: .*three digits after it "
                       r"\(line 2: '1,480'\).*1\.480.*1480"):
        load_recording(path)
    path.write_text("t,gx [mdps]\n" + "\n".join(
        f'{k / 100:.2f},"{"1,480.5" if k % 2 else "0,520"}"' for k in range(3000)) + "\n")
    with pytest.raises(RecordingError, match=r"use both ',' \(line 2: '0,520'\) and '\.' "
                       r"\(line 2: '0.00'\) as the decimal mark"):
        load_recording(path)


@pytest.mark.parametrize("style", ["de_comma", "de_semicolon", "us_comma", "de_exponent"])
def test_the_numbers_of_a_file_settle_its_decimal_mark(tmp_path: Path, style: str) -> None:
    """An outside reviewer's exports: a decimal-comma file whose millisecond stamps are
    grouped with points (``"1.010"``) was read at 100 kHz with a white level 32x low, in
    a comma- and in a semicolon-separated file alike; a US file whose only comma numbers
    are grouped integers (``"1,010"`` ms beside ``12.467``) was refused as ambiguous; a
    German exponent (``"7,8841E-03"``) was no number. One mark per file, settled by the
    numbers that read only one way, and the file read again with it."""
    rng = np.random.default_rng(9)
    y = 12.5 + rng.normal(0.0, 0.04, 3000)
    sep = ";" if style == "de_semicolon" else ","

    def de(text: str) -> str:  # German: ',' decimal, '.' thousands
        return text.replace(",", "_").replace(".", ",").replace("_", ".")

    rows, want = [], []
    for k, v in enumerate(y):
        ms, temp = f"{10 * k:,d}", f"{30 + 0.01 * (k % 50):.2f}"  # the temperature settles it
        if style == "us_comma":
            rows.append(f'"{ms}",{v:.3f},{temp}')
            want.append(round(v, 3))
        elif style == "de_exponent":
            cell = f"{v / 1000:.4e}".upper()
            rows.append(f'"{de(ms)}","{de(cell)}","{de(temp)}"')
            want.append(float(cell))
        else:
            cells = (de(ms), de(f"{v:.3f}"), de(temp))
            rows.append(sep.join(f'"{c}"' if sep == "," else c for c in cells))
            want.append(round(v, 3))
    path = tmp_path / "marks.csv"
    path.write_text(f"time_ms{sep}gyro_x [dps]{sep}temp\n" + "\n".join(rows) + "\n")
    rec = load_recording(path)
    assert len(rec) == 3000 and rec.damage is None
    assert rec.rate_hz == pytest.approx(100.0)
    np.testing.assert_allclose(rec.channel("gx"), want, rtol=1e-12)
    assert rec.temp_c is not None and rec.temp_c.max() == pytest.approx(30.49)


def test_decimal_commas_without_a_header_or_with_spaces_and_ambiguous_exports(
        tmp_path: Path) -> None:
    """A third reviewer's files: a headerless ``0,00;0,45;30,13`` table was split at its
    commas and refused; a one-column ``gx`` of ``0,0114`` was no number; a US semicolon
    export with ``1,010`` ms beside ``473.928`` dps (nothing deciding) was read as 1.01
    ms and 473928 dps. The first two are read, the last refused."""
    rng = np.random.default_rng(4)
    y = 0.5 + rng.normal(0.0, 0.04, 1000)
    path = tmp_path / "n.csv"
    path.write_text("\n".join(f"{k / 100:.2f};{v:.5f};30,13".replace(".", ",")
                              for k, v in enumerate(y)) + "\n")
    rec = load_recording(path, InputOptions(columns={"t": "1", "gx": "2", "temp": "3"}))
    np.testing.assert_allclose(rec.channel("gx"), np.round(y, 5), atol=1e-12)
    path.write_text("gx\n" + "\n".join(f"{v:.4f}".replace(".", ",") for v in y) + "\n")
    rec = load_recording(path, InputOptions(rate_hz=100.0))
    np.testing.assert_allclose(rec.channel("gx"), np.round(y, 4), atol=1e-12)
    path.write_text("t_ms;gyro_x [dps]\n" + "\n".join(
        f"{10 * k:,d};{1000 * v:.3f}" for k, v in enumerate(y)) + "\n")
    with pytest.raises(RecordingError,
                       match=r"three digits after it \(line 102: '1,000' and '\d+\.\d{3}'"):
        load_recording(path)


@pytest.mark.parametrize(("name", "value"), [("temp_K", 303.15), ("Temperatur [°C]", 30.0),
                                           ("board_temp_F", 86.0)])
def test_a_temperature_named_with_its_unit_or_in_german_is_read(tmp_path: Path, name: str,
                                                                value: float) -> None:
    """``temp_K`` and ``Temperatur [°C]`` were left out unread (an outside reviewer)."""
    path = tmp_path / "temp.csv"
    path.write_text(f"t_s,gx_dps,{name}\n" + "\n".join(f"{k / 100:.2f},0.5,{value}"
                                                        for k in range(500)) + "\n")
    rec = load_recording(path)
    assert rec.temp_c is not None
    np.testing.assert_allclose(rec.temp_c, 30.0, atol=1e-9)


def test_a_units_row_of_raw_counts_is_refused_not_read_as_dps(tmp_path: Path) -> None:
    """``t,gx`` then ``s,LSB``: skipped as a damaged line, the counts were read as dps
    (114x, an outside reviewer); now the row is read as units and refused as a header
    ``gx [LSB]`` is."""
    path = tmp_path / "lsb.csv"
    path.write_text("t,gx\ns,LSB\n" + "\n".join(f"{k / 100:.2f},{57 + k % 7}"
                                                for k in range(2000)) + "\n")
    with pytest.raises(RecordingError, match=r"column 'gx \[LSB\]' is in 'LSB', not a gyro"):
        load_recording(path)


def test_an_assumed_unit_of_a_plain_series_is_said(tmp_path: Path,
                                                   caplog: pytest.LogCaptureFixture) -> None:
    """One column with a rate line (rad/s, no unit): read as dps, a white level 57x low,
    ARW and all, with the note only at -v; an assumed unit is now a warning."""
    path = tmp_path / "one.txt"
    path.write_text("# rate_hz: 100\n" + "\n".join(f"{v:.8f}" for v in
                                                   np.random.default_rng(3).normal(0, 1e-3, 2000))
                    + "\n")
    with caplog.at_level("WARNING", logger="imubench.recording"):
        rec = load_recording(path)
    assert rec.metadata["units_assumed"] == ["gx"]
    assert "assumed for gx: nothing in the file states them" in caplog.text
    from imubench import cli

    out = tmp_path / "fit.json"
    assert cli.main(["fit", str(path), "-o", str(tmp_path / "m.toml"), "--json", str(out)]) == 0
    assert json.loads(out.read_text())["units_assumed"] == ["gx"]


def test_a_file_of_unreadable_lines_names_the_first_and_why(tmp_path: Path) -> None:
    """"30000 of 30000 data lines cannot be read" named no line, column or reason."""
    path = tmp_path / "cells.csv"
    path.write_text("t,gx\n" + "\n".join(f"{k / 100:.2f} s,{0.5:.2f} dps"
                                          for k in range(300)) + "\n")
    with pytest.raises(RecordingError, match=r"cannot be read \(first: line 2, 't' holds "
                       r"'0.00 s', not a number\)"):
        load_recording(path)
    path.write_text("t,gx\n" + "\n".join(f"{k / 100:.2f},1,{k % 1000:03d}.5"
                                          for k in range(300)) + "\n")
    with pytest.raises(RecordingError, match=r"\(first: line 2, 3 fields where the header "
                       r"has 2\)"):
        load_recording(path)


@pytest.mark.parametrize(("header", "channel", "factor"), [
    ("t,ax_g", "ax", 1.0), ("t,acc_x_mps2", "ax", 1 / 9.80665),
    ("t,gx_rads", "gx", 180 / np.pi), ("t,gyro_x_dps", "gx", 1.0),
    ("t,gyro_x_radps", "gx", 180 / np.pi), ("t_sec,gx [deg/sec]", "gx", 1.0),
    ("t,gx [rad/sec]", "gx", 180 / np.pi), ("t,gx [º/s]", "gx", 1.0),
    ("t,gx [mrad/s]", "gx", 0.18 / np.pi), ("t,az [ms^-2]", "az", 1 / 9.80665),
    ("t,az [cm/s^2]", "az", 0.01 / 9.80665), ("t,gx [°/sec]", "gx", 1.0),
    ("t,gx [rpm]", "gx", 6.0), ("t,az [mm/s^2]", "az", 0.001 / 9.80665),
    # an outside reviewer's: not read ("no channel of that name") though mrad/s is a unit
    ("t,gx_mrad_s", "gx", 0.18 / np.pi), ("t,gyro_x_mradps", "gx", 0.18 / np.pi),
    ("t,gx_degps", "gx", 1.0)])
def test_unit_suffixes_and_spellings_are_read(tmp_path: Path, header: str, channel: str,
                                              factor: float) -> None:
    """Units in a name's suffix (``ax_g``, ``gyro_x_radps``, ``t_sec``) and spellings
    such as ``deg/sec``, ``º/s``, ``mrad/s``, ``ms^-2``, ``cm/s^2`` were refused."""
    v = np.array([0.3, 0.1, 0.2, 0.4] * 50)
    path = tmp_path / "u.csv"
    path.write_text(header + "\n" + "\n".join(f"{k / 100:.2f},{x}" for k, x in enumerate(v))
                    + "\n")
    rec = load_recording(path)
    np.testing.assert_allclose(rec.channel(channel), v * factor, rtol=1e-12)


def test_unevenly_spaced_stamps_are_refused_and_jitter_is_not(tmp_path: Path) -> None:
    """Intervals that vary at random (a phone's sensor events, 10 +- 2 ms) lie on no
    grid: they were read with 9 % of the rows "damaged" and 5 % holes. Stamps jittered by
    up to 0.4 period around a grid keep every row."""
    rng = np.random.default_rng(8)
    y = rng.normal(0.0, 0.5, 6000)
    path = tmp_path / "irr.csv"
    t = np.cumsum(rng.normal(0.010, 0.002, 6000))
    path.write_text("time,gyro_x [dps]\n" + "\n".join(
        f"{a:.6f},{b:.6f}" for a, b in zip(t, y, strict=True)) + "\n")
    with pytest.raises(RecordingError, match=r"not evenly spaced: \d+ of 6000 rows"):
        load_recording(path)
    t = np.arange(6000) / 100.0 + rng.uniform(-0.004, 0.004, 6000)
    path.write_text("time,gyro_x [dps]\n" + "\n".join(
        f"{a:.6f},{b:.6f}" for a, b in zip(t, y, strict=True)) + "\n")
    rec = load_recording(path)
    assert len(rec) == 6000 and rec.lost_samples == 0 and rec.damage is None


@pytest.mark.parametrize(("data", "hint"), [
    ("time,gyro_x [dps]\n" + "".join(f"0,{k:03d},0,{k % 7}\n" for k in range(50)),
     "decimal commas in a comma-separated file"),
    (("time,gyro_x [dps]\n" + "".join(f"{k / 100:.2f},{k % 7}\n" for k in range(50)))
     .encode("utf-16-le"), "UTF-16 text without a byte-order mark")])
def test_an_unreadable_file_says_what_it_probably_is(tmp_path: Path, data: str | bytes,
                                                     hint: str) -> None:
    """Decimal commas in a comma-separated file and UTF-16 without a byte-order mark read
    as "no readable data lines" or "not a recording", with no hint."""
    path = tmp_path / "x.csv"
    if isinstance(data, bytes):
        path.write_bytes(data)
    else:
        path.write_text(data)
    with pytest.raises(RecordingError, match=hint):
        load_recording(path)


def _times_csv(path: Path, t: np.ndarray) -> Path:
    path.write_text("t,gx\n" + "\n".join(f"{a:.6f},0.001" for a in t) + "\n")
    return path


@pytest.mark.parametrize(("after_hz", "change_row"), [
    (102.0, 30_000), (106.0, 33_017), (104.2, 30_000), (52.0, 31_234)])
def test_a_rate_change_within_the_file_is_named_where_it_happens(
        tmp_path: Path, after_hz: float, change_row: int) -> None:
    """Stamps at 104 Hz and then at another rate (a logger whose clock changed, two
    sessions written as one file): read at one rate, 102 Hz after gave 588 one-sample
    holes that are no lost samples, 106 Hz 566 good rows skipped as "damaged", 52 Hz a
    hole at every other sample. The file is refused naming the line the new rate starts
    at and both rates, with stamps jittered by 0.2 period too; split there, each part
    reads whole; read in order with --rate and no time column it is whole."""
    rng = np.random.default_rng(5)
    n = 60_000
    t = np.concatenate([np.arange(change_row) / 104.0,
                        (change_row - 1) / 104.0
                        + np.arange(1, n - change_row + 1) / after_hz])
    path = tmp_path / "two_rates.csv"
    for jitter in (0.0, 0.2):
        _times_csv(path, t + rng.uniform(-jitter, jitter, n) / 104.0)
        with pytest.raises(RecordingError, match=(
                r"two_rates\.csv:(\d+): the sample rate changes here: the time stamps give "
                rf"104 Hz before and {after_hz:g} Hz from here")) as err:
            load_recording(path)
        line = int(str(err.value).split(".csv:")[1].split(":")[0])
        # to the line without jitter; with it, within the rows over which the change
        # moves a stamp by the jitter
        spread = 0 if jitter == 0 else 2 + int(jitter / abs(104.0 / after_hz - 1.0))
        assert abs(line - (change_row + 2)) <= spread, (line, spread)
    for part, rate in ((t[:change_row], 104.0), (t[change_row:], after_hz)):
        rec = load_recording(_times_csv(tmp_path / "part.csv", part))
        assert len(rec) == part.size and rec.lost_samples == 0
        assert rec.rate_hz == pytest.approx(rate, rel=1e-6)
    rec = load_recording(_times_csv(path, t), InputOptions(rate_hz=104.0,
                                                         columns={"t": "-", "gx": "gx"}))
    assert len(rec) == n and rec.lost_samples == 0


def test_a_rate_change_in_a_ros_bag_names_the_message(tmp_path: Path) -> None:
    """The MCAP / ROS 2 reader indexes header stamps the same way: 4000 messages at 104 Hz
    and 4000 at 102 Hz are refused naming the first message at the new rate."""
    t = np.concatenate([np.arange(4000) / 104.0, 3999 / 104.0 + np.arange(1, 4001) / 102.0])
    write_mcap(tmp_path / "two.mcap", t, np.zeros((t.size, 6)))
    with pytest.raises(RecordingError, match=r"two\.mcap: message 4001 of topic /imu: the "
                                             r"sample rate changes here: the time stamps "
                                             r"give 104 Hz before and 102 Hz from here"):
        load_recording(tmp_path / "two.mcap")


def test_a_rate_change_is_seen_through_lost_samples_and_a_steady_clock_is_not_called_one(
        tmp_path: Path) -> None:
    """A lossy link (1 % of the samples missing at random) does not hide a change from 104
    to 102 Hz; a steady clock with such holes and 0.3 period of jitter, or stamps printed
    to the millisecond, is read as one rate with its holes counted. A clock that drifts
    (30 ppm over 10 min at 1 kHz) is named a drift, not a place to split."""
    rng = np.random.default_rng(6)
    t = np.concatenate([np.arange(30_000) / 104.0, 29_999 / 104.0
                        + np.arange(1, 30_001) / 102.0])
    lossy = np.delete(t, rng.choice(t.size, 600, replace=False))
    with pytest.raises(RecordingError, match="104 Hz before and 102 Hz from here"):
        load_recording(_times_csv(tmp_path / "lossy.csv", lossy))
    steady = np.delete(np.arange(60_000) / 104.0, rng.choice(60_000, 600, replace=False))
    rec = load_recording(_times_csv(tmp_path / "steady.csv",
                                  steady + rng.uniform(-0.3, 0.3, steady.size) / 104.0))
    assert len(rec) == steady.size and rec.lost_samples == 600
    (tmp_path / "ms.csv").write_text("t,gx\n" + "\n".join(
        f"{a:.3f},0.001" for a in np.arange(60_000) / 104.0) + "\n")
    rec = load_recording(tmp_path / "ms.csv")
    assert len(rec) == 60_000 and rec.lost_samples == 0
    drift = np.arange(600_000) / 1000.0
    drift *= 1.0 + 30e-6 * drift / 600.0
    with pytest.raises(RecordingError, match=r"the sample rate drifts within the file: the "
                                             r"time stamps give 1000 Hz at its start and "
                                             r"999\.9\d* Hz at its end.*--columns t=-"):
        load_recording(_times_csv(tmp_path / "drift.csv", drift))


def test_a_logger_restart_is_named_where_it_happens(tmp_path: Path) -> None:
    """A log whose time restarts at 0 halfway had its first half dropped as "damaged"."""
    rows = [f"{(k % 5000) / 100:.2f},{k % 7}" for k in range(10000)]
    path = tmp_path / "r.csv"
    path.write_text("t,gyro_x [dps]\n" + "\n".join(rows) + "\n")
    with pytest.raises(RecordingError, match=r"r\.csv:5002: the time column goes back "
                                             r"\(49\.99 -> 0 s\)"):
        load_recording(path)


def test_empty_cells_are_lost_samples_of_their_channel_and_said(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    rows = [f"{k / 100:.2f},{'' if k == 7 else k % 5},{k % 3}" for k in range(300)]
    path = tmp_path / "e.csv"
    path.write_text("t,gyro_x [dps],gyro_y [dps]\n" + "\n".join(rows) + "\n")
    with caplog.at_level("WARNING"):
        rec = load_recording(path)
    assert np.isnan(rec.channel("gx")[7]) and rec.channel("gy")[7] == 7 % 3
    assert "empty cells (gx 1 on line 9)" in caplog.text
    assert rec.channel_lost("gx") == (1, 1) and rec.channel_lost("gy") == (0, 0)


def test_where_empty_cells_and_holes_lie_is_said_by_line(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """An outside reviewer's 1000 empty cells were warned of with no line, and a 100 s
    jump in the time column was reported only as a hole count."""
    from imubench.recording import empty_cells_text

    t = np.arange(3000) / 100.0
    t[2000:] += 100.0  # 10 000 samples missing before the 2001st data row (line 2002)
    rows = [f"{v:.2f},{'' if 500 <= k < 600 or k == 900 else k % 5}" for k, v in enumerate(t)]
    path = tmp_path / "h.csv"
    path.write_text("t,gyro_x [dps]\n" + "\n".join(rows) + "\n")
    with caplog.at_level("WARNING"):
        rec = load_recording(path)
    assert "empty cells (gx 101 on lines 502-601, 902)" in caplog.text
    assert ("1 hole(s) in the time stamps, 10000 samples missing: before line 2002 (t 120 s, "
            "10000 samples)") in caplog.text
    assert rec.lost_samples == 10000 and rec.channel_lost("gx") == (10101, 3)
    assert empty_cells_text(rec, "gx") == (
        "gx: 10101 samples lost in 3 run(s), 101 of them empty cells beside the recording's "
        "1 hole(s); the curves are computed across them")


def test_a_column_not_read_is_named_with_the_channel_it_may_misspell(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """A header ``t,gx,tmep`` (an outside reviewer's): the temperature went unread and
    untested, with nothing said."""
    rows = [f"{k / 100:.2f},{k % 5},{25 + k % 3},1013" for k in range(300)]
    path = tmp_path / "m.csv"
    path.write_text("t,gx,tmep,pressure\n" + "\n".join(rows) + "\n")
    with caplog.at_level("WARNING"):
        rec = load_recording(path)
    assert "temp" not in rec.channels
    assert ("column(s) not read, no channel of that name: tmep (a misspelt temp? name it "
            "with --columns temp=tmep), pressure") in caplog.text


def test_missing_value_cells_interleaved_sensors_and_unreadable_columns(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """``NaN`` in an accelerometer column on every other line dropped those lines from
    the gyro, read at half its rate; interleaved gyro and accelerometer lines gave every
    deviation NaN with exit status 0; 98 % unreadable cells kept 48 of 3000 lines at
    3.2 Hz; a capital T that does not increase (a temperature) was read as the time."""
    rng = np.random.default_rng(9)
    y = rng.normal(0, 0.5, 3000)
    path = tmp_path / "n.csv"
    path.write_text("time [s],gyro_x [dps],acc_z [g],acc_x [g]\n" + "\n".join(
        f"{k / 100:.2f},{y[k]:.5f},{'NaN' if k % 2 else '1.0'},0.0" for k in range(3000)))
    with caplog.at_level("WARNING"):
        rec = load_recording(path)
    assert rec.rate_hz == pytest.approx(100.0) and len(rec) == 3000
    assert np.isfinite(rec.channel("gx")).all() and "az" not in rec.channels
    assert "az left out: no value on most lines (1500 of 3000)" in caplog.text
    path.write_text("time [s],gyro_x [dps],acc_z [g]\n" + "\n".join(
        f"{k / 200:.3f}," + (f"{y[k // 2]:.5f}," if k % 2 == 0 else ",1.0")
        for k in range(6000)))
    with pytest.raises(RecordingError, match="gyro lines and accelerometer lines interleaved"):
        load_recording(path)
    path.write_text("time [s],gyro_x [dps]\n" + "\n".join(
        f"{k / 100:.2f},{'abc' if k % 50 else y[k]}" for k in range(3000)))
    with pytest.raises(RecordingError, match=r"2940 of 3000 data lines hold a value that is "
                                             r"no number in a column read \(gyro_x \[dps\]; "
                                             r"first 'gyro_x \[dps\]': 'abc'\)"):
        load_recording(path)
    path.write_text("# fs: 100\ngyro_x [dps],T\n" + "\n".join(
        f"{y[k]:.5f},{25 + rng.normal(0, 0.05):.3f}" for k in range(3000)))
    rec = load_recording(path)
    assert len(rec) == 3000 and rec.rate_hz == 100.0
    assert abs(float(np.nanmean(rec.channel("temp"))) - 25.0) < 0.01


def test_a_stream_that_lost_most_samples_is_not_read_at_a_fraction_of_its_rate(
        tmp_path: Path) -> None:
    """60 % of a 100 Hz stream lost at random: the median spacing is two periods, and the
    file was read at 50 Hz with 508 lines "damaged". It is refused, naming the 100 Hz
    grid; with --rate 100 every row is read at its own sample."""
    rng = np.random.default_rng(10)
    kept = np.sort(rng.choice(6000, 2400, replace=False))
    path = tmp_path / "lossy.csv"
    path.write_text("time [s],gyro_x [dps]\n" + "\n".join(
        f"{k / 100:.2f},{rng.normal(0, 0.5):.5f}" for k in kept) + "\n")
    with pytest.raises(RecordingError, match=r"grid of 100 Hz with most samples missing: "
                                             r"give --rate 100"):
        load_recording(path)
    rec = load_recording(path, InputOptions(rate_hz=100.0))
    assert len(rec) == 2400 and rec.lost_samples == int(kept[-1] - kept[0] + 1 - 2400)


def test_linear_acceleration_in_a_stated_unit_is_read(tmp_path: Path) -> None:
    """A phone's gravity-free "linear acceleration" (or a drop test) in m/s^2, the unit in
    the header, reads near 0 g: it was refused as "a unit 1000x off"."""
    rng = np.random.default_rng(11)
    rows = [f"{k / 100:.2f}," + ",".join(f"{rng.normal(0, 0.02):.5f}" for _ in range(3))
            for k in range(500)]
    path = tmp_path / "lin.csv"
    path.write_text("t,ax [m/s^2],ay [m/s^2],az [m/s^2]\n" + "\n".join(rows) + "\n")
    assert len(load_recording(path)) == 500


def test_a_units_row_in_brackets_is_read(tmp_path: Path) -> None:
    """``[s],[rad/s]`` under the header made the names ``Time [[s]]`` (no channel found)."""
    path = tmp_path / "ub.csv"
    path.write_text("Time,GyroX\n[s],[rad/s]\n" + "\n".join(
        f"{k / 100:.2f},{(k % 3) * 0.1:.1f}" for k in range(300)) + "\n")
    rec = load_recording(path)
    assert rec.channel("gx")[1] == pytest.approx(np.degrees(0.1))


def test_columns_names_a_header_column_without_its_unit(tmp_path: Path) -> None:
    """``--columns gx=GyroX`` needed the header's full text ``GyroX [dps]``."""
    path = tmp_path / "c.csv"
    path.write_text("t,GyroX [dps],Other\n" + "\n".join(f"{k / 100:.2f},{k % 5},1"
                                                         for k in range(200)) + "\n")
    rec = load_recording(path, InputOptions(columns={"gx": "GyroX"}))
    assert rec.channel("gx")[3] == 3.0
