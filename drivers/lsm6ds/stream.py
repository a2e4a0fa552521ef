"""FIFO streaming of gyro + accelerometer sample sets (reference §9, §12).

:class:`FifoStream` runs the FIFO in continuous mode at FIFO ODR = sensor ODR, gyro and
accelerometer not decimated, and (by default) the timestamp as 4th data set every ``d``
slots (``d`` chosen so that the bus budget holds). One :meth:`FifoStream.poll`:

1. reads FIFO_STATUS1-4 in one 4-byte transfer (level, flags, pattern position);
2. on OVER_RUN (the FIFO overwrote its oldest data sets, continuous mode §9.3) keeps the
   data still held: they are valid, only their first pattern may be cut; the timestamps
   size the gap (samples lost are reported, never silent);
3. reads whole patterns (a pattern cut by an overwrite or a previous read is completed
   from the words kept from that read, or skipped) in one ``i2c_rdwr`` burst from
   FIFO_DATA_OUT_L, at most 4092 bytes;
4. reads FIFO_STATUS1-4 again: the pattern position after the burst tells where the
   burst really began. If the host stalled between the status and the data read long
   enough for the FIFO to overwrite (a busy host, a GIL-holding thread: 48 ms at
   6660 Hz), the burst began after the overwritten data sets, not at a pattern start;
   the words are then re-aligned on that position instead of being decoded shifted;
5. decodes the words vectorised into sample indices (nominal ODR periods since the first
   sample), raw int16 and host times, checks the timestamps (successive patterns exactly
   one pattern apart; the first one after the previous poll's within the host time that
   passed), and reads the temperature once. A chunk whose timestamps fail the check is
   discarded and the FIFO restarted (``resyncs``); the next chunk's timestamps size the
   whole hole, so nothing is counted twice and no index is invented.

Sample index. Inside one FIFO run slots are consecutive. Each pattern's timestamp
(25 us ticks, unwrapped modulo 2^24 with the number of wraps taken from the host clock)
gives the exact number of slots skipped across an overwrite or restart:
``round(delta_ticks / ticks_per_slot)`` with ``ticks_per_slot = 40 000 / odr`` (timestamp
and ODR share the chip's oscillator, so this holds whatever its frequency error). After a
chip reset the counter restarts; the gap is then sized from host time, mapping ticks to
host seconds with the tick period estimated against the host clock (the sensor clock's
drift). Without timestamps, gaps are sized from the host clock alone (±1 sample).

Chip resets are detected by reading back CTRL1_XL/CTRL2_G every ``verify_every_s`` and
whenever the FIFO is empty when data were due; then the stream re-probes, reconfigures
and restarts.
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass, field

import numpy as np

from lsm6ds.driver import LSM6DS, ImuConfig
from lsm6ds.errors import (
    BusBudgetError,
    ConfigurationError,
    DriverIOError,
    LSM6DSError,
    ProbeError,
)
from lsm6ds.registers import DECIMATION, FIFO_DEPTH_WORDS, FIFO_MODES, ODR_HZ

TICK_S = 25e-6
"""Timestamp tick at TIMER_HR = 1 (§7-8)."""
TICKS_WRAP = 1 << 24
MAX_BURST_BYTES = 4092
"""One FIFO burst at most: the whole FIFO (§9.2)."""
HOST_JITTER_S = 0.002
"""Host timing error allowed when the words a FIFO dropped are estimated from the host
clock (between two status reads), s."""
CLOCK_TOLERANCE = 0.5
"""A tick period measured within this share of the nominal 25 us is the chip's clock (an
oscillator 10.5 % slow was refused by the earlier 10 %, and its ODR reported as exactly
nominal: the jig's ``fifo.odr_error`` read 0 % and passed a part outside its +-10 %);
a part further off is broken beyond what its timestamps can be trusted for."""
DRIFT_JUMP = 0.02
"""Once the period is measured, a reading that implies a period this far from it is a
counter reset under the reading (the next poll sees the reset), not the clock."""
SLEW_PER_SAMPLE = 0.1
"""Most a sample's time stamp departs from the clock model's, per sample, while a change
of that model (the tick period's estimate, a host read time) is taken in: a tenth of the
sample period, so the stamps never run backwards and each step stays within 10 % of the
period (the stamps converge in ten times the change: a 37 ms correction in 0.37 s)."""
BITS_PER_BYTE = 9
BUDGET_FRACTION = 0.95
"""Share of the bus payload limit the stream may plan to use."""


def ds4_decimation_code(factor: int) -> int:
    for code, f in DECIMATION.items():
        if f == factor:
            return code
    raise ValueError(f"decimation factor {factor} is not one of 1, 2, 3, 4, 8, 16, 32")


@dataclass
class StreamChunk:
    """Samples decoded by one poll.

    Attributes:
        index: int64 (n,) sample index (nominal ODR periods since the first sample).
        raw: int16 (n, 6) gx gy gz ax ay az counts.
        t_s: float64 (n,) host time of each sample, s (driver's ``monotonic`` scale).
        temp_c: temperature read at this poll, degC.
        gaps: (index of the sample after the hole, samples lost, reason) of this chunk.
    """

    index: np.ndarray
    raw: np.ndarray
    t_s: np.ndarray
    temp_c: float
    gaps: list[tuple[int, int, str]] = field(default_factory=list)


def bus_need_bytes_per_s(odr_hz: float, ts_decimation: int | None) -> float:
    """FIFO data rate of gyro+accel (12 bytes per slot) plus a 6-byte timestamp set every
    ``ts_decimation`` slots, B/s."""
    per_slot = 12.0 + (6.0 / ts_decimation if ts_decimation else 0.0)
    return odr_hz * per_slot


class FifoStream:
    """Continuous FIFO streaming of one :class:`LSM6DS`.

    Args:
        dev: the driver (configured or not: :meth:`start` configures it).
        cfg: sensor configuration.
        watermark_s: data the stream lets accumulate between polls, s (capped at 40 %
            of the FIFO).
        bus_hz: I2C speed for the budget check (None = no check).
        on_overbudget: ``refuse`` (raise :class:`BusBudgetError`) or ``degrade`` (use
            the highest ODR that fits and say so in :attr:`degraded_from_hz`).
        verify_every_s: period of the configuration read-back, s.
        max_fill: largest watermark as a share of the FIFO depth.
    """

    def __init__(
        self,
        dev: LSM6DS,
        cfg: ImuConfig,
        *,
        watermark_s: float = 0.1,
        bus_hz: float | None = None,
        on_overbudget: str = "refuse",
        verify_every_s: float = 1.0,
        max_fill: float = 0.4,
    ) -> None:
        if on_overbudget not in ("refuse", "degrade"):
            raise ValueError(f"on_overbudget={on_overbudget!r} must be refuse or degrade")
        self.dev = dev
        self.bus_hz = bus_hz
        self.on_overbudget = on_overbudget
        self.verify_every_s = verify_every_s
        self.degraded_from_hz: float | None = None
        if cfg.odr_xl_hz != cfg.odr_hz:
            raise ConfigurationError(
                f"{dev.chip}: gyro at {cfg.odr_hz:g} Hz and accelerometer at "
                f"{cfg.odr_xl_hz:g} Hz: FIFO streaming needs one ODR for both, because a "
                "Batch carries the six channels on one sample index (the slower sensor "
                "would be decimated in the FIFO pattern, §9.4, and its missing samples "
                "could only be filled by repeats); set accel_odr_hz equal to odr_hz, or "
                "decimate the faster sensor afterwards"
            )
        self.cfg, self.ts_decimation = self._plan(cfg)
        self.odr_hz = self.cfg.odr_hz
        slot_words = 6
        self.pattern_slots = self.ts_decimation or 1
        self.pattern_words = self.pattern_slots * slot_words + (3 if self.ts_decimation else 0)
        wm_slots = max(1, round(watermark_s * self.odr_hz))
        wm_words = min(wm_slots * slot_words, int(max_fill * FIFO_DEPTH_WORDS))
        wm_patterns = max(1, wm_words // self.pattern_words)
        self.watermark_words = wm_patterns * self.pattern_words
        self._layout()
        self.counters: dict[str, int] = {
            "samples": 0,
            "gaps": 0,
            "lost_samples": 0,
            "overruns": 0,
            "chip_resets": 0,
            "realigns": 0,
            "overwrites": 0,
            "resyncs": 0,
            "fifo_bytes": 0,
        }
        self._carry: np.ndarray | None = None
        """Words of a pattern cut by the end of the previous burst (its first words)."""
        self.started = False
        self._next_index: int | None = None  # index of the next slot expected
        self._last_ticks: int | None = None  # unwrapped ticks of the last pattern start
        self._last_raw_ticks = 0
        self._epoch_t_ref = 0.0
        self._tick_s_est = TICK_S
        self._drift_cur: tuple[float, float] | None = None  # this epoch: (host s, ticks)
        self._drift_sum: tuple[float, float] = (0.0, 0.0)  # finished epochs, summed
        self._last_sample_host_t: float | None = None
        self._stamped: tuple[int, float] | None = None  # (index, time stamp) of the last sample
        self._pending_gap_reason: str | None = None
        self._last_verify_t = 0.0
        self._last_data_t = 0.0
        self._t_read_end = 0.0

    # ---------------------------------------------------------------- planning
    def _plan(self, cfg: ImuConfig) -> tuple[ImuConfig, int | None]:
        if not cfg.timestamp:
            ts_choices: list[int | None] = [None]
        else:
            ts_choices = [8, 16, 32]
        if self.bus_hz is None:
            return cfg, (
                ts_choices[0] if ts_choices[0] is None or cfg.odr_hz <= 1660 else ts_choices[-1]
            )
        limit = self.bus_hz / BITS_PER_BYTE * BUDGET_FRACTION
        for d in ts_choices:
            if bus_need_bytes_per_s(cfg.odr_hz, d) <= limit:
                return cfg, d
        need = bus_need_bytes_per_s(cfg.odr_hz, ts_choices[-1])
        fitting = [
            f
            for f in sorted(ODR_HZ.values())
            if f > 2 and f <= cfg.odr_hz and bus_need_bytes_per_s(f, ts_choices[-1]) <= limit
        ]
        best = fitting[-1] if fitting else None
        msg = (
            f"{self.dev.chip} at {cfg.odr_hz:g} Hz (gyro + accel, 12 bytes per sample set"
            f"{' + timestamp' if cfg.timestamp else ''}) needs {need:,.0f} B/s of FIFO data "
            f"but a {self.bus_hz / 1e3:g} kHz I2C bus carries at most "
            f"{self.bus_hz / BITS_PER_BYTE:,.0f} B/s (9 bit-times per byte; plan limit "
            f"{BUDGET_FRACTION:.0%}): the highest ODR that fits is "
            f"{best:g} Hz"
            if best
            else "no ODR fits"
        )
        if self.on_overbudget == "refuse" or best is None:
            raise BusBudgetError(
                msg + "; lower odr_hz, raise the bus speed, or set on_overbudget=degrade"
            )
        self.degraded_from_hz = cfg.odr_hz
        # both sensors move: the constructor only admits accel_odr_hz equal to odr_hz
        new = ImuConfig(**{**cfg.__dict__, "odr_hz": best, "accel_odr_hz": None})
        return self._plan(new)

    def _layout(self) -> None:
        d = self.pattern_slots
        gyro = np.empty((d, 3), dtype=np.int64)
        accel = np.empty((d, 3), dtype=np.int64)
        offset = 0
        for s in range(d):
            gyro[s] = offset + np.arange(3)
            accel[s] = offset + 3 + np.arange(3)
            offset += 6
            if s == 0 and self.ts_decimation:
                self._ts_offset = offset
                offset += 3
        # columns of one pattern's words holding gx gy gz ax ay az of slot 0, 1, ...
        self._body_cols = np.concatenate([gyro, accel], axis=1).reshape(-1)
        self.ticks_per_slot = 1.0 / (self.odr_hz * TICK_S)

    @property
    def bytes_per_s(self) -> float:
        return bus_need_bytes_per_s(self.odr_hz, self.ts_decimation)

    # ---------------------------------------------------------------- control
    def fifo_writes(self) -> list[tuple[int, int]]:
        """The exact (register, value) writes of the FIFO set-up, before the timestamp
        reset and the switch to continuous mode."""
        m = self.dev.map
        fth = self.watermark_words
        fth_h_mask = m.field("FTH_H").mask
        ctrl2 = (fth >> 8) & fth_h_mask
        if self.ts_decimation:
            ctrl2 |= m.field("TIMER_PEDO_FIFO_EN").mask
        ds4 = ds4_decimation_code(self.ts_decimation) if self.ts_decimation else 0
        return [
            (m.addr("FIFO_CTRL5"), FIFO_MODES["bypass"]),  # flush (§9.3)
            (m.addr("FIFO_CTRL1"), fth & 0xFF),
            (m.addr("FIFO_CTRL2"), ctrl2),
            (m.addr("FIFO_CTRL3"), (1 << 3) | 1),  # gyro and accel, no decimation (§9.4)
            (m.addr("FIFO_CTRL4"), ds4 << 3),
        ]

    def continuous_value(self) -> int:
        code = self.dev.map.odr_code(self.odr_hz, "fifo")
        return (code << 3) | FIFO_MODES["continuous"]

    def start(self, *, reset: bool = True) -> None:
        """Probe, (reset,) configure and start the FIFO in continuous mode."""
        self.dev.probe()
        if reset:
            self.dev.reset()
        self.dev.configure(self.cfg)
        self._start_fifo(new_epoch=True)
        self.started = True

    def _start_fifo(self, new_epoch: bool) -> None:
        for reg, value in self.fifo_writes():
            self.dev.write_reg(reg, value)
        if new_epoch and self.ts_decimation:
            self._epoch_t_ref = self.dev.reset_timestamp()
            self._last_ticks = None
            if self._drift_cur is not None:  # bank the finished epoch's baseline
                self._drift_sum = (
                    self._drift_sum[0] + self._drift_cur[0],
                    self._drift_sum[1] + self._drift_cur[1],
                )
                self._drift_cur = None
        self.dev.write_reg("FIFO_CTRL5", self.continuous_value())
        now = self.dev.monotonic()
        self._last_verify_t = now
        self._last_data_t = now

    def _restart_fifo(self) -> None:
        d = self.dev
        d.write_reg("FIFO_CTRL5", FIFO_MODES["bypass"])
        d.write_reg("FIFO_CTRL5", self.continuous_value())
        self._last_data_t = d.monotonic()

    def _recover_chip_reset(self) -> None:
        """Re-probe, reconfigure and restart after a chip reset. A transfer that fails on
        the way raises :class:`DriverIOError` (retried by the reader: the next poll finds
        the configuration still lost and starts again), not the probe's
        :class:`ProbeError`, which reads as the wrong device and ended the stream."""
        self._pending_gap_reason = "chip reset"
        try:
            self.dev.probe()
        except ProbeError as exc:
            if isinstance(exc.__cause__, DriverIOError):
                raise exc.__cause__ from None
            raise
        self.dev.configure(self.cfg)
        self._start_fifo(new_epoch=True)
        self.counters["chip_resets"] += 1

    def stop(self) -> None:
        if self.started:
            with contextlib.suppress(LSM6DSError):
                self.dev.write_reg("FIFO_CTRL5", FIFO_MODES["bypass"])
            self.started = False

    def verify_soon(self) -> None:
        """Read the configuration back at the next poll (after an I/O error: a chip that
        reset under a failing bus is found at once)."""
        self._last_verify_t = -float("inf")

    @property
    def words_per_s(self) -> float:
        return self.odr_hz * self.pattern_words / self.pattern_slots

    @property
    def capacity_samples(self) -> int:
        """Samples the FIFO holds when full: a sample made longer ago than this many
        periods and not read is overwritten (continuous mode, §9.3)."""
        return FIFO_DEPTH_WORDS * self.pattern_slots // self.pattern_words

    @property
    def pending_reason(self) -> str | None:
        """Why the next hole will have been lost, when the stream already knows (a chip
        reset recovered, an overrun seen), else None."""
        return self._pending_gap_reason

    def time_to_watermark_s(self, level_words: int) -> float:
        """Host seconds until the FIFO holds the watermark, from ``level_words`` now."""
        return max(0.0, (self.watermark_words - level_words) / self.words_per_s)

    # ---------------------------------------------------------------- polling
    def _status(self) -> tuple[int, bool, int]:
        """FIFO_STATUS1-4 in one transfer: (level in words, OVER_RUN, pattern position)."""
        dev = self.dev
        status = dev.read_block("FIFO_STATUS1", 4)
        level = (status[0] | (status[1] << 8)) & ((1 << dev.map.fifo_diff_bits) - 1)
        if status[1] & 0x10:  # FIFO_EMPTY
            level = 0
        return level, bool(status[1] & 0x40), status[2] | ((status[3] & 0x03) << 8)

    def poll(self) -> tuple[StreamChunk | None, int]:
        """One status read, one burst of whole patterns (if there are any), one status
        read to check the burst's alignment.

        Returns (chunk or None, FIFO level in words left after the read).
        """
        if not self.started:
            raise LSM6DSError("FifoStream.poll before start()")
        dev = self.dev
        now = dev.monotonic()
        verify_every = max(self.verify_every_s, 2.0 * self.time_to_watermark_s(0))
        if now - self._last_verify_t >= verify_every:
            self._last_verify_t = now
            if not dev.config_intact():
                self._recover_chip_reset()
                return None, 0
            if self.ts_decimation:
                self._measure_drift()
        t_before = dev.monotonic()  # the level is sampled after this, before t_status
        level, overrun, pattern_pos = self._status()
        t_status = dev.monotonic()
        P = self.pattern_words
        if overrun:  # §9.3: the oldest data sets were overwritten; the rest is valid
            self.counters["overruns"] += 1
            self._pending_gap_reason = "fifo overrun"
            self._carry = None
        if level == 0:
            # a running FIFO holds a pattern within two pattern periods of the last read:
            # an empty one after that means the chip reset (its FIFO went to bypass)
            due = 2.0 * self.pattern_slots / self.odr_hz + 0.05
            if t_status - self._last_data_t > due and not dev.config_intact():
                self._recover_chip_reset()
            return None, 0
        head = 0  # words completing the pattern the previous burst cut
        if pattern_pos != 0:
            carry = self._carry
            if carry is not None and len(carry) == pattern_pos:
                head = P - pattern_pos
                if head > level:
                    return None, level
            else:  # realign to the pattern start (§9.4), losing the cut pattern
                self._carry = None
                skip = P - pattern_pos
                if skip > level:
                    return None, level
                dev.read_block("FIFO_DATA_OUT_L", 2 * skip)
                self.counters["realigns"] += 1
                self._pending_gap_reason = self._pending_gap_reason or "fifo realign"
                level -= skip
        elif self._carry is not None:  # the cut pattern was overwritten meanwhile
            self._carry = None
        n_patterns = min(
            (level - head) // P, (MAX_BURST_BYTES // 2 - head) // P
        )
        if n_patterns == 0 and head == 0:
            return None, level
        n_words = head + n_patterns * P
        data = dev.read_block("FIFO_DATA_OUT_L", 2 * n_words)
        level_after, _, pos_after = self._status()
        t_after = dev.monotonic()
        temp_c = dev.read_temperature_c()
        self._last_data_t = t_status
        self.counters["fifo_bytes"] += 2 * n_words
        burst = np.frombuffer(data, dtype="<i2")
        # words the FIFO dropped between the two status reads: what was there, plus what
        # arrived, minus what was read and what is left (host timing error allowed for)
        arrived = (t_after - t_before) * self.words_per_s
        discarded = level + arrived - n_words - level_after
        slack = P + 0.02 * arrived + HOST_JITTER_S * self.words_per_s
        if pos_after == 0 and discarded <= slack:
            words = burst if head == 0 else np.concatenate([self._carry, burst])
            self._carry = None
        elif pos_after == 0:
            # whole patterns were overwritten before the burst: it is aligned, but the words
            # that were to complete the cut pattern now belong to a later one
            self.counters["overwrites"] += 1
            self._pending_gap_reason = "fifo overrun"
            words = burst[head:]
            self._carry = None
        else:
            # the FIFO overwrote data sets between the status and the data read: the burst
            # began at pattern position (pos_after - n_words) mod P, not at a pattern start
            self.counters["overwrites"] += 1
            self._pending_gap_reason = "fifo overrun"
            start = (pos_after - n_words) % P
            first = (P - start) % P
            whole = (n_words - first) // P
            words = burst[first : first + whole * P]
            tail = burst[first + whole * P :]
            self._carry = tail.copy() if len(tail) == pos_after else None
        if not len(words):
            return None, level_after
        words = words.reshape(-1, P)
        # slots produced after the newest one read, up to the second status read
        newest_lag = level_after * self.pattern_slots / P + 0.5
        chunk = self._decode(words, t_after - newest_lag / self.odr_hz, temp_c, t_after)
        if chunk is None:  # timestamps inconsistent: discard, restart the FIFO
            self.counters["resyncs"] += 1
            self._pending_gap_reason = "fifo resync"
            self._carry = None
            self._restart_fifo()
            return None, 0
        # words that arrived since the second status read count too (else the next sleep
        # overshoots and, near the bus limit, the FIFO overruns)
        since = (dev.monotonic() - t_after) * self.words_per_s
        return chunk, level_after + int(since)

    def _decode(
        self, words: np.ndarray, t_newest: float, temp_c: float, t_read: float
    ) -> StreamChunk | None:
        """Indices, raw counts and host times of whole patterns; None when the
        timestamps show the words cannot be these patterns (see :meth:`_ticks_plausible`)."""
        n_pat, d = len(words), self.pattern_slots
        raw = np.take(words, self._body_cols, axis=1).reshape(n_pat * d, 6)
        gaps: list[tuple[int, int, str]] = []
        if self.ts_decimation:
            ts_w = words[:, self._ts_offset : self._ts_offset + 2].astype(np.int64) & 0xFFFF
            raw_ticks = ((ts_w[:, 0] & 0xFF) << 8) | ((ts_w[:, 0] >> 8) << 16) | (ts_w[:, 1] >> 8)
            found = self._pattern_start_slots(raw_ticks, gaps, t_read)
            if found is None:
                return None
            start_slots, ticks = found
        else:
            start_slots = self._pattern_start_slots_host(n_pat, t_newest, gaps)
        index = (start_slots[:, None] + np.arange(d)).reshape(-1)
        self._next_index = int(index[-1]) + 1
        if self.ts_decimation:
            # pattern-start ticks are measured; the other slots at nominal spacing
            slot_ticks = ticks[:, None] + np.arange(d) * self.ticks_per_slot
            t_s = self._epoch_t_ref + slot_ticks.reshape(-1) * self._tick_s_est
        else:
            t_s = t_newest + (index - index[-1]) / self.odr_hz
        self._last_sample_host_t = float(t_s[-1])
        t_s = self._slewed(np.asarray(t_s, dtype=np.float64), index)
        n_lost = sum(g[1] for g in gaps)
        self.counters["samples"] += len(index)
        self.counters["gaps"] += len(gaps)
        self.counters["lost_samples"] += n_lost
        return StreamChunk(
            index=index.astype(np.int64), raw=raw, t_s=np.asarray(t_s), temp_c=temp_c, gaps=gaps
        )

    def _slewed(self, t_s: np.ndarray, index: np.ndarray) -> np.ndarray:
        """The clock model's times ``t_s`` of the samples ``index``, joined to the stamps
        already given without a step back.

        The model is the epoch origin plus ticks times the tick period's estimate (or,
        without the timestamp, the host's read time); each refinement of the estimate
        moves every later time, by 37 ms after the first second of a crystal 3.75 % fast,
        and a host read time by its jitter. Taken as it comes, that made the stamps run
        backwards (by 26.7 ms at 104 Hz, and by 6 periods after bus NACKs). Here the
        offset between where the last stamp was and where the model now puts it decays
        by :data:`SLEW_PER_SAMPLE` periods per sample: the stamps stay strictly
        increasing and rejoin the model."""
        if self._stamped is None:
            self._stamped = int(index[-1]), float(t_s[-1])
            return t_s
        last_index, last_t = self._stamped
        period = 1.0 / (self.measured_odr_hz if self.ts_decimation else self.odr_hz)
        offset = last_t - (float(t_s[0]) - (int(index[0]) - last_index) * period)
        if offset != 0.0:
            since = (index - last_index).astype(np.float64)
            left = np.maximum(abs(offset) - SLEW_PER_SAMPLE * period * since, 0.0)
            t_s = t_s + math.copysign(1.0, offset) * left
        self._stamped = int(index[-1]), float(t_s[-1])
        return t_s

    def _measure_drift(self) -> None:
        """Estimate the sensor clock against the host clock: read the timestamp counter
        (TIMESTAMP0-2, §7-8) at a known host time (the transfer's midpoint) and compare
        with the epoch origin (host time of the 0xAA counter reset, tick 0). The tick
        period is total host seconds / total ticks over every epoch's baseline, so after
        a second of data the error is ~(25 us + transfer jitter) / baseline; a crystal
        running 3.75 % fast (107.9 Hz for 104) is then known to ~1e-5.
        """
        t0 = self.dev.monotonic()
        raw = self.dev.read_timestamp_ticks()
        t_read = 0.5 * (t0 + self.dev.monotonic())
        prev_ticks = self._drift_cur[1] if self._drift_cur is not None else 0.0
        # the epoch's tick count is congruent to the raw 24-bit counter (both start at 0)
        ticks = prev_ticks + ((raw - int(prev_ticks) % TICKS_WRAP) % TICKS_WRAP)
        span_t = t_read - self._epoch_t_ref
        measured = self._tick_s_est != TICK_S
        ref, tol = (self._tick_s_est, DRIFT_JUMP) if measured else (TICK_S, CLOCK_TOLERANCE)
        if span_t <= 0 or ticks <= 0 or abs(span_t / (ticks * ref) - 1.0) > tol:
            return  # counter reset under us (a chip reset the next poll will see)
        self._drift_cur = (span_t, float(ticks))
        tot_t, tot_k = self._drift_sum[0] + span_t, self._drift_sum[1] + ticks
        if tot_k * TICK_S >= 0.5:
            est = tot_t / tot_k
            if abs(est / TICK_S - 1.0) < CLOCK_TOLERANCE:
                self._tick_s_est = est

    @property
    def measured_odr_hz(self) -> float:
        """The output data rate measured against the host clock, Hz (the nominal ODR
        until the first drift measurement; needs the timestamp, ``timestamp=True``)."""
        return 1.0 / (self.ticks_per_slot * self._tick_s_est)

    def _ticks_plausible(self, raw_ticks: np.ndarray, t_read: float) -> np.ndarray | None:
        """Unwrapped ticks of each pattern start, or None if they cannot be real.

        Within one burst the patterns are consecutive FIFO content, so successive
        timestamps are one pattern apart (``d * ticks_per_slot``, within 2 % for the
        rounding of the 25 us counter). The first pattern after the previous poll's last
        one lies at least one pattern later and no later than the host time that has
        passed since that sample (+ 50 ms + 2 %); the number of 2^24 wraps in between is
        taken from that host time, so a stall longer than the counter's 419 s period is
        sized right. Words decoded out of alignment give timestamps that fail this.
        """
        pattern_ticks = self.pattern_slots * self.ticks_per_slot
        inner = np.diff(raw_ticks) % TICKS_WRAP
        if len(inner) and np.any(np.abs(inner - pattern_ticks) > 0.02 * pattern_ticks + 2):
            return None
        if self._last_ticks is None:  # new epoch: pattern 0 ticks = its raw value
            first = int(raw_ticks[0])
        else:
            step = (int(raw_ticks[0]) - self._last_raw_ticks) % TICKS_WRAP
            assert self._last_sample_host_t is not None
            host_ticks = (t_read - self._last_sample_host_t) / self._tick_s_est
            wraps = max(0, round((host_ticks - step) / TICKS_WRAP))
            step += wraps * TICKS_WRAP
            last_slot_ticks = (self.pattern_slots - 1) * self.ticks_per_slot
            earliest = pattern_ticks - 0.02 * pattern_ticks - 2
            latest = last_slot_ticks + host_ticks * 1.02 + 0.05 / self._tick_s_est
            if not earliest <= step <= latest:
                return None
            first = self._last_ticks + step
        return first + np.concatenate([[0], np.cumsum(inner)]).astype(np.int64)

    def _pattern_start_slots(
        self, raw_ticks: np.ndarray, gaps: list[tuple[int, int, str]], t_read: float
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Slot index and unwrapped ticks of each pattern start (timestamps mod 2^24);
        None when the timestamps are not plausible (:meth:`_ticks_plausible`)."""
        d = self.pattern_slots
        ticks = self._ticks_plausible(raw_ticks, t_read)
        if ticks is None:
            return None
        slots_rel = np.rint((ticks - ticks[0]) / self.ticks_per_slot).astype(np.int64)
        if self._next_index is None:
            first = 0
        elif self._last_ticks is not None:
            first = (
                self._next_index
                - d
                + round((int(ticks[0]) - self._last_ticks) / self.ticks_per_slot)
            )
        else:  # new epoch after a chip reset: size the gap from host time
            t_first = self._epoch_t_ref + int(ticks[0]) * self._tick_s_est
            assert self._last_sample_host_t is not None
            period = self.ticks_per_slot * self._tick_s_est
            first = max(
                self._next_index,
                self._next_index - 1 + round((t_first - self._last_sample_host_t) / period),
            )
        starts = first + slots_rel
        self._last_ticks = int(ticks[-1])
        self._last_raw_ticks = int(raw_ticks[-1])
        self._record_gaps(starts, d, gaps)
        return starts, ticks

    def _pattern_start_slots_host(
        self, n_pat: int, t_newest: float, gaps: list[tuple[int, int, str]]
    ) -> np.ndarray:
        d = self.pattern_slots
        if self._next_index is None:
            first = 0
        elif self._pending_gap_reason is None:
            first = self._next_index
        else:  # restart without timestamps: size the gap from host time (±1 sample)
            assert self._last_sample_host_t is not None
            t_first = t_newest - (n_pat * d - 1) / self.odr_hz
            first = max(
                self._next_index,
                self._next_index - 1 + round((t_first - self._last_sample_host_t) * self.odr_hz),
            )
        starts = first + d * np.arange(n_pat, dtype=np.int64)
        self._record_gaps(starts, d, gaps)
        return starts

    def _record_gaps(self, starts: np.ndarray, d: int, gaps: list[tuple[int, int, str]]) -> None:
        expected = np.concatenate(
            [
                [self._next_index if self._next_index is not None else int(starts[0])],
                starts[:-1] + d,
            ]
        )
        jumps = starts - expected
        # a continuous FIFO loses samples only by overwriting its oldest data sets (§9.3)
        reason = self._pending_gap_reason or "fifo overrun"
        for k in np.nonzero(jumps > 0)[0]:
            gaps.append((int(starts[k]), int(jumps[k]), reason))
        self._pending_gap_reason = None


__all__ = ["BusBudgetError", "DriverIOError", "FifoStream", "StreamChunk"]
