"""Commands of the DataLogExtended serial protocol: builders of requests and replies.

Reference: ``lsm6ds-registers.md`` §14.A, tables "Generic commands", "Sensors-enabled
mask" and "Sensor sub-commands (cmd 0x50)" (read in X-CUBE-MEMS1 ``Serial_CMD.h``,
``sensor_commands.c`` and the SensorTile ``DemoSerial.c``). The device address is 0x32;
a reply goes to the source address of the request, with command code + 0x80. Integers
are little-endian, floats IEEE-754 little-endian.

Each ``*_request`` function returns the *logical message*; :func:`frame` adds checksum,
stuffing and terminator (``tmsg.encode_frame``).
"""

from __future__ import annotations

import struct
from enum import IntEnum, IntFlag

from lsm6ds.sensortile.tmsg import encode_frame

DEV_ADDR = 0x32
"""Address of the SensorTile firmware (``DEV_ADDR`` = 50)."""
HOST_ADDR = 0x01
"""Default host address (any byte works; the device replies to it)."""
REPLY_FLAG = 0x80
DATALOG_EXT_MODE = 101
"""Firmware id answered to *check mode support* (DataLogExtended)."""
PRESENTATION_STRING = "MEMS shield demo,101,4.0.0,0.0.0,STLKT01V1"
"""SensorTile presentation string of the DataLogExtended firmware (§14.A)."""


class Cmd(IntEnum):
    """Generic command codes (``Serial_CMD.h``)."""

    PING = 0x01
    READ_PRES_STRING = 0x02
    NACK = 0x03
    CHECK_MODE_SUPPORT = 0x04
    START_DATA_STREAMING = 0x08
    STOP_DATA_STREAMING = 0x09
    SET_DATE_TIME = 0x0C
    ENTER_DFU_MODE = 0x0E
    SENSOR_ENABLE = 0x10
    SENSOR = 0x50


class SensorMask(IntFlag):
    """ "Sensors enabled" mask of START_DATA_STREAMING (X-CUBE-MEMS1 ``main.h``)."""

    PRESSURE = 0x01
    TEMPERATURE = 0x02
    HUMIDITY = 0x04
    UV = 0x08
    ACCELEROMETER = 0x10
    GYROSCOPE = 0x20
    MAGNETOMETER = 0x40


IMU_MASK = SensorMask.ACCELEROMETER | SensorMask.GYROSCOPE | SensorMask.MAGNETOMETER
"""Mask 0x70 (accel + gyro + mag), the worked example of §14.A."""


class SensorType(IntEnum):
    """Byte 4 of a sensor command."""

    ACCELEROMETER = 1
    GYROSCOPE = 2
    MAGNETOMETER = 3
    TEMPERATURE = 4
    HUMIDITY = 5
    PRESSURE = 6
    UV = 7


class SensorSub(IntEnum):
    """Sub-command at byte 3 of a SENSOR (0x50) command."""

    GET_NAME = 0x01
    READ_REGISTER = 0x02
    WRITE_REGISTER = 0x03
    GET_FS_LIST = 0x04
    SET_FS = 0x05
    GET_ODR_LIST = 0x06
    SET_ODR = 0x07
    GET_SENSOR_LIST = 0x14
    SET_SENSOR_INDEX = 0x15
    GET_FS = 0x1E
    GET_ODR = 0x1F


def frame(message: bytes) -> bytes:
    """Wire bytes of a logical message (checksum, stuffing, ``0xF0``)."""
    return encode_frame(message)


def _msg(cmd: int, payload: bytes = b"", host: int = HOST_ADDR) -> bytes:
    return bytes([DEV_ADDR, host & 0xFF, cmd & 0xFF]) + payload


def ping_request(host: int = HOST_ADDR) -> bytes:
    """PING (0x01), no payload. Wire: ``32 01 01 CC F0``."""
    return _msg(Cmd.PING, host=host)


def presentation_request(host: int = HOST_ADDR) -> bytes:
    """READ_PRES_STRING (0x02); reply 0x82 + ASCII presentation string."""
    return _msg(Cmd.READ_PRES_STRING, host=host)


def check_mode_request(host: int = HOST_ADDR) -> bytes:
    """CHECK_MODE_SUPPORT (0x04); reply 0x84 + int32 LE firmware id (101)."""
    return _msg(Cmd.CHECK_MODE_SUPPORT, host=host)


