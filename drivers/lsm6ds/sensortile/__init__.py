"""The SensorTile (STEVAL-STLKT01V1) USB serial link: TMsg framing, commands, stream, ASCII.

Modules: :mod:`~lsm6ds.sensortile.tmsg` (checksum, byte stuffing, incremental deframer),
:mod:`~lsm6ds.sensortile.commands` (request builders), :mod:`~lsm6ds.sensortile.stream`
(the 56-byte stream frame, RTC time line), :mod:`~lsm6ds.sensortile.datalog_ascii` (the
DataLog ASCII fallback) and :mod:`~lsm6ds.sensortile.link` (port, commands, stream,
reconnection). Protocol reference: ``lsm6ds-registers.md`` §14.
"""

from lsm6ds.sensortile.commands import DEV_ADDR, HOST_ADDR, IMU_MASK, Cmd, SensorMask
from lsm6ds.sensortile.datalog_ascii import BadRecord, DataLogParser, DataLogRecord
from lsm6ds.sensortile.link import LinkConfig, Received, SensorTileError, SensorTileLink
from lsm6ds.sensortile.stream import (
    RtcTimeline,
    StreamFrame,
    parse_stream_message,
)
from lsm6ds.sensortile.tmsg import BadFrame, Frame, FrameDecoder, checksum, encode_frame

__all__ = [
    "DEV_ADDR",
    "HOST_ADDR",
    "IMU_MASK",
    "BadFrame",
    "BadRecord",
    "Cmd",
    "DataLogParser",
    "DataLogRecord",
    "Frame",
    "FrameDecoder",
    "LinkConfig",
    "Received",
    "RtcTimeline",
    "SensorMask",
    "SensorTileError",
    "SensorTileLink",
    "StreamFrame",
    "checksum",
    "encode_frame",
    "parse_stream_message",
]
