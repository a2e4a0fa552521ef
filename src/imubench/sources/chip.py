"""``sim://`` and ``i2c://`` sources: the real :mod:`lsm6ds` driver streaming the FIFO of
a simulated chip (on the simulated bus) or of a real chip (on ``smbus2.SMBus``).

URIs (parameters of both unless marked)::

    sim://CHIP?odr_hz=104&fs_dps=250&fs_g=2&seed=0&clock=virtual|wall&model=PATH
              &bus_khz=0&nack_rate=0&nack_burst=1&reset_every_s=0&overrun_at_s=
              &crystal_ppm=0&addr=0x6a&duration_s=&watermark_s=0.1&timestamp=1
              &on_overbudget=refuse|degrade&counting=0&stuck_bus_at_s=&stuck_bus_for_s=0
              &temperature=PROFILE&stuck_output_at_s=&stuck_output_for_s=0
              &temp_glitch_rate=0&temp_glitch_c=5&temp_glitch_s=0
    i2c:///dev/i2c-1?addr=0x6a&chip=lsm6dsl&odr_hz=104&fs_dps=250&fs_g=2&bus_khz=400
              &duration_s=&watermark_s=0.1&timestamp=1&on_overbudget=refuse

``bus_khz=0`` or absent means no bus timing model on ``sim://`` (and no budget check);
``nack_rate`` is per transaction; ``reset_every_s`` resets the chip periodically;
``overrun_at_s`` forces one FIFO overrun; ``temperature`` is a die-temperature profile
(``25``, ``ramp:20:0.01[:40]``, ``steps:0=20,600=30``, ``sine:25:5:3600``,
``replay:FILE.csv[:t_s:temp_c]``; URL-quote it) acting on the model's temperature terms;
``stuck_output_at_s``/``_for_s`` freeze every output (registers and FIFO repeat the last
sample); ``temp_glitch_rate`` (per s) adds +-``temp_glitch_c`` degC spikes lasting
``temp_glitch_s`` to the temperature output; ``counting=1`` makes raw gyro X count samples
(test signal); ``stall_every_s``/``stall_s`` stall the reading thread for ``stall_s``
between a FIFO status read and the data burst, once per ``stall_every_s``, as a busy host
would. ``duration_s`` makes the stream finite: it ends after the sample of index
``round(odr_hz * duration_s) - 1`` and every index below that is either delivered or
counted lost. Every parameter, its type, default and unit is declared once in
:data:`SIM_PARAMS` / :data:`I2C_PARAMS`. ``clock=wall`` paces :meth:`read` to real time
in batches of about ``watermark_s`` of data; :meth:`close` interrupts a wait at once.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from lsm6ds.driver import LSM6DS, ImuConfig
from lsm6ds.errors import DriverIOError, LSM6DSError
from lsm6ds.registers import CHIPS, accel_fs_code, chip_map, gyro_fs_code
from lsm6ds.stream import FifoStream, StreamChunk

from imubench.batch import Batch, Gap, gaps_before
from imubench.errors import SourceError
from imubench.sources.base import Source, SourceInfo
from imubench.sources.registry import (
    Backend,
    Param,
    SourceURI,
    check_model_param,
    register_backend,
)

if TYPE_CHECKING:
    from lsm6ds_sim.chip import SimChip
    from lsm6ds_sim.clock import SimClock
    from lsm6ds_sim.i2c import SimI2CBus
    from lsm6ds_sim.physics import SensorPhysics

COMMON_PARAMS: tuple[Param, ...] = (
    Param("odr_hz", float, 104.0, "output data rate of gyro and accelerometer, Hz"),
    Param("accel_odr_hz", float, None, "accelerometer ODR if different, Hz (FIFO refuses it)"),
    Param("fs_dps", float, 250.0, "gyro full scale, dps"),
    Param("fs_g", float, 2.0, "accelerometer full scale, g"),
    Param("addr", int, 0x6A, "7-bit I2C address (0x6a or 0x6b)"),
    Param("duration_s", float, None, "make the stream finite after this many seconds, s"),
    Param("io_timeout_s", float, None,
          "give up when the device has not answered for this long, s (default: retry)"),
    Param("watermark_s", float, None, "data let into the FIFO between polls, s"),
    Param("timestamp", bool, True, "stream the chip's timestamp in the FIFO"),
    Param("on_overbudget", str, "refuse", "an ODR the bus cannot carry: refuse or degrade",
          ("refuse", "degrade")),
)
SIM_PARAMS: tuple[Param, ...] = (
    *COMMON_PARAMS,
    Param("bus_khz", float, 0.0, "I2C timing model, kHz (0: none)"),
    Param("seed", int, 0, "random seed of the noise and the faults"),
    Param("clock", str, "virtual", "virtual (as fast as read) or wall (real time)",
          ("virtual", "wall")),
    Param("model", str, None, "noise model TOML file"),
    Param("temperature", str, None, "die temperature profile (docs/simulator.md)"),
    Param("crystal_ppm", float, 0.0, "oscillator frequency error, ppm"),
    Param("counting", bool, False, "test signal: raw gyro X counts samples"),
    Param("nack_rate", float, 0.0, "NACK probability per transaction"),
    Param("nack_burst", int, 1, "consecutive NACKed transactions per event"),
    Param("reset_every_s", float, 0.0, "spontaneous chip reset period, s (0: never)"),
    Param("overrun_at_s", float, None, "force one FIFO overrun at this time, s"),
    Param("stuck_bus_at_s", float, None, "bus stuck (timeouts) from this time, s"),
    Param("stuck_bus_for_s", float, 0.0, "bus stuck for this long, s"),
    Param("stuck_output_at_s", float, None, "outputs frozen from this time, s"),
    Param("stuck_output_for_s", float, 0.0, "outputs frozen for this long, s"),
    Param("temp_glitch_rate", float, 0.0, "temperature spikes per second"),
    Param("temp_glitch_c", float, 5.0, "temperature spike size, degC"),
    Param("temp_glitch_s", float, 0.0, "temperature spike length, s"),
    Param("stall_every_s", float, 0.0,
          "stall the reader between FIFO status and data read this often, s (0: never)"),
    Param("stall_s", float, 0.0, "length of each such stall, s"),
)
I2C_PARAMS: tuple[Param, ...] = (
    *COMMON_PARAMS,
    Param("chip", str, "lsm6dsl", "which chip is on the bus", CHIPS),
    Param("bus_khz", float, 400.0, "I2C clock for the bandwidth check, kHz"),
)
log = logging.getLogger(__name__)
IO_BACKOFF_MAX_S = 1.0
NO_ANSWER = "device not answering"
"""Gap reason of the samples a chip made while its bus failed every transfer, until the
stream stopped or ended (:meth:`ChipSource._outage_tail`)."""
FIRST_POLL_S = 0.1
"""The first poll comes after at most this long, s (its samples get one temperature)."""


@dataclass(frozen=True)
class SimHandles:
    """The simulated parts behind a ``sim://`` source, for jigs and tests that drive the
    sensor's physics (orientation, rate, temperature) or read the fault counts."""

    chip: SimChip
    bus: SimI2CBus
    physics: SensorPhysics
    clock: SimClock


