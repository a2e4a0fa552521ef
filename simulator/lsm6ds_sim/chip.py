"""Register-level model of the LSM6DS3H, LSM6DSM and LSM6DSL (reference ``lsm6ds-registers.md``).

A :class:`SimChip` is a device on :class:`lsm6ds_sim.i2c.SimI2CBus`: the bus calls
:meth:`SimChip.read` and :meth:`SimChip.write` for each transaction. Before serving an
access the chip catches up with the simulated clock: it produces every sample due since
its last access, in vectorised blocks (physics, self-test deflection, quantisation and
saturation, output registers, FIFO words), so a driver reading the FIFO once every few
seconds of virtual time costs a handful of numpy calls.

Sample timing. The chip runs off one oscillator whose frequency error is ``crystal_ppm``
(an LSM6DSM measured at 107.9 Hz for 104 Hz nominal is +37 500 ppm). Output sample ``k``
of the fastest enabled sensor (the *base* ODR ``f``) is produced at ``k / (f (1 + ppm))``
seconds; the grid is free-running (it survives reconfiguration and resets, as the chip's
oscillator does). FIFO slot ``j`` at FIFO ODR ``f_fifo`` is written at
``j / (f_fifo (1 + ppm))`` with the latest sample of each sensor; the timestamp counter
ticks at 40 kHz (1 + ppm) (25 us, or 6.4 ms with TIMER_HR = 0, §7-8).

What is modelled (reference section in brackets): register file with per-chip reset
values and writable bits, reserved bits read 0 [§2, §3, §3.13]; WHO_AM_I [§1]; SW_RESET
(restores reset values, bit reads 1 for 50 us) and BOOT (bit reads 1 for 15 ms) [§1,
§3.3]; IF_INC auto-increment and ROUNDING wrap [§3.3, §3.5, §5]; BDU latching of L/H
pairs [§3.3, §13]; ODR, full scale (sensitivities), power modes [§3.1-3.2, §4]; STATUS_REG
XLDA/GDA/TDA set on new data and cleared by reading the outputs [§3.12]; temperature with
each chip's scale [§6]; timestamp (enable per chip, both resolutions, 0xAA reset, FIFO
byte order) [§7-8]; FIFO modes, FIFO ODR, decimation, pattern order gyro-accel-DS3-DS4,
threshold, overrun, FIFO_STATUS1-4, FIFO_DATA_OUT wrap [§9]; self-test (CTRL5_C) [§3.5];
the chip differences of [§10] through :mod:`lsm6ds.registers`.

Defects for test jigs (``sim_`` controls): a stuck output axis (:meth:`SimChip.sim_stick_axis`),
a FIFO that loses whole patterns (:meth:`SimChip.sim_set_fifo_drop_rate`), self-test
deflections out of limits (:attr:`SimChip.sim_self_test_gyro_lsb`,
:attr:`SimChip.sim_self_test_accel_g`).

Not modelled: interrupts pins, embedded functions (pedometer, tilt, tap), sensor hub
(DS3 words read 0), OIS/aux SPI, user offsets, filters other than what the physics
applies, ONLY_HIGH_DATA.

Test-only controls carry a ``sim_`` prefix.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any, Protocol

import numpy as np
from lsm6ds.registers import (
    ACCEL_FS,
    DECIMATION,
    GYRO_FS,
    ODR_HZ,
    ChipMap,
    chip_map,
)

from lsm6ds_sim.clock import SimClock
from lsm6ds_sim.fifo import Fifo

TIMESTAMP_HZ = 40_000.0
"""Timestamp tick rate at TIMER_HR = 1 (25 us/LSB, §7-8)."""

SW_RESET_BUSY_S = 50e-6
BOOT_BUSY_S = 15e-3
MAX_BLOCK = 65_536
"""Samples generated per physics call at most (bounds memory on long sleeps)."""

_OUT_FIRST = 0x20
_OUT_LAST = 0x2D
_FIFO_L = 0x3E
_FIFO_H = 0x3F


class Physics(Protocol):
    """What the chip needs from :class:`lsm6ds_sim.physics.SensorPhysics`."""

    def generate(self, n: int, dt_s: float) -> Any: ...


def default_physics(seed: int = 0) -> Physics:
    """The sensor physics of a chip built without one: ``SensorPhysics(seed=seed)``, a
    quiet sensor (no model: no noise) at rest, gravity on +z."""
    from lsm6ds_sim.physics import SensorPhysics  # physics imports the model, not the chip

    return SensorPhysics(seed=seed)


@dataclass
class _Config:
    """Sample-production settings decoded from the registers."""

    odr_g: float = 0.0
    odr_xl: float = 0.0
    base: float = 0.0
    gyro_sens: float = GYRO_FS[0][1]
    accel_sens: float = ACCEL_FS[0][1]
    st_g: int = 0  # -1, 0, +1
    st_xl: int = 0
    fifo_odr: float = 0.0
    dec: tuple[int, int, int, int] = (0, 0, 0, 0)  # gyro, accel, ds3, ds4 factors
    ds4_timestamp: bool = False
    ds4_temp: bool = False
    timer_en: bool = False
    timer_hr: bool = False
    pattern_slots: int = 1
    slot_offset: np.ndarray = field(default_factory=lambda: np.zeros(1, dtype=np.int64))
    pattern_words: int = 0
    word_cols: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    """Columns of a (patterns, slots x 12) word table that the FIFO holds, in order."""
    bdu: bool = False
    fifo_ratio: Fraction = Fraction(1)  # f_fifo / f_base, exact


class SimChip:
    """One simulated LSM6DS3H / LSM6DSM / LSM6DSL.

    Args:
        chip: ``lsm6ds3h``, ``lsm6dsm`` or ``lsm6dsl``.
        clock: the shared simulated clock.
        physics: what the sensing element outputs (``generate(n, dt_s)``); default
            :func:`default_physics`.
        crystal_ppm: oscillator frequency error, ppm (actual ODR = nominal (1 + ppm 1e-6)).
        sim_counting: test signal: raw gyro X of base sample ``k`` is ``k mod 2^16`` (as
            int16), so a test can check every delivered sample's identity.
    """

    def __init__(
        self,
        chip: str = "lsm6dsl",
        clock: SimClock | None = None,
        physics: Physics | None = None,
        *,
        crystal_ppm: float = 0.0,
        seed: int = 0,
        sim_counting: bool = False,
    ) -> None:
        self.map: ChipMap = chip_map(chip)
        self.name = self.map.name
        self.clock = clock if clock is not None else SimClock()
        self.physics: Physics = physics if physics is not None else default_physics(seed)
        self.crystal_ppm = float(crystal_ppm)
        self.fifo = Fifo()
        self.sim_counting = sim_counting
        self.sim_stuck_output = False
        self.sim_self_test_gyro_lsb = np.array([5700.0, 5700.0, 5700.0])
        """Gyro self-test deflection, LSB (5700 LSB = 50 dps at 250 dps, 399 dps at 2000)."""
        self.sim_self_test_accel_g = np.array([0.5, 0.5, 0.5])
        """Accelerometer self-test deflection, g (datasheet range 0.09-1.7 g)."""
        self.sim_stuck_axes: dict[int, int | None] = {}
        """Defect: output column (1..6 for gx gy gz ax ay az) -> the raw count it is stuck
        at (None until the next sample fixes it); see :meth:`sim_stick_axis`."""
        self.sim_fifo_drop_rate = 0.0
        """Defect: probability that the FIFO loses each whole pattern it should store."""
        self._drop_rng = np.random.default_rng(seed)
        self.sim_stats: dict[str, int] = {
            "reserved_writes": 0,
            "readonly_writes": 0,
            "undefined_accesses": 0,
            "resets": 0,
            "samples": 0,
            "fifo_underflow_words": 0,
            "fifo_dropped_patterns": 0,
        }
        self.sim_reserved_log: list[tuple[int, int]] = []
        self._temp_glitches: list[tuple[int, int, float]] = []
        """Pending glitches: (first base sample, last base sample, degC)."""
        self._a = {name: reg.address for name, reg in self.map.registers.items()}
        self._power_on()

    # ---------------------------------------------------------------- state / reset
    @property
    def _f_scale(self) -> float:
        return 1.0 + self.crystal_ppm * 1e-6

    def sim_sample_period_s(self, base_odr_hz: float) -> float:
        """Seconds between the samples this chip produces at a base ODR of
        ``base_odr_hz`` (its oscillator runs ``crystal_ppm`` fast)."""
        return 1.0 / (base_odr_hz * self._f_scale)

    def _power_on(self) -> None:
        now = self.clock.now()
        self.regs = bytearray(128)
        for addr, value in self.map.reset_values.items():
            self.regs[addr] = value
        self._out = bytearray(14)
        self._held = np.zeros(7, dtype=np.int64)  # temp, gx gy gz, ax ay az
        self._status = 0
        self._bdu_locked: set[int] = set()
        self._half: int | None = None
        self.fifo.set_mode(0)
        self.fifo.threshold_words = 0
        self._t_done = now
        self._sw_reset_until = -math.inf
        self._boot_until = -math.inf
        self._ts_origin = self._ticks_at(now)
        self._cfg = _Config()
        self._k_last = 0
        self._j_last = 0
        self._slot0 = 0
        self._reconfigure(now)

    def _ticks_at(self, t_s: float) -> int:
        return math.floor(t_s * TIMESTAMP_HZ * self._f_scale)

    def sim_reset(self) -> None:
        """Spontaneous reset: registers back to reset values, FIFO and outputs cleared."""
        self.sim_advance_to(self.clock.now())
        self.sim_stats["resets"] += 1
        self._power_on()

    def sim_force_overrun(self) -> None:
        """Lose the FIFO's content as an overrun would, setting OVER_RUN."""
        self.fifo.drop_all()

    def sim_temp_glitch(
        self, delta_c: float, duration_s: float = 0.0, at_s: float | None = None
    ) -> None:
        """Temperature glitch: add ``delta_c`` (degC) to the temperature output of the
        samples produced from ``at_s`` (default now) for ``duration_s`` seconds (at least
        the next sample)."""
        t0 = self.clock.now() if at_s is None else at_s
        self.sim_advance_to(t0)
        k0 = self._k_last + 1
        f = self._cfg.base * self._f_scale
        k1 = max(k0, math.floor((t0 + duration_s) * f)) if f else k0
        self._temp_glitches.append((k0, k1, float(delta_c)))

    def sim_stick_axis(self, channel: str, counts: int | None = None) -> None:
        """Defect: one output axis (``gx`` .. ``az``) stuck at ``counts`` (raw int16), or at
        the value of the next sample it produces when None: registers and FIFO then
        repeat that value whatever the input, self-test included."""
        names = ("gx", "gy", "gz", "ax", "ay", "az")
        if channel not in names:
            raise ValueError(f"sim_stick_axis: channel {channel!r} must be one of {names}")
        if counts is not None and not -32768 <= counts <= 32767:
            raise ValueError(f"sim_stick_axis: counts={counts} is not an int16")
        self.sim_stuck_axes[1 + names.index(channel)] = counts

    def sim_set_fifo_drop_rate(self, rate: float, seed: int = 0) -> None:
        """Defect: the FIFO loses each whole pattern it should store (data sets and
        timestamp of one pattern) with probability ``rate``, drawn from ``seed``. The
        timestamps of the patterns kept show the hole (the driver sizes the gap)."""
        if not 0.0 <= rate <= 1.0:
            raise ValueError(f"sim_set_fifo_drop_rate: rate={rate} must be in [0, 1]")
        self.sim_fifo_drop_rate = float(rate)
        self._drop_rng = np.random.default_rng(seed)

    def sim_trigger_fifo(self) -> None:
        """The trigger event of the continuous-to-FIFO and bypass-to-continuous modes."""
        self.fifo.trigger()

    def sim_advance_to(self, t_s: float) -> None:
        """Produce every sample due up to time ``t_s``."""
        self._advance(t_s)

    # ---------------------------------------------------------------- configuration
    def _bits(self, field_name: str) -> int:
        reg, mask = self.map.field_addr_mask(field_name)
        return (self.regs[reg] & mask) >> ((mask & -mask).bit_length() - 1)

    def _reconfigure(self, now: float) -> None:
        old = self._cfg
        c = _Config()
        odr_g_code = self._bits("ODR_G")
        odr_xl_code = self._bits("ODR_XL")
        c.odr_g = ODR_HZ.get(odr_g_code, 0.0) if odr_g_code in self.map.gyro_odr_codes else 0.0
        c.odr_xl = ODR_HZ.get(odr_xl_code, 0.0) if odr_xl_code in self.map.accel_odr_codes else 0.0
        c.base = max(c.odr_g, c.odr_xl)
        c.gyro_sens = GYRO_FS.get(self._bits("FS_G"), GYRO_FS[0])[1]
        c.accel_sens = ACCEL_FS[self._bits("FS_XL")][1]
        st_g = self._bits("ST_G")
        st_xl = self._bits("ST_XL")
        c.st_g = {0: 0, 1: 1, 3: -1}.get(st_g, 0)
        c.st_xl = {0: 0, 1: 1, 2: -1}.get(st_xl, 0)
        fifo_code = self._bits("ODR_FIFO")
        c.fifo_odr = ODR_HZ.get(fifo_code, 0.0) if fifo_code <= 10 else 0.0
        c.ds4_timestamp = bool(self._bits("TIMER_PEDO_FIFO_EN"))
        c.ds4_temp = bool(self._bits("FIFO_TEMP_EN")) and not c.ds4_timestamp
        c.dec = (
            DECIMATION[self._bits("DEC_FIFO_GYRO")],
            DECIMATION[self._bits("DEC_FIFO_XL")],
            DECIMATION[self._bits("DEC_DS3_FIFO")],
            DECIMATION[self._bits("DEC_DS4_FIFO")] if (c.ds4_timestamp or c.ds4_temp) else 0,
        )
        c.timer_en = bool(self._bits("TIMER_EN"))
        c.timer_hr = bool(self._bits("TIMER_HR"))
        c.bdu = bool(self._bits("BDU"))
        self._build_pattern(c)
        if c.base and c.fifo_odr:
            c.fifo_ratio = Fraction(round(c.fifo_odr * 10)) / Fraction(round(c.base * 10))
        # FIFO threshold, 11 or 12 bits (§9.1)
        self.fifo.threshold_words = self.regs[self._a["FIFO_CTRL1"]] | (self._bits("FTH_H") << 8)
        self.fifo.stop_on_fth = bool(self._bits("STOP_ON_FTH"))
        mode = self._bits("FIFO_MODE")
        fifo_restart = (
            mode != self.fifo.mode
            or c.fifo_odr != old.fifo_odr
            or c.dec != old.dec
            or c.base != old.base
        )
        if mode != self.fifo.mode:
            self.fifo.set_mode(mode)
        if c.timer_en and not old.timer_en:
            self._ts_origin = self._ticks_at(now)
        # the free-running grids: last produced sample / slot at or before now
        if c.base != old.base:
            self._k_last = math.floor(now * c.base * self._f_scale) if c.base else 0
        if c.fifo_odr != old.fifo_odr:
            self._j_last = math.floor(now * c.fifo_odr * self._f_scale) if c.fifo_odr else 0
        if fifo_restart:
            self._slot0 = self._j_last + 1
            self.fifo.next_pattern_pos = 0
        self._cfg = c

    @staticmethod
    def _build_pattern(c: _Config) -> None:
        """Pattern layout (§9.4): slot ``s`` holds data set ``i`` (gyro, accel, DS3, DS4)
        when its decimation factor ``d_i`` is non-zero and ``s % d_i == 0``; the pattern
        repeats after lcm(d_i) slots."""
        factors = [d for d in c.dec if d]
        slots = math.lcm(*factors) if factors else 1
        present = np.zeros((slots, 4), dtype=bool)
        for i, d in enumerate(c.dec):
            if d:
                present[::d, i] = True
        counts = present.sum(axis=1)
        slot_offset = np.concatenate([[0], np.cumsum(counts * 3)[:-1]]).astype(np.int64)
        c.pattern_slots = slots
        c.word_cols = np.nonzero(np.repeat(present, 3, axis=1).reshape(-1))[0]
        c.slot_offset = slot_offset
        c.pattern_words = int(counts.sum() * 3)

    # ---------------------------------------------------------------- sample production
    def _advance(self, now: float) -> None:
        if now <= self._t_done:
            return
        c = self._cfg
        self._t_done = now
        if c.base <= 0:
            return
        k_due = math.floor(now * c.base * self._f_scale)
        while self._k_last < k_due:
            n = min(MAX_BLOCK, k_due - self._k_last)
            self._produce(self._k_last + 1, self._k_last + n)
            self._k_last += n

    def _produce(self, k0: int, k1: int) -> None:
        """Produce base samples ``k0..k1`` (inclusive)."""
        c = self._cfg
        n = k1 - k0 + 1
        dt = 1.0 / (c.base * self._f_scale)
        # row 0: the sample before k0 (the FIFO may need it); rows 1..n: k0..k1
        if self.sim_stuck_output:
            rows = np.broadcast_to(self._held, (n + 1, 7)).copy()
        else:
            true = self.physics.generate(n, dt)
            f = np.empty((n + 1, 7))
            f[0] = self._held
            v = f[1:]
            v[:, 0] = true.temp_c
            v[:, 1:4] = true.gyro_dps
            v[:, 4:7] = true.accel_g
            v[:, 0] -= self.map.temp_zero_c
            v[:, 0] *= self.map.temp_lsb_per_c
            if self._temp_glitches:
                self._apply_temp_glitches(v[:, 0], k0, k1)
            v[:, 1:4] *= 1.0 / c.gyro_sens
            if c.st_g:
                v[:, 1:4] += c.st_g * self.sim_self_test_gyro_lsb
            if c.st_xl:
                v[:, 4:7] += c.st_xl * self.sim_self_test_accel_g
            v[:, 4:7] *= 1.0 / c.accel_sens
            np.rint(v, out=v)
            np.maximum(v, -32768.0, out=v)  # saturation at full scale (int16)
            np.minimum(v, 32767.0, out=v)
            rows = f.astype(np.int64)
            if self.sim_counting:
                rows[1:, 1] = (np.arange(k0, k1 + 1) & 0xFFFF).astype(np.uint16).view(np.int16)
            for cols, odr in ((slice(1, 4), c.odr_g), (slice(4, 7), c.odr_xl)):
                ratio = round(c.base / odr) if odr else 0
                if ratio == 1:
                    continue
                # a slower sensor holds its last sample between its own updates
                k = np.arange(k0 - 1, k1 + 1)
                fresh = (k % ratio == 0) if ratio else np.zeros(n + 1, dtype=bool)
                fresh[0] = True
                idx = np.maximum.accumulate(np.where(fresh, np.arange(n + 1), 0))
                rows[:, cols] = rows[idx, cols]
        for col, value in self.sim_stuck_axes.items():
            if value is None:
                value = int(rows[1, col])
                self.sim_stuck_axes[col] = value
            rows[1:, col] = value
        self._held = rows[-1].copy()
        self.sim_stats["samples"] += n
        self._update_outputs(self._held)
        if c.fifo_odr > 0 and self.fifo.accepting:
            self._fill_fifo(k0, k1, rows)

    def _apply_temp_glitches(self, temp_lsb: np.ndarray, k0: int, k1: int) -> None:
        """Add the pending glitches overlapping base samples ``k0..k1`` (in LSB)."""
        keep = []
        for g0, g1, delta_c in self._temp_glitches:
            lo, hi = max(g0, k0), min(g1, k1)
            if lo <= hi:
                temp_lsb[lo - k0 : hi - k0 + 1] += delta_c * self.map.temp_lsb_per_c
            if g1 > k1:
                keep.append((g0, g1, delta_c))
        self._temp_glitches = keep

    def _update_outputs(self, row: np.ndarray) -> None:
        c = self._cfg
        data = row.astype(np.int16).tobytes()  # temp, gx, gy, gz, ax, ay, az (LE)
        if c.bdu and self._bdu_locked:
            for pair in range(7):
                if pair not in self._bdu_locked:
                    self._out[2 * pair : 2 * pair + 2] = data[2 * pair : 2 * pair + 2]
        else:
            self._out[:] = data
        self._status |= 0x04 | (0x02 if c.odr_g else 0) | (0x01 if c.odr_xl else 0)

    def _fill_fifo(self, k0: int, k1: int, src: np.ndarray) -> None:
        """Write FIFO slots due between base samples ``k0 - 1`` (excl.) and ``k1``;
        ``src[0]`` is the sample before ``k0``, ``src[i]`` sample ``k0 - 1 + i``."""
        c = self._cfg
        r = c.fifo_ratio
        j_due = (k1 * r.numerator) // r.denominator
        j_from = max(self._j_last + 1, self._slot0)
        self._j_last = max(self._j_last, j_due)
        if j_due < j_from or c.pattern_words == 0:
            return
        # slots j_from..j_due, laid out on whole patterns: `lead` slots before j_from
        S = c.pattern_slots
        lead = (j_from - self._slot0) % S
        m = j_due - j_from + 1
        n_pat = -(-(lead + m) // S)
        j = np.arange(j_from - lead, j_from - lead + n_pat * S, dtype=np.int64)
        # latest base sample at each slot time
        idx = (j * r.denominator) // r.numerator - (k0 - 1)
        np.maximum(idx, 0, out=idx)
        np.minimum(idx, len(src) - 1, out=idx)
        vals = np.zeros((n_pat * S, 12), dtype=np.uint16)  # gyro, accel, DS3, DS4 words
        vals[:, 0:6] = np.take(src, idx, axis=0)[:, 1:7]  # two's complement wraps
        if c.ds4_timestamp:
            ticks = (j * round(TIMESTAMP_HZ * 10)) // round(c.fifo_odr * 10) - self._ts_origin
            if not c.timer_en:
                ticks[:] = 0
            if not c.timer_hr:
                ticks //= 256
            ticks &= 0xFFFFFF
            vals[:, 9] = ((ticks >> 8) & 0xFF) | (((ticks >> 16) & 0xFF) << 8)
            vals[:, 10] = (ticks & 0xFF) << 8
        elif c.ds4_temp:
            vals[:, 9] = np.take(src[:, 0], idx)
        # pattern order (§9.4): the words present in each slot, slot after slot
        words = np.take(vals.reshape(n_pat, S * 12), c.word_cols, axis=1).reshape(-1)
        first = int(c.slot_offset[lead])
        n_words = (
            ((lead + m) // S) * c.pattern_words
            + int(c.slot_offset[(lead + m) % S])
            - first
        )
        words = words[first : first + n_words]
        pos = ((first + np.arange(n_words)) % c.pattern_words).astype(np.uint16)
        if self.sim_fifo_drop_rate > 0:
            words, pos = self._drop_patterns(words, pos, c.pattern_words)
        self.fifo.push(words.view(np.int16), pos)
        self.fifo.next_pattern_pos = int(c.slot_offset[(j_due + 1 - self._slot0) % S])

    def _drop_patterns(
        self, words: np.ndarray, pos: np.ndarray, pattern_words: int
    ) -> tuple[np.ndarray, np.ndarray]:
        """``words``/``pos`` without the whole patterns the FIFO defect loses (only
        patterns wholly inside this push, so the pattern positions stay aligned)."""
        starts = np.nonzero(pos == 0)[0]
        starts = starts[starts + pattern_words <= len(words)]
        lost = starts[self._drop_rng.random(len(starts)) < self.sim_fifo_drop_rate]
        if not len(lost):
            return words, pos
        keep = np.ones(len(words), dtype=bool)
        for s in lost:
            keep[s : s + pattern_words] = False
        self.sim_stats["fifo_dropped_patterns"] += len(lost)
        return words[keep], pos[keep]

    # ---------------------------------------------------------------- register access
    def _ctrl3(self) -> int:
        now = self.clock.now()
        v = self.regs[self._a["CTRL3_C"]] & ~0x81
        if now < self._sw_reset_until:
            v |= 0x01
        if now < self._boot_until:
            v |= 0x80
        return v

    def _timestamp_now(self) -> int:
        if not self._cfg.timer_en:
            return 0
        ticks = self._ticks_at(self.clock.now()) - self._ts_origin
        if not self._cfg.timer_hr:
            ticks //= 256
        return ticks & 0xFFFFFF

    def _read_byte(self, a: int) -> int:
        if _OUT_FIRST <= a <= _OUT_LAST:
            if a <= 0x21:
                self._status &= ~0x04
            elif a <= 0x27:
                self._status &= ~0x02
            else:
                self._status &= ~0x01
            return self._out[a - _OUT_FIRST]
        if a == 0x1E:
            return self._status
        if a == 0x12:
            return self._ctrl3()
        if a == 0x3A:
            return min(self.fifo.level, (1 << self.map.fifo_diff_bits) - 1) & 0xFF
        if a == 0x3B:
            level = min(self.fifo.level, (1 << self.map.fifo_diff_bits) - 1)
            diff_mask = self.map.field("DIFF_FIFO_H").mask
            flags = (
                (0x80 if self.fifo.watermark() else 0)
                | (0x40 if self.fifo.overrun else 0)
                | (0x20 if self.fifo.full() else 0)
                | (0x10 if self.fifo.level == 0 else 0)
            )
            return flags | ((level >> 8) & diff_mask)
        if a == 0x3C:
            return self.fifo.pattern_position() & 0xFF
        if a == 0x3D:
            return (self.fifo.pattern_position() >> 8) & 0x03
        if 0x40 <= a <= 0x42:
            return (self._timestamp_now() >> (8 * (a - 0x40))) & 0xFF
        if a in self.map.by_address:
            return self.regs[a]
        self.sim_stats["undefined_accesses"] += 1
        return 0

    def _next_addr(self, a: int) -> int:
        if not self.regs[self._a["CTRL3_C"]] & 0x04:  # IF_INC = 0
            return a
        rounding = self._bits("ROUNDING")
        if rounding in (1, 3, 5, 6, 7) and a == 0x2D:
            return 0x22 if rounding in (3, 6, 7) else 0x28
        if rounding == 2 and a == 0x27:
            return 0x22
        return (a + 1) & 0x7F

    def read(self, register: int, length: int) -> bytes:
        """One read transaction of ``length`` bytes starting at ``register``."""
        self._advance(self.clock.now())
        if register == _FIFO_L and length % 2 == 0 and self._half is None:
            words = self.fifo.pop_words(length // 2)  # FIFO_DATA_OUT wraps (§9.4)
            self.sim_stats["fifo_underflow_words"] = self.fifo.underflow_reads
            return words.tobytes()
        out = bytearray(length)
        a = register
        read_l: set[int] = set()
        for i in range(length):
            if a == _FIFO_L:
                word = int(self.fifo.pop_words(1)[0]) & 0xFFFF
                out[i] = word & 0xFF
                self._half = word >> 8
                a = _FIFO_H
                continue
            if a == _FIFO_H:
                if self._half is None:
                    self._half = (int(self.fifo.pop_words(1)[0]) & 0xFFFF) >> 8
                out[i] = self._half
                self._half = None
                a = _FIFO_L
                continue
            out[i] = self._read_byte(a)
            if _OUT_FIRST <= a <= _OUT_LAST:
                pair = (a - _OUT_FIRST) // 2
                if a % 2 == 0:
                    read_l.add(pair)
                else:
                    read_l.discard(pair)
                    self._bdu_locked.discard(pair)
            a = self._next_addr(a)
        if read_l and self._bits("BDU"):
            self._bdu_locked |= read_l
        return bytes(out)

    def write(self, register: int, data: bytes) -> None:
        """One write transaction: ``data`` bytes to ``register`` onwards."""
        now = self.clock.now()
        self._advance(now)
        a = register
        for value in data:
            self._write_byte(a, value, now)
            a = self._next_addr(a)
        self._reconfigure(now)

    def _write_byte(self, a: int, value: int, now: float) -> None:
        reg = self.map.by_address.get(a)
        if reg is None:
            self.sim_stats["undefined_accesses"] += 1
            return
        if reg.name == "TIMESTAMP2_REG":
            if value == 0xAA:  # counter reset (§7-8)
                self._ts_origin = self._ticks_at(now)
            else:
                self.sim_stats["readonly_writes"] += 1
            return
        if reg.writable == 0:
            self.sim_stats["readonly_writes"] += 1
            return
        if value & ~reg.writable & 0xFF:
            self.sim_stats["reserved_writes"] += 1
            self.sim_reserved_log.append((a, value & ~reg.writable & 0xFF))
        value &= reg.writable
        if reg.name == "CTRL3_C":
            if value & 0x01:  # SW_RESET: reset values back, bit self-clears (§1, §3.3)
                self.sim_stats["resets"] += 1
                self._power_on()
                self._sw_reset_until = now + SW_RESET_BUSY_S
                return
            if value & 0x80:  # BOOT: reload trimming, bit self-clears
                self._boot_until = now + BOOT_BUSY_S
            value &= ~0x81
        self.regs[a] = value
