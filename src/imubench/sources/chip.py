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
(test signal). ``duration_s`` makes the stream finite: it ends after the sample of index
``round(odr_hz * duration_s) - 1`` and every index below that is either delivered or
counted lost. ``clock=wall`` paces :meth:`read` to real time in batches of about
``watermark_s`` of data; :meth:`close` interrupts a wait at once.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from lsm6ds.driver import LSM6DS, ImuConfig
from lsm6ds.errors import DriverIOError, LSM6DSError
from lsm6ds.registers import CHIPS
from lsm6ds.stream import FifoStream, StreamChunk

from imubench.batch import Batch
from imubench.errors import SourceError
from imubench.sources.base import Source, SourceInfo
from imubench.sources.registry import SourceURI, register_source

_COMMON = {
    "odr_hz",
    "accel_odr_hz",
    "fs_dps",
    "fs_g",
    "addr",
    "duration_s",
    "watermark_s",
    "timestamp",
    "on_overbudget",
    "bus_khz",
}
SIM_PARAMS = _COMMON | {
    "seed",
    "clock",
    "model",
    "nack_rate",
    "nack_burst",
    "reset_every_s",
    "overrun_at_s",
    "crystal_ppm",
    "counting",
    "stuck_bus_at_s",
    "stuck_bus_for_s",
    "stuck_output_at_s",
    "stuck_output_for_s",
    "temp_glitch_rate",
    "temp_glitch_c",
    "temp_glitch_s",
    "temperature",
}
I2C_PARAMS = _COMMON | {"chip"}
IO_BACKOFF_MAX_S = 1.0


