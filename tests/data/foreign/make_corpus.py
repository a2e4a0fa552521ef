"""Writes the corpus of recordings "from elsewhere" in this folder (issue 13, acceptance 1).

    python tests/data/foreign/make_corpus.py      # rewrites every file, deterministically

Every file holds the same 2 s of a static IMU at 104 Hz (or its rate), in the layout and
units of the tool it imitates; ``tests/test_foreign_inputs.py`` reads each one back to
the right rate, channels and values (in dps and g), or checks that it is refused with a
one-line error naming the file and the fix, and that this script still writes exactly
the committed bytes (the ``.imbr``'s end record holds its closing time: compared by
content). Where each layout comes from:

- imubench's own CSV (``imubench convert REC.imbr OUT.csv``): ``# key: JSON`` metadata,
  ``t,gx,gy,gz,ax,ay,az,temp,index``; and the same without metadata nor index, ``t``
  printed to 6 decimals, as most loggers write it (the issue's crashing case).
- Generic logger CSVs: ``timestamp,gyro_x,...,accel_x`` headers as written by Arduino /
  STM32 serial loggers, with units in brackets or none at all; a European spreadsheet
  export with ``;`` separators and decimal commas; tab- and space-separated tables.
- ROS 1 ``rostopic echo -p /imu/data > imu.csv`` of ``sensor_msgs/Imu``: header
  ``%time,field.header.seq,field.header.stamp,field.header.frame_id,
  field.orientation.x,...,field.orientation_covariance0..8,field.angular_velocity.x,...,
  field.linear_acceleration.x,...`` (times in ns, rad/s, m/s^2; REP 103 units).
- EuRoC MAV dataset (Burri et al., IJRR 2016) and TUM-VI ``mav0/imu0/data.csv``: header
  ``#timestamp [ns],w_RS_S_x [rad s^-1],...,a_RS_S_x [m s^-2],...``.
- Stable32 / allantools data files: one value per line, or a Modified Julian Date and a
  value per line (Stable32 "Read" of two-column data).
- ROS 2: a bag (``ros2 bag record``'s folder: ``metadata.yaml`` + SQLite ``.db3``) and a
  standalone MCAP file of ``sensor_msgs/msg/Imu`` on ``/imu/data`` (CDR, header.stamp in
  s + ns, REP 103 units), written with ``rosbags`` as ``ros2 bag`` would.
- A gzip-compressed CSV (``.csv.gz``), imubench's native ``.imbr``, and imubench's
  exports of it: HDF5 (``.h5``) and gx as a Stable32 data file (``convert --channel``).
- Files that must be refused: ``t`` in milliseconds under imubench's own header, a
  logger CSV without units, a headerless three-column table, binary junk.
"""

from __future__ import annotations

import contextlib
import gzip
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RATE_HZ = 104.0
N = 208
G_M_S2 = 9.80665
T0_NS = 1_403_636_579_758_555_392  # a EuRoC-like epoch stamp (2014-06-24, ns)


def truth() -> dict[str, np.ndarray]:
    """The static IMU every file holds: gyro bias + small tones (dps), gravity on z (g),
    a slow temperature ramp (degC)."""
    k = np.arange(N)
    return {
        "gx": 0.25 + 0.02 * np.sin(2 * np.pi * k / 26),
        "gy": -0.10 + 0.01 * np.cos(2 * np.pi * k / 13),
        "gz": 0.05 + 0.001 * k / N,
        "ax": 0.01 + 0.002 * np.sin(2 * np.pi * k / 52),
        "ay": -0.02 + 0.001 * np.cos(2 * np.pi * k / 17),
        "az": 0.998 + 0.0005 * np.sin(2 * np.pi * k / 8),
        "temp": 25.0 + 0.01 * k / N,
    }


GYRO = ("gx", "gy", "gz")
ACCEL = ("ax", "ay", "az")


def rows(fmt: str, *cols: np.ndarray) -> str:
    return "".join(",".join(fmt.format(v) for v in r) + "\n" for r in zip(*cols, strict=True))


def write(name: str, text: str) -> None:
    (HERE / name).write_text(text, encoding="utf-8")