def start_streaming_request(mask: int = IMU_MASK, host: int = HOST_ADDR) -> bytes:
    """START_DATA_STREAMING (0x08) + uint32 LE sensors mask.

    Mask 0x70 on the wire: ``32 01 08 70 00 00 00 55 F0``.
    """
    return _msg(Cmd.START_DATA_STREAMING, struct.pack("<I", mask & 0xFFFFFFFF), host=host)


def stop_streaming_request(host: int = HOST_ADDR) -> bytes:
    """STOP_DATA_STREAMING (0x09), no payload."""
    return _msg(Cmd.STOP_DATA_STREAMING, host=host)


def set_time_request(hours: int, minutes: int, seconds: int, host: int = HOST_ADDR) -> bytes:
    """SET_DATE_TIME (0x0C) + hh, mm, ss bytes (sets the firmware RTC)."""
    if not (0 <= hours <= 23 and 0 <= minutes <= 59 and 0 <= seconds <= 59):
        raise ValueError(f"set_time_request: {hours:02d}:{minutes:02d}:{seconds:02d} is no time")
    return _msg(Cmd.SET_DATE_TIME, bytes([hours, minutes, seconds]), host=host)


def sensor_request(sub: int, sensor: int, args: bytes = b"", host: int = HOST_ADDR) -> bytes:
    """SENSOR (0x50): byte 3 sub-command, byte 4 sensor type, then ``args``."""
    return _msg(Cmd.SENSOR, bytes([sub & 0xFF, sensor & 0xFF]) + args, host=host)


def get_name_request(sensor: int, host: int = HOST_ADDR) -> bytes:
    """SENSOR/GET_NAME; reply carries the sensor name ASCII from byte 5."""
    return sensor_request(SensorSub.GET_NAME, sensor, host=host)


def read_register_request(sensor: int, reg: int, host: int = HOST_ADDR) -> bytes:
    """SENSOR/READ_REGISTER: byte 5 = register; reply byte 6 = value."""
    return sensor_request(SensorSub.READ_REGISTER, sensor, bytes([reg & 0xFF]), host=host)


def write_register_request(sensor: int, reg: int, value: int, host: int = HOST_ADDR) -> bytes:
    """SENSOR/WRITE_REGISTER: byte 5 register, byte 6 value."""
    return sensor_request(
        SensorSub.WRITE_REGISTER, sensor, bytes([reg & 0xFF, value & 0xFF]), host=host
    )


def set_fs_request(sensor: int, full_scale: int, host: int = HOST_ADDR) -> bytes:
    """SENSOR/SET_FS: uint32 LE full scale at byte 5 (g for accel, dps for gyro)."""
    return sensor_request(SensorSub.SET_FS, sensor, struct.pack("<I", full_scale), host=host)


def get_fs_request(sensor: int, host: int = HOST_ADDR) -> bytes:
    """SENSOR/GET_FS; reply uint32 LE full scale at byte 5."""
    return sensor_request(SensorSub.GET_FS, sensor, host=host)


def set_odr_request(sensor: int, odr_hz: float, host: int = HOST_ADDR) -> bytes:
    """SENSOR/SET_ODR: float32 LE ODR in Hz at byte 5."""
    return sensor_request(SensorSub.SET_ODR, sensor, struct.pack("<f", odr_hz), host=host)


def get_odr_request(sensor: int, host: int = HOST_ADDR) -> bytes:
    """SENSOR/GET_ODR; reply float32 LE ODR in Hz at byte 5."""
    return sensor_request(SensorSub.GET_ODR, sensor, host=host)


def reply_message(request: bytes, payload: bytes = b"") -> bytes:
    """The device's reply to a logical request: addresses swapped, command + 0x80.

    For SENSOR commands the reply echoes sub-command and sensor type (bytes 3-4) before
    its own data, as ``sensor_commands.c`` builds it in place.
    """
    dest, src, cmd = request[0], request[1], request[2]
    head = bytes([src, dest, (cmd | REPLY_FLAG) & 0xFF])
    if cmd == Cmd.SENSOR:
        head += request[3:5]
    return head + payload


def nack_message(request: bytes) -> bytes:
    """NACK (0x03) header sent by the device for an unknown or malformed command."""
    return bytes([request[1], request[0], Cmd.NACK])