@dataclass(frozen=True)
class ChipOptions:
    """Typed, validated options of a ``sim://`` or ``i2c://`` URI."""

    chip: str
    cfg: ImuConfig
    addr: int
    bus_hz: float | None
    watermark_s: float | None
    on_overbudget: str
    duration_s: float | None
    values: dict[str, Any]


class ChipSource(Source):
    """FIFO streaming of one LSM6DS chip through :class:`lsm6ds.stream.FifoStream`.

    Build it with ``open_source("sim://...")`` or ``open_source("i2c://...")``.
    ``sim`` holds the simulated parts of a ``sim://`` source (None on hardware).
    """

    def __init__(
        self,
        uri: str,
        dev: LSM6DS,
        cfg: ImuConfig,
        *,
        bus_hz: float | None,
        watermark_s: float,
        on_overbudget: str,
        duration_s: float | None,
        paced: bool,
        extra_config: dict[str, Any],
        on_close: Callable[[], None] | None = None,
        max_fill: float = 0.4,
        sim: SimHandles | None = None,
        io_timeout_s: float | None = None,
    ) -> None:
        super().__init__()
        self.dev = dev
        self.sim = sim
        self._paced = paced
        try:
            self.stream = FifoStream(
                dev,
                cfg,
                watermark_s=watermark_s,
                bus_hz=bus_hz,
                on_overbudget=on_overbudget,
                max_fill=max_fill,
            )
        except LSM6DSError as exc:
            raise SourceError(f"source {uri!r}: {exc}") from None
        cfg = self.stream.cfg
        if self.stream.degraded_from_hz is not None:  # said in the header only, before
            log.warning("source %r: %g Hz does not fit the bus (on_overbudget=degrade): "
                        "streaming at %g Hz", uri, self.stream.degraded_from_hz, cfg.odr_hz)
        self._sensitivity = np.array(
            [cfg.gyro_sensitivity_dps] * 3 + [cfg.accel_sensitivity_g] * 3
        )
        """dps or g per LSB of gx gy gz ax ay az."""
        self.bus_hz = bus_hz
        self.duration_s = duration_s
        self._n_total = round(cfg.odr_hz * duration_s) if duration_s is not None else None
        self._on_close = on_close
        self._t0_host: float | None = None
        self._start_host: float | None = None
        self._done = False
        self.io_timeout_s = io_timeout_s
        """Give up (SourceError) when the device has not answered for this long, s."""
        self._io_failing_since: float | None = None
        self._last_temp: tuple[float, float] | None = None
        """(host time of the newest sample, die temperature) of the previous poll."""
        self._sleep_first_s = 0.0
        self._pending: list[Gap] = []
        self._last_index = -1
        """Index of the newest sample delivered (-1 before the first)."""
        self._last_sample_t: float | None = None
        """Host time of that sample (the stream's start before the first), s."""
        self._stop_t: float | None = None
        """Host time a paced source was asked to stop (:meth:`interrupt`), s."""
        config = {
            "watermark_s": watermark_s,
            "bus_hz": bus_hz,
            "ts_decimation": self.stream.ts_decimation,
            "degraded_from_hz": self.stream.degraded_from_hz,
            **extra_config,
        }
        self.info = SourceInfo(
            uri=uri,
            chip=dev.chip,
            odr_hz=cfg.odr_hz,
            realtime=paced,
            fs_dps=cfg.fs_dps,
            fs_g=cfg.fs_g,
            gyro_sensitivity_dps=cfg.gyro_sensitivity_dps,
            accel_sensitivity_g=cfg.accel_sensitivity_g,
            config=config,
        )

    def interrupt(self) -> None:
        """As :meth:`Source.interrupt`, noting when (paced sources): a stop during an
        outage counts the samples made until then (:meth:`_outage_tail`), not until a
        blocked read returns."""
        if self._paced and self._stop_t is None:
            self._stop_t = self.dev.monotonic()
        super().interrupt()

    # -- helpers -------------------------------------------------------------------
    def _sleep(self, dt_s: float) -> None:
        if dt_s <= 0:
            return
        if self._paced:
            self._interrupt.wait(dt_s)
        else:
            self.dev.sleep(dt_s)

    def _sync_counters(self) -> None:
        c = self.dev.counters
        self.counters["bus_bytes"] = c["bus_bytes"]
        self.counters["io_errors"] = c["io_errors"]
        self.counters["retries"] = c["retries"]
        self.counters["overruns"] = self.stream.counters["overruns"]

    @property
    def elapsed_s(self) -> float:
        if self._start_host is None:
            return 0.0
        return self.dev.monotonic() - self._start_host

    @property
    def expected_samples(self) -> int | None:
        return self._n_total

    @property
    def measured_odr_hz(self) -> float | None:
        """ODR measured against the host clock from the chip's timestamp counter, Hz (None
        without timestamps): a crystal error shows here (107.9 for 104)."""
        return self.stream.measured_odr_hz if self.stream.ts_decimation else None

    @property
    def bus_utilization(self) -> float:
        """Wire bytes x 9 bits / (bus_hz x elapsed): the share of the link's payload
        limit the driver used (0 without a bus speed)."""
        if not self.bus_hz or self.elapsed_s <= 0:
            return 0.0
        return self.counters["bus_bytes"] * 9.0 / (self.bus_hz * self.elapsed_s)

    # -- Source hooks ----------------------------------------------------------------
    def prepare(self) -> None:
        """A simulated chip's first noise blocks are computed now, not in the first read."""
        if self.sim is not None:
            period = self.sim.chip.sim_sample_period_s(self.info.odr_hz)
            self.sim.physics.prepare(period)

    def _open(self) -> None:
        try:
            self.stream.start()
        except LSM6DSError as exc:
            raise SourceError(f"source {self.info.uri!r}: {exc}") from None
        self._start_host = self.dev.monotonic()
        self._last_sample_t = self._start_host

    def _close(self) -> None:
        self.stream.stop()
        if self._on_close is not None:
            self._on_close()

    def _read(self) -> Batch | None:
        backoff = 0.01
        self._sleep(self._sleep_first_s)
        self._sleep_first_s = 0.0
        while not self._done:
            if self._interrupt.is_set():
                return self._outage_tail(stopping=True)
            if self._n_total is not None and (tail := self._outage_tail()) is not None:
                return tail
            try:
                chunk, level = self.stream.poll()
                self._io_failing_since = None
            except DriverIOError as exc:
                self._give_up_after_timeout(exc)
                self._sync_counters()
                self._sleep(backoff)
                backoff = min(2 * backoff, IO_BACKOFF_MAX_S)
                self.stream.verify_soon()  # check for a reset at the next poll
                continue
            except LSM6DSError as exc:
                raise SourceError(f"source {self.info.uri!r}: {exc}") from None
            self._sync_counters()
            if chunk is not None:
                batch = self._to_batch(chunk)
                self._sleep_first_s = self.stream.time_to_watermark_s(level)
                if batch is not None:
                    return batch
                continue
            wait = self.stream.time_to_watermark_s(level)
            if self._last_temp is None:  # see _temperatures
                wait = min(wait, FIRST_POLL_S)
            self._sleep(max(wait, 0.0005))
        if self._pending:  # the stream ended in a gap
            gaps, self._pending = tuple(self._pending), []
            return Batch.empty(with_raw=True, gaps=gaps)
        return None

    def _outage_tail(self, *, stopping: bool = False) -> Batch | None:
        """The samples the chip made after the newest one read that no poll will bring,
        as a batch of one gap, or None.

        A chip that resets faster than it is polled, a bus that stopped answering or a
        board that was unplugged delivers nothing, and a hole was sized only when data
        came back: a finite stream never ended (virtual time spun for 16 simulated days)
        and a stop during the outage reported 0 lost. The samples are counted from the
        host time since the newest sample read, at the measured ODR:

        * a finite stream ends once every sample below its end is older than the FIFO
          holds (:attr:`~lsm6ds.stream.FifoStream.capacity_samples`): none can be read
          any more;
        * at a stop (``stopping``) during an outage (the device not answering, a chip
          reset recovered and no sample since, or no sample for twice the poll interval
          and at least a second), every sample made until the stop was asked for is
          lost (a read blocked by the outage may return seconds later: an outside
          reviewer's stop during an 11 s bus stall counted the 4.3 s after it). Outside an
          outage a stop ends with the newest sample read, as before.
        """
        assert self._last_sample_t is not None
        now = self.dev.monotonic()
        if stopping and self._stop_t is not None:
            now = max(min(now, self._stop_t), self._last_sample_t)
        odr = self.measured_odr_hz or self.info.odr_hz
        made = self._last_index + math.floor((now - self._last_sample_t) * odr)
        if stopping:
            quiet = max(2.0 * self.stream.time_to_watermark_s(0), 1.0)
            outage = (self._io_failing_since is not None
                      or self.stream.pending_reason == "chip reset"
                      or now - self._last_sample_t > quiet)
            end = made + 1 if outage else self._last_index + 1
        elif (self._n_total is not None
              and made - self.stream.capacity_samples >= self._n_total - 1):
            end = self._n_total
        else:
            return None
        if self._n_total is not None:
            end = min(end, self._n_total)
        self._done = True
        gaps = [*self._pending]
        start = max([self._last_index + 1, *(g.at for g in gaps)])
        if end > start:
            gaps.append(Gap(end, end - start, self._outage_reason()))
        self._pending = []
        return Batch.empty(with_raw=True, gaps=tuple(gaps)) if gaps else None

    def _lost_at_failure(self) -> Batch | None:
        """The outage before a failure, as a stop during it counts it
        (:meth:`_outage_tail`)."""
        return self._outage_tail(stopping=True)

    def _outage_reason(self) -> str:
        """Why the samples after the newest read were lost (:meth:`_outage_tail`)."""
        if self._io_failing_since is not None:
            return NO_ANSWER
        return self.stream.pending_reason or "fifo overrun"

    def _temperatures(self, t_s: np.ndarray, temp_c: float) -> np.ndarray:
        """The die temperature of each sample of a poll: the one reading of the poll
        (taken after its newest sample) and the previous poll's, interpolated over the
        samples' times. One reading for the whole poll stamped its older samples up to a
        poll late (+0.7 degC on average during a 0.5 degC/s ramp, a 0.02 dps/degC board
        corrected 0.014 dps off). The first poll, which has no previous reading, comes
        after at most :data:`FIRST_POLL_S`: in virtual time a simulated chip polls about
        every 2.7 s, and its first 280 samples were given the temperature at their end
        (+1.35 degC during that ramp). A reading taken at the start is no use: OUT_TEMP
        holds its reset value (25 degC) until the first conversion."""
        prev, self._last_temp = self._last_temp, (float(t_s[-1]), temp_c)
        if prev is None or not t_s[-1] > prev[0] or not math.isfinite(prev[1]):
            return np.full(len(t_s), temp_c)
        frac = np.clip((t_s - prev[0]) / (t_s[-1] - prev[0]), 0.0, 1.0)
        return prev[1] + (temp_c - prev[1]) * frac

    def _give_up_after_timeout(self, exc: DriverIOError) -> None:
        """SourceError once the device has failed every transaction for
        :attr:`io_timeout_s` (a board unplugged from the jig hung it with no message)."""
        now = self.dev.monotonic()
        if self._io_failing_since is None:
            self._io_failing_since = now
        elif self.io_timeout_s is not None and now - self._io_failing_since > self.io_timeout_s:
            raise SourceError(
                f"source {self.info.uri!r}: the device has not answered for "
                f"{now - self._io_failing_since:.1f} s ({exc}); check the wiring and the "
                "power, or raise io_timeout_s") from None

    def _to_batch(self, chunk: StreamChunk) -> Batch | None:
        index = chunk.index
        keep = slice(None)
        gaps = [Gap(at, lost, reason) for at, lost, reason in chunk.gaps]
        if self._n_total is not None:
            n = self._n_total
            n_keep = int(np.searchsorted(index, n))
            keep = slice(0, n_keep)
            gaps = gaps_before(gaps, n)
            if n_keep < len(index):
                self._done = True
        index = index[keep]
        self._pending.extend(gaps)
        if not len(index):
            return None
        last = int(index[-1])
        self._last_index, self._last_sample_t = last, float(chunk.t_s[keep][-1])
        mine = tuple(g for g in self._pending if g.at <= last)
        self._pending = [g for g in self._pending if g.at > last]
        raw = chunk.raw[keep]
        if self._t0_host is None:
            self._t0_host = float(chunk.t_s[0])
        return Batch(
            index=index,
            t_s=chunk.t_s[keep] - self._t0_host,
            values=raw * self._sensitivity,
            temp_c=self._temperatures(chunk.t_s, chunk.temp_c)[keep],
            raw=raw.astype(np.int16, copy=False),
            gaps=mine,
        )