def main() -> None:
    tr = truth()
    k = np.arange(N)
    t = k / RATE_HZ
    rad = {c: np.deg2rad(tr[c]) for c in GYRO}
    ms2 = {c: tr[c] * G_M_S2 for c in ACCEL}

    # imubench CSV with metadata and index (what `imubench convert` writes)
    write("imubench_meta.csv",
          '# chip: "lsm6dsl"\n# odr_hz: 104.0\nt,gx,gy,gz,ax,ay,az,temp,index\n'
          + "".join(",".join(f"{v:.9g}" for v in (t[i], *(tr[c][i] for c in (*GYRO, *ACCEL)),
                                                   tr["temp"][i], i)) + "\n"
                    for i in range(N)))
    # the same without metadata nor index, t rounded to 6 decimals
    plain = "t,gx,gy,gz,ax,ay,az\n" + "".join(
        f"{t[i]:.6f}," + ",".join(f"{tr[c][i]:.6f}" for c in (*GYRO, *ACCEL)) + "\n"
        for i in range(N))
    write("imubench_rounded_t.csv", plain)
    with gzip.GzipFile(HERE / "imubench_rounded_t.csv.gz", "wb", mtime=0) as gz:
        gz.write(plain.encode())
    # t in milliseconds under imubench's own header: refused (t is documented in s)
    write("imubench_t_in_ms.csv", "t,gx,gy,gz,ax,ay,az\n" + "".join(
        f"{t[i] * 1e3:.3f}," + ",".join(f"{tr[c][i]:.6f}" for c in (*GYRO, *ACCEL)) + "\n"
        for i in range(N)))
    # logger with units in brackets: seconds, rad/s, m/s^2
    write("logger_units_in_header.csv",
          "time_s,gyro_x [rad/s],gyro_y [rad/s],gyro_z [rad/s],acc_x [m/s^2],acc_y [m/s^2],"
          "acc_z [m/s^2]\n" + rows("{:.9g}", t, *(rad[c] for c in GYRO),
                                   *(ms2[c] for c in ACCEL)))
    # logger with milliseconds in the name and no units for the sensors: refused
    write("logger_no_units.csv", "timestamp,gyro_x,gyro_y,gyro_z,accel_x,accel_y,accel_z\n"
          + rows("{:.9g}", np.round(t * 1e3, 3), *(tr[c] for c in GYRO),
                 *(tr[c] for c in ACCEL)))
    # European spreadsheet export: ';' and decimal commas, dps and g in parentheses, ms
    write("spreadsheet_semicolon.csv",
          "Time (ms);Gyro X (dps);Gyro Y (dps);Gyro Z (dps);Acc X (g);Acc Y (g);Acc Z (g);"
          "Temperature (degC)\n" + "".join(
              ";".join(f"{v:.6f}".replace(".", ",") for v in (
                  t[i] * 1e3, *(tr[c][i] for c in (*GYRO, *ACCEL)), tr["temp"][i])) + "\n"
              for i in range(N)))
    # tab-separated with imubench names and metadata
    write("tab_separated.tsv", "# odr_hz: 104\nt\tgx\tgy\tgz\tax\tay\taz\n" + "".join(
        "\t".join(f"{v:.9g}" for v in (t[i], *(tr[c][i] for c in (*GYRO, *ACCEL)))) + "\n"
        for i in range(N)))
    # whitespace-aligned table, microseconds from an arbitrary origin
    write("whitespace_aligned.dat", "time_us    gx          gy          gz\n" + "".join(
        f"{int(5_000_000 + round(t[i] * 1e6)):<10d} "
        + " ".join(f"{tr[c][i]:<11.6f}" for c in GYRO) + "\n" for i in range(N)))
    # ROS 1 rostopic echo -p of sensor_msgs/Imu
    cov = ",".join(f"field.orientation_covariance{j}" for j in range(9))
    gcov = ",".join(f"field.angular_velocity_covariance{j}" for j in range(9))
    acov = ",".join(f"field.linear_acceleration_covariance{j}" for j in range(9))
    header = ("%time,field.header.seq,field.header.stamp,field.header.frame_id,"
              "field.orientation.x,field.orientation.y,field.orientation.z,"
              f"field.orientation.w,{cov},field.angular_velocity.x,"
              f"field.angular_velocity.y,field.angular_velocity.z,{gcov},"
              "field.linear_acceleration.x,field.linear_acceleration.y,"
              f"field.linear_acceleration.z,{acov}\n")
    zeros9 = ",".join(["0.0"] * 9)
    lines = []
    for i in range(N):
        stamp = T0_NS + round(t[i] * 1e9)
        recv = stamp + 1_500_000 + (i % 7) * 100_000  # received later, with jitter
        lines.append(f"{recv},{i},{stamp},imu_link,0.0,0.0,0.0,1.0,{zeros9},"
                     + ",".join(f"{rad[c][i]:.12g}" for c in GYRO) + f",{zeros9},"
                     + ",".join(f"{ms2[c][i]:.12g}" for c in ACCEL) + f",{zeros9}\n")
    write("ros_imu_echo.csv", header + "".join(lines))
    # EuRoC / TUM-VI imu0/data.csv
    write("euroc_imu0_data.csv",
          "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
          "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\n" + "".join(
              f"{T0_NS + round(t[i] * 1e9)},"
              + ",".join(f"{v:.17g}" for v in (*(rad[c][i] for c in GYRO),
                                               *(ms2[c][i] for c in ACCEL))) + "\n"
              for i in range(N)))
    # Stable32 / allantools: one value per line; MJD + value
    write("stable32_one_column.txt", "# gx, dps, 104 Hz\n" + "".join(
        f"{v:.9g}\n" for v in tr["gx"]))
    mjd0 = 60_000.5
    write("stable32_mjd_value.txt", "".join(
        f"{mjd0 + t[i] / 86_400:.12f} {tr['gx'][i]:.9g}\n" for i in range(N)))
    # refused: a headerless table of three columns, binary junk
    write("headerless_three_columns.txt", rows("{:.6f}", t, tr["gx"], tr["gy"]))
    rng = np.random.default_rng(13)
    (HERE / "binary_junk.csv").write_bytes(rng.integers(0, 256, 3000, dtype=np.uint8)
                                           .tobytes())
    ros2(t, rad, ms2)
    # imubench native
    sys.path.insert(0, str(HERE.parents[2] / "src"))
    from imubench.batch import Batch
    from imubench.recording import NativeWriter

    path = HERE / "imubench_native.imbr"
    path.unlink(missing_ok=True)
    values = np.column_stack([tr[c] for c in (*GYRO, *ACCEL)])
    meta = {"chip": "lsm6dsl", "odr_hz": RATE_HZ, "storage": "float64",
            "channels": list((*GYRO, *ACCEL)), "start_utc": "2026-11-24T00:00:00+00:00"}
    with NativeWriter(path, meta) as w:
        w.write(Batch(k.astype(np.int64), t, values, tr["temp"]))
    # imubench's own exports of it: HDF5, and gx as a Stable32 data file
    from imubench.recording import convert

    with contextlib.chdir(HERE):  # the exports name their source as given: relative
        for name, channel in (("imubench_hdf5.h5", None),
                              ("imubench_stable32_export.dat", "gx")):
            Path(name).unlink(missing_ok=True)
            convert(path.name, name, channel=channel)


