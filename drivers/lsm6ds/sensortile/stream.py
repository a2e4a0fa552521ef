"""The SensorTile DataLogExtended stream frame and its RTC time line.

Layout of the 56-byte logical message (``lsm6ds-registers.md`` §14.A, "Stream payload —
SensorTile DataLogExtended 2018", read in the SensorTile ``main.c`` with
``STREAMING_MSG_LENGTH`` 56):

===========  =========================================================  ================
bytes        content                                                    type / unit
===========  =========================================================  ================
0 / 1 / 2    host address / 0x32 / 0x08                                uint8
3, 4, 5, 6   RTC hours, minutes, seconds, hundredths (12-hour format)   uint8
7-10         pressure                                                   float32, hPa
11-14        temperature                                                float32, degC
15-18        humidity                                                   float32, %
19-30        accel X, Y, Z                                              int32 LE, mg
31-42        gyro X, Y, Z                                               int32 LE, mdps
43-54        mag X, Y, Z                                                int32 LE, mgauss
55           new-data flags b0 acc, b1 gyro, b2 mag, b3 press, b4 hum,  uint8
             b5 temp
===========  =========================================================  ================

The frame carries no sequence number: its only position in time is the RTC stamp
(10 ms resolution, wrapping every 12 hours). :class:`RtcTimeline` turns stamps into the
frame index ``round(elapsed / period)`` so that a lost frame becomes a hole.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from lsm6ds.sensortile.commands import DEV_ADDR, Cmd

STREAM_MESSAGE_LEN = 56
"""Length of the logical stream message (header + payload, checksum excluded)."""
_PAYLOAD = struct.Struct("<4B3f3i3i3iB")
assert _PAYLOAD.size == STREAM_MESSAGE_LEN - 3

FLAG_ACC = 0x01
FLAG_GYRO = 0x02
FLAG_MAG = 0x04
FLAG_PRESS = 0x08
FLAG_HUM = 0x10
FLAG_TEMP = 0x20
_FLAGS_ALL = 0x3F

RTC_WRAP_CS = 12 * 3600 * 100
"""The 12-hour RTC repeats every 4 320 000 hundredths of a second."""


@dataclass(frozen=True)
class StreamFrame:
    """One decoded stream frame (integers exactly as the firmware sent them).

    Attributes:
        host: destination (host) address of the frame.
        rtc: (hours, minutes, seconds, hundredths) of the firmware RTC.
        pressure_hpa, temperature_c, humidity_pct: float32 values widened to float.
        accel_mg: accelerometer X, Y, Z in mg (int32).
        gyro_mdps: gyroscope X, Y, Z in mdps (int32).
        mag_mgauss: magnetometer X, Y, Z in mgauss (int32).
        flags: new-data flags (``FLAG_*``); a field whose flag is 0 holds a stale value.
    """

    host: int
    rtc: tuple[int, int, int, int]
    pressure_hpa: float
    temperature_c: float
    humidity_pct: float
    accel_mg: tuple[int, int, int]
    gyro_mdps: tuple[int, int, int]
    mag_mgauss: tuple[int, int, int]
    flags: int

    @property
    def rtc_cs(self) -> int:
        """RTC stamp in hundredths of a second modulo 12 h (hours taken modulo 12)."""
        h, m, s, cc = self.rtc
        return (((h % 12) * 60 + m) * 60 + s) * 100 + cc

    def pack(self) -> bytes:
        """The 56-byte logical message (what the firmware frames)."""
        return bytes([self.host & 0xFF, DEV_ADDR, Cmd.START_DATA_STREAMING]) + _PAYLOAD.pack(
            *self.rtc,
            self.pressure_hpa,
            self.temperature_c,
            self.humidity_pct,
            *self.accel_mg,
            *self.gyro_mdps,
            *self.mag_mgauss,
            self.flags,
        )


def is_stream_message(message: bytes) -> bool:
    """True for a logical message with the stream header (``.. 32 08``), any length."""
    return len(message) >= 3 and message[1] == DEV_ADDR and message[2] == Cmd.START_DATA_STREAMING


def parse_stream_message(message: bytes) -> StreamFrame:
    """Decode a 56-byte stream message (checksum already removed).

    Raises:
        ValueError: wrong length or header, impossible RTC fields or undefined flag bits
            (a frame damaged in a way the 8-bit checksum missed).
    """
    if len(message) != STREAM_MESSAGE_LEN:
        raise ValueError(
            f"stream frame has {len(message)} bytes, want {STREAM_MESSAGE_LEN} "
            "(SensorTile DataLogExtended layout)"
        )
    if not is_stream_message(message):
        raise ValueError(f"not a stream frame: header {message[:3].hex(' ')}")
    v = _PAYLOAD.unpack(message[3:])
    h, m, s, cc = v[0:4]
    if h > 23 or m > 59 or s > 59 or cc > 99:
        raise ValueError(f"impossible RTC stamp {h:02d}:{m:02d}:{s:02d}.{cc:02d}")
    if v[16] & ~_FLAGS_ALL:
        raise ValueError(f"undefined new-data flag bits 0x{v[16]:02X}")
    return StreamFrame(
        host=message[0],
        rtc=(h, m, s, cc),
        pressure_hpa=v[4],
        temperature_c=v[5],
        humidity_pct=v[6],
        accel_mg=(v[7], v[8], v[9]),
        gyro_mdps=(v[10], v[11], v[12]),
        mag_mgauss=(v[13], v[14], v[15]),
        flags=v[16],
    )


class RtcTimeline:
    """Frame index and time from the 12-hour, 10 ms RTC stamps, optionally checked by the host.

    ``index = round((rtc_unwrapped_cs - rtc_first_cs) / period_cs)`` where the unwrapped
    RTC adds 12 h each time the stamp moves backwards across the wrap. A stamp that does
    not move forward (``delta mod 12 h`` in the upper half, or zero) is rejected: the
    frame is a duplicate or damaged.

    With ``host_check_s`` set (wall-clock sources), the RTC is checked against the host
    clock: a frame is read after it was stamped, so the host's time since the first frame
    less the RTC's (the frame's latency, plus the clocks' drift) never falls more than
    ``host_check_s`` below its lowest value so far unless the firmware RTC was reset
    (reboot after a USB unplug of a bus-powered kit: a stamp back at 00:00:00 reads as
    nearly 12 h ahead) or jumped; the index then continues from the host's delta instead
    (``reanchors`` counts these). A latency that GROWS is the host being late, not the
    kit: a busy host reads the frames that waited in the serial buffers in one burst,
    and the RTC, not the host, says which frames they are and which the kit lost (taking
    the host's delta there counted a 2.6 s pause as 260 lost frames and stamped every
    later frame 2.6 s late).
    """

    def __init__(self, period_cs: float, host_check_s: float | None = None) -> None:
        if period_cs <= 0:
            raise ValueError(f"RtcTimeline: period_cs must be > 0, got {period_cs}")
        self.period_cs = float(period_cs)
        self.host_check_s = host_check_s
        self._last_cs: int | None = None
        self._unwrapped = 0
        self._last_host: float | None = None
        self._last_index = -1
        self._first_host: float | None = None
        self._least_latency_cs = 0.0
        self.reanchors = 0

    @property
    def last_index(self) -> int:
        return self._last_index

    def accept(self, rtc_cs: int, host_s: float | None = None) -> int | None:
        """Index of a frame stamped ``rtc_cs``, or None when the stamp is not plausible."""
        if self._last_cs is None:
            self._last_cs = rtc_cs
            self._last_host = host_s
            self._first_host = host_s
            self._last_index = 0
            return 0
        delta = (rtc_cs - self._last_cs) % RTC_WRAP_CS
        use_host = False
        latency_cs = 0.0
        if (self.host_check_s is not None and host_s is not None
                and self._first_host is not None):
            latency_cs = (host_s - self._first_host) * 100.0 - (self._unwrapped + delta)
            use_host = latency_cs < self._least_latency_cs - self.host_check_s * 100.0
        if use_host:
            assert host_s is not None and self._last_host is not None
            delta = max(round((host_s - self._last_host) * 100.0), 1)
            self.reanchors += 1
            assert self._first_host is not None
            latency_cs = (host_s - self._first_host) * 100.0 - (self._unwrapped + delta)
            self._least_latency_cs = latency_cs
        elif delta == 0 or delta > RTC_WRAP_CS // 2:
            return None
        index = round((self._unwrapped + delta) / self.period_cs)
        if index <= self._last_index:
            return None
        self._unwrapped += delta
        self._last_cs = rtc_cs
        self._last_host = host_s
        self._last_index = index
        self._least_latency_cs = min(self._least_latency_cs, latency_cs)
        return index

    def time_s(self, index: int) -> float:
        """Seconds since the first frame, from the RTC (10 ms resolution)."""
        return index * self.period_cs / 100.0

    @property
    def elapsed_s(self) -> float:
        """Unwrapped RTC seconds since the first frame."""
        return self._unwrapped / 100.0
