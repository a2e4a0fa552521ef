"""Reading ``sensor_msgs/msg/Imu`` from ROS 2 bags and MCAP files.

* A ROS 2 bag (a folder with ``metadata.yaml`` and its ``.db3`` or ``.mcap`` storage, or
  the ``.db3`` file itself): the maintained ``rosbags`` package (no ROS installation).
* A standalone ``.mcap`` file: the ``mcap`` reader with ``mcap-ros2-support``'s decoder.

The times are the messages' ``header.stamp`` (the sensor's clock; the bag's receipt
times carry the transport's jitter), the values ``angular_velocity`` in rad/s and
``linear_acceleration`` in m/s^2 (REP 103), converted to dps and g. With several Imu
topics, ``--topic`` picks one (refused otherwise, listing them). Rate and indices:
:mod:`imubench.recording.timebase`, on the messages sorted by their stamps (a bag holds
them in the order they were received). A covariance whose element 0 is -1 says the
sensor gives no such estimate (sensor_msgs/Imu): those values are not read as zeros. A
topic whose messages name several ``header.frame_id`` carries several IMUs and is
refused. ``--columns t=-`` with ``--rate`` reads the messages in order, without stamps.
"""

from __future__ import annotations

import contextlib
import io
import logging
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from imubench.batch import CHANNELS, Batch
from imubench.errors import RecordingError
from imubench.recording.options import (
    ACCEL_UNITS_G,
    GYRO_UNITS_DPS,
    NO_TIME_COLUMN,
    InputOptions,
)
from imubench.recording.textin import TextRead
from imubench.recording.timebase import Timebase, check_one_rate, timebase_from_times

IMU_TYPE = "sensor_msgs/msg/Imu"
log = logging.getLogger("imubench.recording")


@contextlib.contextmanager
def _decoder_output_as_warning(where: str) -> Iterator[None]:
    """What the ROS message decoders print on stderr or warn about (``mcap_ros2``'s vendored
    rosidl parser prints ``Error with: ...`` on a damaged schema) becomes one warning on
    ``imubench.recording``, with how many lines it was: the project's one format."""
    err = io.StringIO()
    with warnings.catch_warnings(record=True) as caught, contextlib.redirect_stderr(err):
        warnings.simplefilter("always")
        try:
            yield
        finally:
            said = [line for line in err.getvalue().splitlines() if line.strip()]
            said += [str(w.message) for w in caught]
            if said:
                first = said[0].encode("ascii", "backslashreplace").decode()[:120]
                log.warning("%s: the ROS message decoder reported %d line(s) (damaged "
                            "schema or message?), first: %s", where, len(said), first)


def is_ros2_bag(path: Path) -> bool:
    """A ROS 2 bag folder (``metadata.yaml`` inside) or its ``.db3`` storage file."""
    if path.suffix == ".db3":
        return True
    try:
        return path.is_dir() and (path / "metadata.yaml").is_file()
    except OSError:  # a name too long or unreadable: not a bag
        return False


def _pick_topic(topics: list[str], options: InputOptions, where: str) -> str:
    if not topics:
        raise RecordingError(f"{where}: no {IMU_TYPE} topic in this file")
    if options.topic is not None:
        if options.topic not in topics:
            raise RecordingError(f"{where}: no {IMU_TYPE} topic {options.topic!r}; the "
                                 f"file has {', '.join(topics)}")
        return options.topic
    if len(topics) > 1:
        raise RecordingError(f"{where}: several {IMU_TYPE} topics ({', '.join(topics)}); "
                             "pick one with --topic")
    return topics[0]


NO_ESTIMATE = -1.0
"""Element 0 of an Imu covariance that says the sensor gives no such estimate."""


Rows = tuple[list[tuple[float, ...]], set[str]]
"""(stamp, gx..az) per message, and the frame ids seen."""


def _rows_from(messages: Any) -> Rows:
    """(stamp, gx..az) per message, NaN for a sensor whose covariance says it gives no
    estimate; and the frame ids seen."""
    rows: list[tuple[float, ...]] = []
    frames: set[str] = set()
    nan = float("nan")
    for m in messages:
        s = m.header.stamp
        frames.add(str(m.header.frame_id))
        w, a = m.angular_velocity, m.linear_acceleration
        gyro = ((nan,) * 3 if m.angular_velocity_covariance[0] == NO_ESTIMATE
                else (w.x, w.y, w.z))
        acc = ((nan,) * 3 if m.linear_acceleration_covariance[0] == NO_ESTIMATE
               else (a.x, a.y, a.z))
        rows.append((s.sec + s.nanosec * 1e-9, *gyro, *acc))
    return rows, frames