# ---------------------------------------------------------------- factories
def _chip_options(uri: SourceURI, params: tuple[Param, ...], chip: str) -> ChipOptions:
    """Typed options of a chip URI, checked against the chip's tables (no device I/O)."""
    v = uri.values(params)
    if chip not in CHIPS:
        raise SourceError(
            f"source URI {uri.text!r}: chip {chip!r} must be one of {', '.join(CHIPS)}"
        )
    m = chip_map(chip)
    cfg = ImuConfig(
        odr_hz=v["odr_hz"], accel_odr_hz=v["accel_odr_hz"], fs_dps=v["fs_dps"],
        fs_g=v["fs_g"], timestamp=v["timestamp"],
    )
    try:
        m.odr_code(cfg.odr_hz, "gyro")
        m.odr_code(cfg.odr_xl_hz, "accel")
        gyro_fs_code(cfg.fs_dps)
        accel_fs_code(cfg.fs_g)
    except ValueError as exc:
        raise SourceError(f"source URI {uri.text!r}: {exc}") from None
    if v["addr"] not in (0x6A, 0x6B):
        raise SourceError(f"source URI {uri.text!r}: addr=0x{v['addr']:02x} must be 0x6a or 0x6b")
    for name in ("duration_s", "watermark_s"):
        if v[name] is not None and v[name] <= 0:
            raise SourceError(f"source URI {uri.text!r}: {name}={v[name]} must be > 0")
    return ChipOptions(
        chip=chip, cfg=cfg, addr=v["addr"],
        bus_hz=v["bus_khz"] * 1e3 if v["bus_khz"] else None,
        watermark_s=v["watermark_s"], on_overbudget=v["on_overbudget"],
        duration_s=v["duration_s"], values=v,
    )