def ros2(t: np.ndarray, rad: dict[str, np.ndarray], ms2: dict[str, np.ndarray]) -> None:
    """A ROS 2 bag (SQLite) and a standalone MCAP file of the same Imu messages."""
    import shutil
    import tempfile

    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    imu, header, stamp = (ts.types[n] for n in ("sensor_msgs/msg/Imu", "std_msgs/msg/Header",
                                                  "builtin_interfaces/msg/Time"))
    quat, vec = ts.types["geometry_msgs/msg/Quaternion"], ts.types["geometry_msgs/msg/Vector3"]
    with tempfile.TemporaryDirectory() as tmp:
        for plugin, name in ((StoragePlugin.SQLITE3, "ros2_bag"), (StoragePlugin.MCAP, "m")):
            out = HERE / name if name == "ros2_bag" else Path(tmp) / name
            shutil.rmtree(out, ignore_errors=True)
            with Writer(out, version=8, storage_plugin=plugin) as w:
                conn = w.add_connection("/imu/data", imu.__msgtype__, typestore=ts)
                for i in range(N):
                    ns = T0_NS + round(t[i] * 1e9)
                    msg = imu(header=header(stamp=stamp(sec=ns // 10**9, nanosec=ns % 10**9),
                                            frame_id="imu_link"),
                              orientation=quat(x=0.0, y=0.0, z=0.0, w=1.0),
                              orientation_covariance=np.zeros(9),
                              angular_velocity=vec(**{a: float(rad["g" + a][i])
                                                      for a in "xyz"}),
                              angular_velocity_covariance=np.zeros(9),
                              linear_acceleration=vec(**{a: float(ms2["a" + a][i])
                                                         for a in "xyz"}),
                              linear_acceleration_covariance=np.zeros(9))
                    w.write(conn, ns + 1_500_000, ts.serialize_cdr(msg, imu.__msgtype__))
            if name == "m":
                shutil.copyfile(next(out.glob("*.mcap")), HERE / "ros2_imu.mcap")


if __name__ == "__main__":
    main()