def _read_bag(path: Path, options: InputOptions, where: str) -> tuple[str, Rows]:
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    bag = path.parent if path.suffix == ".db3" else path
    try:
        store = get_typestore(Stores.ROS2_HUMBLE)
        with _decoder_output_as_warning(where), AnyReader([bag], default_typestore=store) as r:
            conns = [c for c in r.connections if c.msgtype == IMU_TYPE]
            topic = _pick_topic(sorted({c.topic for c in conns}), options, where)
            mine = [c for c in conns if c.topic == topic]
            return topic, _rows_from(r.deserialize(raw, c.msgtype)
                                     for c, _, raw in r.messages(connections=mine))
    except RecordingError:
        raise
    except Exception as exc:  # rosbags' own errors: unreadable or damaged storage
        raise RecordingError(f"{where}: cannot read the ROS 2 bag: {exc}") from None


def _read_mcap(path: Path, options: InputOptions, where: str) -> tuple[str, Rows]:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    try:
        with _decoder_output_as_warning(where), open(path, "rb") as fh:
            reader = make_reader(fh, decoder_factories=[DecoderFactory()])
            summary = reader.get_summary()
            if summary is None:
                raise RecordingError(f"{where}: MCAP file without a summary (truncated?)")
            topics = sorted({ch.topic for ch in summary.channels.values()
                             if summary.schemas[ch.schema_id].name == IMU_TYPE})
            topic = _pick_topic(topics, options, where)
            return topic, _rows_from(dec for _, _, _, dec in
                                     reader.iter_decoded_messages(topics=[topic]))
    except RecordingError:
        raise
    except Exception as exc:  # the mcap reader's errors: bad magic, CRC, truncation
        raise RecordingError(f"{where}: cannot read the MCAP file: {exc}") from None


def read_ros(path: str | Path, options: InputOptions) -> TextRead:
    """Read the Imu messages of a ROS 2 bag or an MCAP file (module docstring)."""
    path = Path(path)
    where = str(path)
    fmt = "ROS 2 bag" if is_ros2_bag(path) else "MCAP"
    topic, (rows, frames) = (_read_bag if fmt == "ROS 2 bag" else _read_mcap)(
        path, options, where)
    if not rows:
        raise RecordingError(f"{where}: topic {topic} holds no messages")
    if len(frames) > 1:
        shown = ", ".join(repr(f) for f in sorted(frames)[:5])
        raise RecordingError(
            f"{where}: topic {topic} carries {len(frames)} frame ids ({shown}): several "
            "IMUs on one topic, whose samples would be read as one stream; record each "
            "IMU on its own topic")
    table = np.asarray(rows, dtype=np.float64)
    in_order = options.columns.get("t") == NO_TIME_COLUMN
    if not in_order:  # a bag holds messages as received: the stamps give their order
        table = table[np.argsort(table[:, 0], kind="stable")]
    gyro = options.gyro_unit or "rad/s"
    accel = options.accel_unit or "m/s2"
    values = np.column_stack([table[:, 1:4] * GYRO_UNITS_DPS[gyro],
                              table[:, 4:7] * ACCEL_UNITS_G[accel]])
    present: np.ndarray = np.asarray(~np.isnan(values).all(axis=0))
    absent = [name for name, has in (("gyro", present[:3].any()),
                                     ("accelerometer", present[3:].any())) if not has]
    if len(absent) == 2:
        raise RecordingError(f"{where}: every message of topic {topic} says (covariance "
                             "element 0 = -1) that it has neither angular velocity nor "
                             "linear acceleration")
    if in_order:
        if options.rate_hz is None:
            raise RecordingError(f"{where}: --columns t=- reads the messages in order and "
                                 "needs --rate HZ")
        tb = Timebase.in_order(options.rate_hz, len(table), "--rate, messages in order")
    else:
        tb = timebase_from_times(table[:, 0], where, options.rate_hz)
        check_one_rate(table[:, 0], tb.rate_hz,
                       lambda row: f"{where}: message {row + 1} of topic {topic}")
    keep = tb.keep
    channels = [c for c, has in zip(CHANNELS, present, strict=True) if has]
    meta: dict[str, Any] = {"odr_hz": float(tb.rate_hz), "source_format": fmt,
                            "topic": topic, "channels": channels}
    how = "--rate" if options.rate_hz is not None and not in_order else tb.how
    note = (f"{where}: read as {fmt}: topic {topic}, {len(rows)} messages; rate "
            f"{tb.rate_hz:.6g} Hz ({how}{'' if in_order else ', header.stamp'}); units gyro "
            f"{gyro}, accel {accel}"
            + (f"; no {' and no '.join(absent)} estimate (covariance element 0 = -1): "
               "not read" if absent else ""))
    batch = Batch(index=tb.index, t_s=table[keep, 0], values=values[keep],
                  temp_c=np.full(int(keep.sum()), np.nan))
    bad = [int(i) + 1 for i in np.nonzero(~keep)[0]]  # messages (in stamp order) dropped
    return TextRead(meta, batch, [], bad, [note], True, "message")