SIM_NOISE_BLOCK = 1 << 14
"""Samples of noise the physics generates ahead per block on ``sim://`` (amortises the
per-call cost of the FIFO read loop; the values do not depend on it)."""


def sim_options(uri: SourceURI) -> ChipOptions:
    opts = _chip_options(uri, SIM_PARAMS, uri.target.strip("/").lower() or "lsm6dsl")
    v = opts.values
    base_hz = max(float(v["odr_hz"]), float(v["accel_odr_hz"] or v["odr_hz"]))
    check_model_param(uri, v["model"], base_hz)  # the physics samples at the faster ODR
    _fault_plan(uri, v)
    return opts


def _fault_plan(uri: SourceURI, v: dict[str, Any]) -> Any:
    from lsm6ds_sim.faults import FaultPlan

    try:
        return FaultPlan(
            nack_rate=v["nack_rate"], nack_burst=v["nack_burst"],
            reset_every_s=v["reset_every_s"], overrun_at_s=v["overrun_at_s"],
            stuck_bus_at_s=v["stuck_bus_at_s"], stuck_bus_for_s=v["stuck_bus_for_s"],
            stuck_output_at_s=v["stuck_output_at_s"],
            stuck_output_for_s=v["stuck_output_for_s"],
            temp_glitch_rate=v["temp_glitch_rate"], temp_glitch_c=v["temp_glitch_c"],
            temp_glitch_s=v["temp_glitch_s"], stall_every_s=v["stall_every_s"],
            stall_s=v["stall_s"], seed=v["seed"],
        )
    except ValueError as exc:
        raise SourceError(f"source URI {uri.text!r}: {exc}") from None