class ChipSource(Source):
    """FIFO streaming of one LSM6DS chip through :class:`lsm6ds.stream.FifoStream`.

    Build it with :func:`open_sim` / :func:`open_i2c` (or ``open_source(uri)``).
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
    ) -> None:
        super().__init__()
        self.dev = dev
        self._wake = threading.Event()
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
        self._sensitivity = np.array(
            [cfg.gyro_sensitivity_dps] * 3 + [cfg.accel_sensitivity_g] * 3
        )
        """dps or g per LSB of gx gy gz ax ay az."""
        self.bus_hz = bus_hz
        self.duration_s = duration_s
        self.n_total = round(cfg.odr_hz * duration_s) if duration_s is not None else None
        self._on_close = on_close
        self._t0_host: float | None = None
        self._start_host: float | None = None
        self._done = False
        self._sleep_first_s = 0.0
        self._delivered_to = -1  # last index handed out
        self.gap_log: list[tuple[int, int, str]] = []
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
            fs_dps=cfg.fs_dps,
            fs_g=cfg.fs_g,
            gyro_sensitivity_dps=cfg.gyro_sensitivity_dps,
            accel_sensitivity_g=cfg.accel_sensitivity_g,
            config=config,
        )

    # -- helpers -------------------------------------------------------------------
    def _sleep(self, dt_s: float) -> None:
        if dt_s <= 0:
            return
        if self._paced:
            self._wake.wait(dt_s)
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
    def measured_odr_hz(self) -> float | None:
        """ODR measured against the host clock from the chip's timestamp counter, Hz
        (None without timestamps): a crystal error shows here (107.9 for 104)."""
        return self.stream.measured_odr_hz if self.stream.ts_decimation else None

    @property
    def bus_utilization(self) -> float:
        """Wire bytes x 9 bits / (bus_hz x elapsed): the share of the link's payload
        limit the driver used (0 without a bus speed)."""
        if not self.bus_hz or self.elapsed_s <= 0:
            return 0.0
        return self.counters["bus_bytes"] * 9.0 / (self.bus_hz * self.elapsed_s)

    # -- Source hooks ----------------------------------------------------------------
    def _open(self) -> None:
        self._wake.clear()
        try:
            self.stream.start()
        except LSM6DSError as exc:
            raise SourceError(f"source {self.info.uri!r}: {exc}") from None
        self._start_host = self.dev.monotonic()

    def _close(self) -> None:
        self._wake.set()
        self.stream.stop()
        if self._on_close is not None:
            self._on_close()

    def _read(self) -> Batch | None:
        backoff = 0.01
        self._sleep(self._sleep_first_s)
        self._sleep_first_s = 0.0
        while not self._done:
            if self._paced and self._wake.is_set():
                return None
            try:
                chunk, level = self.stream.poll()
            except DriverIOError:
                self._sync_counters()
                self._sleep(backoff)
                backoff = min(2 * backoff, IO_BACKOFF_MAX_S)
                self.stream._last_verify_t = -float("inf")  # check for a reset next time
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
            self._sleep(max(self.stream.time_to_watermark_s(level), 0.0005))
        return None

    def _to_batch(self, chunk: StreamChunk) -> Batch | None:
        index = chunk.index
        keep = slice(None)
        gaps = chunk.gaps
        if self.n_total is not None:
            n = self.n_total
            n_keep = int(np.searchsorted(index, n))
            keep = slice(0, n_keep)
            # a gap (at, lost) is the hole [at - lost, at - 1]; keep its part below n
            gaps = [
                (min(at, n), min(at, n) - (at - lost), r) for at, lost, r in gaps if at - lost < n
            ]
            if n_keep < len(index):
                self._done = True
        for at, lost, reason in gaps:
            self.counters["gaps"] += 1
            self.counters["lost_samples"] += lost
            self.gap_log.append((at, lost, reason))
        index = index[keep]
        if not len(index):
            return None
        raw = chunk.raw[keep]
        if self._t0_host is None:
            self._t0_host = float(chunk.t_s[0])
        values = raw * self._sensitivity
        lost_before = int(index[0]) - self._delivered_to - 1
        self._delivered_to = int(index[-1])
        return Batch(
            index=index,
            t_s=chunk.t_s[keep] - self._t0_host,
            values=values,
            temp_c=np.full(len(index), chunk.temp_c),
            raw=raw.astype(np.int16, copy=False),
            lost_before=max(0, lost_before),
            meta={"gaps": [g for g in gaps if g[0] <= int(index[-1])]},
        )


# ---------------------------------------------------------------- factories
def _common(uri: SourceURI, default_bus_khz: float) -> dict[str, Any]:
    odr = uri.get_float("odr_hz", 104.0)
    fs_dps = uri.get_float("fs_dps", 250.0)
    fs_g = uri.get_float("fs_g", 2.0)
    cfg = ImuConfig(
        odr_hz=odr,
        accel_odr_hz=uri.get_float("accel_odr_hz"),
        fs_dps=fs_dps,
        fs_g=fs_g,  # type: ignore[arg-type]
        timestamp=uri.get_bool("timestamp", True),
    )
    try:
        cfg.gyro_sensitivity_dps, cfg.accel_sensitivity_g  # noqa: B018 - validate FS
    except ValueError as exc:
        raise SourceError(f"source URI {uri.text!r}: {exc}") from None
    bus_khz = uri.get_float("bus_khz", default_bus_khz)
    duration = uri.get_float("duration_s")
    if duration is not None and duration <= 0:
        raise SourceError(f"source URI {uri.text!r}: duration_s={duration} must be > 0")
    return {
        "cfg": cfg,
        "addr": uri.get_int("addr", 0x6A),
        "bus_hz": bus_khz * 1e3 if bus_khz else None,
        "watermark_s": uri.get_float("watermark_s"),
        "on_overbudget": uri.get_choice("on_overbudget", ("refuse", "degrade"), "refuse"),
        "duration_s": duration,
    }


SIM_NOISE_BLOCK = 1 << 14
"""Samples of noise the physics generates ahead per block on ``sim://`` (amortises the
per-call cost of the FIFO read loop; the values do not depend on it)."""


def _sim_physics(
    uri: SourceURI, seed: int, model_path: str | None, duration_s: float | None
) -> Any:
    """The sensor physics behind a ``sim://`` chip: ``model=`` noise model (quiet without
    one), ``temperature=`` profile (25 degC without one), flicker exact over the whole
    ``duration_s`` (default hint 3 h for an endless stream)."""
    from lsm6ds_sim.physics import DEFAULT_DURATION_HINT_S, SensorPhysics

    model = None
    if model_path:
        from lsm6ds_sim.model import load_model

        try:
            model = load_model(model_path)
        except Exception as exc:  # ModelError and file errors, reported with the URI
            raise SourceError(f"source URI {uri.text!r}: model {model_path!r}: {exc}") from None
    profile = uri.get_str("temperature")
    try:
        return SensorPhysics(
            model,
            seed=seed,
            temperature=profile or None,
            duration_hint_s=duration_s or DEFAULT_DURATION_HINT_S,
            noise_block=SIM_NOISE_BLOCK,
        )
    except Exception as exc:  # ConfigError of a malformed profile, missing replay file
        raise SourceError(f"source URI {uri.text!r}: temperature={profile!r}: {exc}") from None


def build_sim(uri: SourceURI) -> ChipSource:
    """The ``sim://`` source: SimChip + SimI2CBus + the real driver."""
    from lsm6ds_sim.chip import SimChip
    from lsm6ds_sim.clock import SimClock
    from lsm6ds_sim.faults import FaultPlan
    from lsm6ds_sim.i2c import SimI2CBus

    uri.check_known(SIM_PARAMS)
    chip = uri.target.strip("/").lower() or "lsm6dsl"
    if chip not in CHIPS:
        raise SourceError(
            f"source URI {uri.text!r}: chip {chip!r} must be one of {', '.join(CHIPS)}"
        )
    common = _common(uri, 0.0)
    seed = uri.get_int("seed", 0)
    clock_mode = uri.get_choice("clock", ("virtual", "wall"), "virtual")
    clock = SimClock(clock_mode)
    model_path = uri.get_str("model")
    physics = _sim_physics(uri, seed, model_path, common["duration_s"])
    try:
        plan = FaultPlan(
            nack_rate=uri.get_float("nack_rate", 0.0),  # type: ignore[arg-type]
            nack_burst=uri.get_int("nack_burst", 1),  # type: ignore[arg-type]
            reset_every_s=uri.get_float("reset_every_s", 0.0),  # type: ignore[arg-type]
            overrun_at_s=uri.get_float("overrun_at_s"),
            stuck_bus_at_s=uri.get_float("stuck_bus_at_s"),
            stuck_bus_for_s=uri.get_float("stuck_bus_for_s", 0.0),  # type: ignore[arg-type]
            stuck_output_at_s=uri.get_float("stuck_output_at_s"),
            stuck_output_for_s=uri.get_float("stuck_output_for_s", 0.0),  # type: ignore[arg-type]
            temp_glitch_rate=uri.get_float("temp_glitch_rate", 0.0),  # type: ignore[arg-type]
            temp_glitch_c=uri.get_float("temp_glitch_c", 5.0),  # type: ignore[arg-type]
            temp_glitch_s=uri.get_float("temp_glitch_s", 0.0),  # type: ignore[arg-type]
            seed=seed,  # type: ignore[arg-type]
        )
    except ValueError as exc:
        raise SourceError(f"source URI {uri.text!r}: {exc}") from None
    sim_chip = SimChip(
        chip,
        clock,
        physics,
        crystal_ppm=uri.get_float("crystal_ppm", 0.0),  # type: ignore[arg-type]
        sim_counting=uri.get_bool("counting", False),
    )
    bus = SimI2CBus(clock, common["bus_hz"], plan)
    addr = common["addr"]
    if addr not in (0x6A, 0x6B):
        raise SourceError(f"source URI {uri.text!r}: addr=0x{addr:02x} must be 0x6a or 0x6b")
    bus.attach(addr, sim_chip)
    dev = LSM6DS(bus, chip, addr, sleep=clock.sleep, monotonic=clock.now)
    watermark_s = common["watermark_s"]
    max_fill = 0.4
    if watermark_s is None:
        # virtual time: large bursts are free (fast); wall clock: small, paced batches
        watermark_s = 0.1 if clock_mode == "wall" else 60.0
        if clock_mode == "virtual" and (common["bus_hz"] is None or common["cfg"].odr_hz <= 833):
            max_fill = 0.9
    src = ChipSource(
        uri.text,
        dev,
        common["cfg"],
        bus_hz=common["bus_hz"],
        max_fill=max_fill,
        watermark_s=watermark_s,
        on_overbudget=common["on_overbudget"],
        duration_s=common["duration_s"],
        paced=clock_mode == "wall",
        extra_config={
            "seed": seed,
            "clock": clock_mode,
            "model": model_path,
            "faults": {k: v for k, v in plan.__dict__.items() if v},
        },
        on_close=bus.close,
    )
    src.sim_chip = sim_chip  # type: ignore[attr-defined]
    src.sim_bus = bus  # type: ignore[attr-defined]
    return src


