"""Byte-exact tests of the SensorTile TMsg protocol, stream layout, RTC and DataLog ASCII.

Expected bytes come from ``lsm6ds-registers.md`` §14 (worked bytes, layout tables) or are
derived by hand in the comments from the rules stated there; none is produced by the
encoder under test.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator

import pytest
from lsm6ds.sensortile import commands as cmds
from lsm6ds.sensortile import link as link_mod
from lsm6ds.sensortile.datalog_ascii import BadRecord, DataLogParser, DataLogRecord
from lsm6ds.sensortile.link import LinkConfig, SensorTileError, SensorTileLink
from lsm6ds.sensortile.stream import (
    RTC_WRAP_CS,
    RtcTimeline,
    StreamFrame,
    parse_stream_message,
)
from lsm6ds.sensortile.tmsg import BadFrame, Frame, FrameDecoder, checksum, encode_frame

H = bytes.fromhex


# --------------------------------------------------------------------- framing
def test_worked_bytes_of_section_14() -> None:
    """§14.A worked bytes: ping and start streaming (mask 0x70) with their replies."""
    assert cmds.frame(cmds.ping_request()) == H("32 01 01 CC F0")
    assert cmds.frame(cmds.start_streaming_request(0x70)) == H("32 01 08 70 00 00 00 55 F0")
    assert encode_frame(cmds.reply_message(cmds.ping_request())) == H("01 32 81 4C F0")
    assert encode_frame(cmds.reply_message(cmds.start_streaming_request(0x70))) == H(
        "01 32 88 45 F0"
    )


def test_command_frames_by_hand() -> None:
    # 32 01 02: sum 0x35 -> chk 0xCB
    assert cmds.frame(cmds.presentation_request()) == H("32 01 02 CB F0")
    # 32 01 04: sum 0x37 -> chk 0xC9
    assert cmds.frame(cmds.check_mode_request()) == H("32 01 04 C9 F0")
    # 32 01 09: sum 0x3C -> chk 0xC4
    assert cmds.frame(cmds.stop_streaming_request()) == H("32 01 09 C4 F0")
    # 32 01 0C 0B 3B 3B (11:59:59): sum 0xC0 -> chk 0x40
    assert cmds.frame(cmds.set_time_request(11, 59, 59)) == H("32 01 0C 0B 3B 3B 40 F0")
    # 32 01 50 1E 02 (get FS, gyro): sum 0xA3 -> chk 0x5D
    assert cmds.frame(cmds.get_fs_request(cmds.SensorType.GYROSCOPE)) == H("32 01 50 1E 02 5D F0")
    # host address 0x05: 32 05 01 -> sum 0x38 -> chk 0xC8
    assert cmds.frame(cmds.ping_request(host=0x05)) == H("32 05 01 C8 F0")


def test_byte_stuffing_by_hand() -> None:
    # message 32 01 F0 F1: sum 0x214 -> low byte 0x14 -> chk 0xEC;
    # F0 -> F1 F2, F1 -> F1 F1, then the terminator F0.
    msg = H("32 01 F0 F1")
    assert checksum(msg) == 0xEC
    assert encode_frame(msg) == H("32 01 F1 F2 F1 F1 EC F0")
    # a checksum that is itself F0 gets stuffed: 32 01 DD -> sum 0x110 -> chk 0xF0
    assert encode_frame(H("32 01 DD")) == H("32 01 DD F1 F2 F0")


def test_decoder_any_split_gives_same_frames() -> None:
    wire = (
        encode_frame(H("32 01 F0 F1"))
        + cmds.frame(cmds.ping_request())
        + encode_frame(H("32 01 DD"))
    )
    for step in (1, 2, 3, 7, len(wire)):
        dec = FrameDecoder()
        out = [f for i in range(0, len(wire), step) for f in dec.feed(wire[i : i + step])]
        assert out == [Frame(H("32 01 F0 F1")), Frame(H("32 01 01")), Frame(H("32 01 DD"))]
        assert dec.bad_frames == 0


@pytest.mark.parametrize(
    ("wire", "reason"),
    [
        (H("32 01 01 CD F0"), "checksum"),  # sum 0x01
        (H("32 01 F1 03 CC F0"), "invalid escape"),
        (H("32 01 01 CC F1 F0"), "escape byte"),
        (H("F0"), "empty"),
        (H("32 01 F0"), "shorter"),
    ],
)
def test_decoder_rejects_and_resynchronises(wire: bytes, reason: str) -> None:
    dec = FrameDecoder()
    out = list(dec.feed(wire + cmds.frame(cmds.ping_request())))
    assert isinstance(out[0], BadFrame) and reason in out[0].reason
    assert out[-1] == Frame(H("32 01 01"))
    assert dec.bad_frames == len(out) - 1 and dec.frames == 1


def test_decoder_drops_overlong_run() -> None:
    dec = FrameDecoder(max_len=64)
    # no start byte: the run up to the next F0 is one frame, however long
    out = list(dec.feed(bytes(500) + H("F0") + cmds.frame(cmds.ping_request())))
    assert isinstance(out[0], BadFrame) and "terminator" in out[0].reason
    assert out[1] == Frame(H("32 01 01"))


# --------------------------------------------------------------------- stream layout
def _stream_bytes() -> bytes:
    """A stream message laid out field by field from the §14.A table (not by the packer)."""
    msg = bytes([0x01, 0x32, 0x08])
    msg += bytes([11, 59, 59, 99])  # RTC 11:59:59.99
    msg += struct.pack("<f", 1013.25) + struct.pack("<f", 25.5) + struct.pack("<f", 40.0)
    msg += b"".join(v.to_bytes(4, "little", signed=True) for v in (-12, 34, 1001))  # mg
    msg += b"".join(v.to_bytes(4, "little", signed=True) for v in (70, -8750, 123456))  # mdps
    msg += b"".join(v.to_bytes(4, "little", signed=True) for v in (220, -45, -410))  # mgauss
    msg += bytes([0b100111])  # acc, gyro, mag, temp
    return msg


def test_stream_frame_layout() -> None:
    msg = _stream_bytes()
    assert len(msg) == 56
    f = parse_stream_message(msg)
    assert f.rtc == (11, 59, 59, 99)
    assert (f.pressure_hpa, f.temperature_c, f.humidity_pct) == (1013.25, 25.5, 40.0)
    assert f.accel_mg == (-12, 34, 1001)
    assert f.gyro_mdps == (70, -8750, 123456)
    assert f.mag_mgauss == (220, -45, -410)
    assert f.flags == 0x27
    assert f.pack() == msg
    assert f.rtc_cs == RTC_WRAP_CS - 1


def test_stream_frame_rejects_damage() -> None:
    msg = _stream_bytes()
    with pytest.raises(ValueError, match="56"):
        parse_stream_message(msg[:-1])
    with pytest.raises(ValueError, match="RTC"):
        parse_stream_message(msg[:4] + bytes([60]) + msg[5:])
    with pytest.raises(ValueError, match="flag"):
        parse_stream_message(msg[:-1] + bytes([0x80]))


def test_rtc_timeline_unwraps_12_hours_and_counts_holes() -> None:
    tl = RtcTimeline(period_cs=1)

    def cs(h: int, m: int, s: int, c: int) -> int:
        return StreamFrame(1, (h, m, s, c), 0, 0, 0, (0,) * 3, (0,) * 3, (0,) * 3, 0).rtc_cs

    assert tl.accept(cs(11, 59, 59, 97)) == 0
    assert tl.accept(cs(11, 59, 59, 98)) == 1
    assert tl.accept(cs(12, 0, 0, 0)) == 3  # 12-hour display "12": .99 lost
    assert tl.accept(cs(0, 0, 0, 1)) == 4  # the same instant family, shown as 00
    assert tl.accept(cs(0, 0, 0, 1)) is None  # duplicate
    assert tl.accept(cs(0, 0, 0, 0)) is None  # backwards
    assert tl.accept(cs(0, 0, 1, 0)) == 103
    assert tl.elapsed_s == pytest.approx(1.03)  # 11:59:59.97 -> 00:00:01.00


def test_rtc_timeline_host_check_reanchors_after_rtc_reset() -> None:
    tl = RtcTimeline(period_cs=1, host_check_s=2.0)
    assert tl.accept(360000 * 3, host_s=100.0) == 0  # 03:00:00.00
    assert tl.accept(360000 * 3 + 1, host_s=100.01) == 1
    # kit rebooted: RTC back to 00:00:00.00 while 30 s passed on the host
    assert tl.accept(0, host_s=130.01) == 3001
    assert tl.reanchors == 1


def test_rtc_timeline_trusts_the_rtc_when_the_host_was_late() -> None:
    """A host paused 2.6 s reads the frames that waited in the serial buffers in one
    burst: each stamp is one period after the last, the host delta 2.6 s. The index
    follows the RTC (the host's delta invented 260 lost frames and stamped every later
    frame 2.6 s late)."""
    tl = RtcTimeline(period_cs=1, host_check_s=2.0)
    assert tl.accept(5000, host_s=100.0) == 0
    assert tl.accept(5001, host_s=100.01) == 1
    assert tl.accept(5002, host_s=102.61) == 2  # read late, after the pause
    assert tl.accept(5003, host_s=102.611) == 3  # the rest of the burst
    assert tl.accept(5263, host_s=102.62) == 263  # frames the kit did lose: counted
    assert tl.reanchors == 0


# --------------------------------------------------------------------- DataLog ASCII
DATALOG_TEXT = (
    b"TimeStamp: 1200\r\n"
    b" Acc_X: 12, Acc_Y: -3, Acc_Z :1001\r\n"
    b" Gyro_X:150, Gyro_Y:-280, Gyro_Z:70\r\n"
    b" Magn_X:-200, Magn_Y:110, Magn_Z:-420\r\n"
    b" Press:1013.25, Temp:25.00, Hum:45.0\r\n"
)
RECORD = DataLogRecord(
    1200, (12, -3, 1001), (150, -280, 70), (-200, 110, -420), 1013.25, 25.0, 45.0
)


def test_datalog_format_and_parse() -> None:
    assert RECORD.format() == DATALOG_TEXT
    for step in (1, 5, len(DATALOG_TEXT)):
        p = DataLogParser()
        out = [
            r for i in range(0, len(DATALOG_TEXT), step) for r in p.feed(DATALOG_TEXT[i : i + step])
        ]
        assert out == [RECORD]


def test_datalog_resynchronises_after_damage() -> None:
    damaged = DATALOG_TEXT.replace(b"Gyro_Y", b"Gy#o_Y")
    p = DataLogParser()
    out = list(p.feed(b"o_Z:1\r\n" + damaged + DATALOG_TEXT))  # starts mid-record
    assert p.skipped_lines == 3  # the partial line, then Magn and Press of the bad block
    assert isinstance(out[0], BadRecord)
    assert out[-1] == RECORD and p.records == 1


# --------------------------------------------------------------------- expected_protocol
class ExpectedPort:
    """pymeasure ``expected_protocol`` style: each write must equal the next expected
    bytes exactly; the paired reply is then served to reads."""

    def __init__(self, exchanges: list[tuple[bytes, bytes]]) -> None:
        self.exchanges = list(exchanges)
        self.rx = bytearray()
        self.is_open = True

    @property
    def in_waiting(self) -> int:
        return len(self.rx)

    def write(self, data: bytes) -> int:
        assert self.exchanges, f"unexpected write {bytes(data).hex(' ')}"
        want, reply = self.exchanges.pop(0)
        assert bytes(data) == want, f"wrote {bytes(data).hex(' ')}, expected {want.hex(' ')}"
        self.rx += reply
        return len(data)

    def read(self, n: int = 1) -> bytes:
        out = bytes(self.rx[:n])
        del self.rx[:n]
        return out

    def flush(self) -> None:
        pass

    def close(self) -> None:
        self.is_open = False


@pytest.fixture
def expected(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[ExpectedPort]]:
    """Queue of ExpectedPorts handed out by serial_for_url; all must be used up."""
    queue: list[ExpectedPort] = []
    used: list[ExpectedPort] = []

    def fake_serial_for_url(url: str, **kwargs: object) -> ExpectedPort:
        port = queue.pop(0)
        used.append(port)
        return port

    monkeypatch.setattr(link_mod.serial, "serial_for_url", fake_serial_for_url)
    yield queue
    for port in used:
        assert not port.exchanges, f"expected exchanges never happened: {port.exchanges}"


def test_link_commands_byte_exact(expected: list[ExpectedPort]) -> None:
    pres = b"MEMS shield demo,101,4.0.0,0.0.0,STLKT01V1"
    pres_reply = bytes([0x01, 0x32, 0x82]) + pres
    port = ExpectedPort(
        [
            (H("32 01 01 CC F0"), H("01 32 81 4C F0")),
            (H("32 01 02 CB F0"), encode_frame(pres_reply)),
            # check mode: reply 01 32 84 65 00 00 00 -> sum 0x11C -> chk 0xE4
            (H("32 01 04 C9 F0"), H("01 32 84 65 00 00 00 E4 F0")),
            (H("32 01 08 70 00 00 00 55 F0"), H("01 32 88 45 F0")),
            # stop: reply 01 32 89 -> sum 0xBC -> chk 0x44
            (H("32 01 09 C4 F0"), H("01 32 89 44 F0")),
        ]
    )
    expected.append(port)
    link = SensorTileLink("fake://", config=LinkConfig(reply_timeout_s=0.2))
    link.open()
    link.ping()
    assert link.presentation() == pres.decode()
    assert link.check_mode() == 101
    link.start_streaming(0x70)
    link.stop_streaming()
    assert not port.exchanges
    link.close()


def test_link_nack_and_retry(expected: list[ExpectedPort]) -> None:
    # first ping reply is damaged (bad checksum): the link re-sends, second one answers;
    # then an unknown command gets NACK (01 32 03 -> sum 0x36 -> chk 0xCA)
    port = ExpectedPort(
        [
            (H("32 01 01 CC F0"), H("01 32 81 4D F0")),
            (H("32 01 01 CC F0"), H("01 32 81 4C F0")),
            (H("32 01 0E BF F0"), H("01 32 03 CA F0")),
        ]
    )
    expected.append(port)
    link = SensorTileLink("fake://", config=LinkConfig(reply_timeout_s=0.05))
    link.ping()
    assert link.counters["retries"] == 1 and link.counters["bad_frames"] == 1
    with pytest.raises(SensorTileError, match="NACK"):
        link.command(bytes([0x32, 0x01, 0x0E]))


def test_link_on_pyserial_loop_url() -> None:
    """``loop://`` goes through the same serial_for_url code; what we write comes back."""
    link = SensorTileLink("loop://")
    link.open()
    frame = parse_stream_message(_stream_bytes())
    link._port.write(encode_frame(frame.pack()))  # type: ignore[union-attr]
    got = link.read_stream(timeout_s=1.0)
    assert [r.item for r in got] == [frame]
    link.close()


def test_link_open_error_names_port() -> None:
    with pytest.raises(SensorTileError, match="/nonexistent/ttyACM9"):
        SensorTileLink("/nonexistent/ttyACM9").open()