def _sim_physics(uri: SourceURI, v: dict[str, Any], duration_s: float | None) -> Any:
    """The sensor physics behind a ``sim://`` chip: ``model=`` noise model (quiet without
    one), ``temperature=`` profile (25 degC without one), flicker exact over the whole
    ``duration_s`` (default hint 3 h for an endless stream)."""
    from lsm6ds_sim.model import load_model
    from lsm6ds_sim.physics import DEFAULT_DURATION_HINT_S, SensorPhysics

    model = load_model(v["model"]) if v["model"] else None
    profile = v["temperature"]
    try:
        return SensorPhysics(
            model,
            seed=v["seed"],
            temperature=profile or None,
            duration_hint_s=duration_s or DEFAULT_DURATION_HINT_S,
            noise_block=SIM_NOISE_BLOCK,
        )
    except Exception as exc:  # ConfigError of a malformed profile, missing replay file
        raise SourceError(f"source URI {uri.text!r}: temperature={profile!r}: {exc}") from None


def build_sim(uri: SourceURI, opts: ChipOptions) -> ChipSource:
    """The ``sim://`` source: SimChip + SimI2CBus + the real driver."""
    from lsm6ds_sim.chip import SimChip
    from lsm6ds_sim.clock import SimClock
    from lsm6ds_sim.i2c import SimI2CBus

    v = opts.values
    clock_mode = v["clock"]
    clock = SimClock(clock_mode)
    physics = _sim_physics(uri, v, opts.duration_s)
    plan = _fault_plan(uri, v)
    sim_chip = SimChip(
        opts.chip, clock, physics, crystal_ppm=v["crystal_ppm"], sim_counting=v["counting"]
    )
    bus = SimI2CBus(clock, opts.bus_hz, plan,
                    stall_register=chip_map(opts.chip).addr("FIFO_STATUS1"))
    bus.attach(opts.addr, sim_chip)
    dev = LSM6DS(bus, opts.chip, opts.addr, sleep=clock.sleep, monotonic=clock.now)
    watermark_s = opts.watermark_s
    max_fill = 0.4
    if watermark_s is None:
        # virtual time: large bursts are free (fast); wall clock: small, paced batches
        watermark_s = 0.1 if clock_mode == "wall" else 60.0
        if clock_mode == "virtual" and (opts.bus_hz is None or opts.cfg.odr_hz <= 833):
            max_fill = 0.9
        if v["reset_every_s"]:  # poll between resets (each empties the FIFO), or no
            # sample survives one: 12.5 Hz polled every 24 s with a reset every 10 s
            watermark_s = min(watermark_s, v["reset_every_s"] / 4.0)
    return ChipSource(
        uri.text,
        dev,
        opts.cfg,
        bus_hz=opts.bus_hz,
        max_fill=max_fill,
        watermark_s=watermark_s,
        on_overbudget=opts.on_overbudget,
        duration_s=opts.duration_s,
        io_timeout_s=opts.values["io_timeout_s"],
        paced=clock_mode == "wall",
        extra_config={
            "seed": v["seed"],
            "clock": clock_mode,
            "model": v["model"],
            "faults": {k: val for k, val in plan.__dict__.items() if val},
        },
        on_close=bus.close,
        sim=SimHandles(sim_chip, bus, physics, clock),
    )