def build_i2c(uri: SourceURI) -> ChipSource:
    """The ``i2c://`` source on a real ``smbus2.SMBus``."""
    uri.check_known(I2C_PARAMS)
    path = uri.target or "/dev/i2c-1"
    chip = (uri.get_str("chip", "lsm6dsl") or "lsm6dsl").lower()
    if chip not in CHIPS:
        raise SourceError(
            f"source URI {uri.text!r}: chip={chip!r} must be one of {', '.join(CHIPS)}"
        )
    common = _common(uri, 400.0)
    try:
        from smbus2 import SMBus

        bus = SMBus(path)
    except (OSError, ImportError) as exc:
        raise SourceError(
            f"source URI {uri.text!r}: cannot open I2C adapter {path!r} "
            f"({exc}); check the path and permissions (group i2c)"
        ) from None
    dev = LSM6DS(bus, chip, common["addr"], sleep=time.sleep, monotonic=time.monotonic)
    return ChipSource(
        uri.text,
        dev,
        common["cfg"],
        bus_hz=common["bus_hz"],
        watermark_s=common["watermark_s"] or 0.1,
        on_overbudget=common["on_overbudget"],
        duration_s=common["duration_s"],
        paced=True,
        extra_config={"adapter": path},
        on_close=bus.close,
    )


register_source("sim")(build_sim)
register_source("i2c")(build_i2c)