def i2c_options(uri: SourceURI) -> ChipOptions:
    return _chip_options(uri, I2C_PARAMS, str(uri.values(I2C_PARAMS)["chip"]))


def build_i2c(uri: SourceURI, opts: ChipOptions) -> ChipSource:
    """The ``i2c://`` source on a real ``smbus2.SMBus``."""
    path = uri.target or "/dev/i2c-1"
    try:
        from smbus2 import SMBus

        bus = SMBus(path)
    except (OSError, ImportError) as exc:
        raise SourceError(
            f"source URI {uri.text!r}: cannot open I2C adapter {path!r} "
            f"({exc}); check the path and permissions (group i2c)"
        ) from None
    dev = LSM6DS(bus, opts.chip, opts.addr, sleep=time.sleep, monotonic=time.monotonic)
    return ChipSource(
        uri.text,
        dev,
        opts.cfg,
        bus_hz=opts.bus_hz,
        watermark_s=opts.watermark_s or 0.1,
        on_overbudget=opts.on_overbudget,
        duration_s=opts.duration_s,
        io_timeout_s=opts.values["io_timeout_s"],
        paced=True,
        extra_config={"adapter": path},
        on_close=bus.close,
    )


register_backend(Backend("sim", SIM_PARAMS, sim_options, build_sim,
                         "simulated chip read through the real driver"))
register_backend(Backend("i2c", I2C_PARAMS, i2c_options, build_i2c, "a real chip on Linux I2C"))
