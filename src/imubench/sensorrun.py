"""One sensor of ``imubench run``: its pipeline (source, recorder, Allan engine), its
snapshot payload, health and status detail.

The daemon (:mod:`imubench.daemon`) runs one :class:`SensorRun` per sensor (one, or
several with ``[[sensors]]``), each with its own acquisition thread, ring buffer,
recording, engine state and MQTT topics; they share the event loop and the broker
connection.
"""

from __future__ import annotations

import asyncio
import datetime as dt
import logging
import math
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from imubench.batch import CHANNELS, UNITS
from imubench.calibration import Calibration, recording_header
from imubench.calibration.live import LiveCalibration
from imubench.config import Config, SensorSpec
from imubench.errors import ImubenchError
from imubench.pipeline import Consumer, Pipeline
from imubench.recorder import NOT_RECORDED, Recorder
from imubench.sources.base import SourceInfo
from imubench.sources.registry import open_source
from imubench.stats.result import dev_unit

RESUME_GAP_FACTORS = 4
"""Gap rows between a resumed state and the new run: at most this many times the longest
averaging factor (:meth:`SensorRun._resume`)."""

if TYPE_CHECKING:  # imported off the event loop, after the status is online (numba)
    from imubench.allan_consumer import AllanConsumer, Snapshot
    from imubench.stats.streaming import StreamingAllan

log = logging.getLogger("imubench.daemon")

FAULT_LOG_S = 60.0
"""Shortest time between two fault lines of one sensor in the log, s."""


def utc_stamp() -> str:
    """UTC time as ``YYYYmmddTHHMMSSZ`` (the ``{start}`` of ``log.path``)."""
    return dt.datetime.now(dt.UTC).strftime("%Y%m%dT%H%M%SZ")


def per_channel(snap: Snapshot) -> list[Mapping[str, Any]]:
    """A six-channel engine's snapshot: one mapping (statistic -> result) per channel."""
    if not isinstance(snap, list):
        raise TypeError("a six-channel engine returns one snapshot per channel")
    return snap


def _changed_settings(saved: StreamingAllan, fresh: StreamingAllan, use_raw: bool,
                      scale: list[float] | None) -> list[str]:
    """What differs between a saved engine and the one this run would start: the rate,
    the statistics, the memory mode, the averaging factors (taus, max_tau_s), and the
    input's kind and scale (raw counts at a sensitivity, or values: a full scale or a
    calibration changed; ``scale``: this run's unit per count, None for values). A state
    was resumed when the rate and the statistics matched:
    after a restart at 2000 dps instead of 250 the new counts were scaled at the old
    sensitivity (live OADEV 32 % low, the interval excluding the truth), a bounded state
    ran on under memory = "exact", and a state of raw counts fed calibrated values
    crashed the engine at every start (an outside reviewer, multi-day runs)."""
    out = []
    if abs(saved.nominal_rate_hz - fresh.nominal_rate_hz) > 1e-9:
        out.append(f"ODR {saved.nominal_rate_hz:g} Hz, now {fresh.nominal_rate_hz:g}")
    if list(saved.stats) != list(fresh.stats):
        out.append(f"statistics {', '.join(saved.stats)}, now {', '.join(fresh.stats)}")
    if saved.memory != fresh.memory:
        out.append(f"memory {saved.memory}, now {fresh.memory}")
    if list(saved.ms) != list(fresh.ms):
        out.append(f"taus up to {saved.max_m / saved.nominal_rate_hz:g} s on "
                   f"{len(saved.ms)} factors, now {fresh.max_m / fresh.nominal_rate_hz:g} s "
                   f"on {len(fresh.ms)}")
    if saved.input_is_integer is not None and saved.input_is_integer != use_raw:
        out.append(f"input {'raw counts' if saved.input_is_integer else 'values'}, "
                   f"now {'raw counts' if use_raw else 'values'} (a calibration was added "
                   "or removed)")
    elif saved.channel_scale is not None:
        new_scale = np.broadcast_to(np.asarray(1.0 if scale is None else scale, float),
                                    saved.channel_scale.shape)
        if not np.allclose(saved.channel_scale, new_scale, rtol=1e-9):
            out.append("sensitivity per count "
                       f"{', '.join(f'{v:g}' for v in saved.channel_scale[[0, 3]])}, now "
                       f"{', '.join(f'{v:g}' for v in new_scale[[0, 3]])} (another full "
                       "scale)")
    return out


class SensorRun:
    """Everything the daemon runs for one sensor.

    ``say`` prints a line on the daemon's terminal; ``on_recorder_state`` is called from
    the recorder's thread when the recording state changes (``not recording: ...``).
    """

    def __init__(self, cfg: Config, spec: SensorSpec, *, start: str,
                 say: Callable[[str], None],
                 on_recorder_state: Callable[[SensorRun, str], None]) -> None:
        self.cfg = cfg
        self.spec = spec
        self.name = spec.name
        self._say = say
        self.calibration = (None if spec.calibration is None
                            else Calibration.load(spec.calibration))
        self.recorder: Recorder | None = None
        if cfg.log.enabled:
            path = Path(cfg.log.path.format(station=cfg.mqtt.station, sensor=spec.name,
                                            start=start))
            self.recorder = Recorder(
                path,
                {"config": cfg.public_dump(), "station": cfg.mqtt.station,
                 "sensor": spec.name, "source": spec.uri,
                 "calibration": recording_header(self.calibration)},
                fsync_interval_s=cfg.log.fsync_interval_s,
                on_state=lambda state: on_recorder_state(self, state),
                make_dirs=True,  # log.path may name directories per station / day
            )
        self.engine_consumer: AllanConsumer | None = None
        self.resumed_samples = 0
        """Samples the engine took over from ``allan.state_path`` at the start."""
        self.pipeline: Pipeline | None = None
        self.live_calibration: LiveCalibration | None = None
        """The calibration as applied to the stream (watches the die temperature)."""
        self.published = 0
        self._fault_counts: dict[str, int] = {}
        self._fault_logged_s = -math.inf
        self.skipped_slots = 0
        self.phase = "starting"

    def say(self, text: str) -> None:
        """A line on the terminal, prefixed by the sensor's name when there are several."""
        self._say(f"{self.name}: {text}" if self.cfg.sensors else text)

    @property
    def engine(self) -> StreamingAllan | None:
        return None if self.engine_consumer is None else self.engine_consumer.engine

    # -- building (in a worker thread: imports the simulator, scipy, numba) --------------
    def build(self) -> None:
        """The source, the recorder and the Allan engine, prepared (kernels compiled or
        loaded, recording opened) but not started."""
        from imubench.allan_consumer import AllanConsumer

        source = open_source(self.spec.uri)
        info = source.info
        if self.calibration is not None:  # another chip or range: refused before it runs
            self.calibration.check_data(info.chip, info.fs_dps, info.fs_g, None,
                                        f"source {info.uri}")
        self.say(f"source {info.uri}: {info.chip} at {info.odr_hz:g} Hz")
        self.engine_consumer = AllanConsumer(self._make_engine,
                                             lambda: source.measured_odr_hz,
                                             calibrated=self.calibration is not None)
        consumers: list[Consumer] = [self.engine_consumer]
        if self.recorder is not None:
            consumers.insert(0, self.recorder)
        cal = self.calibration
        self.live_calibration = (None if cal is None
                                 else LiveCalibration(cal, f"source {info.uri}", self.say))
        self.pipeline = Pipeline(source, consumers, capacity_s=self.cfg.buffer.capacity_s,
                                 duration_s=self.cfg.run.duration_s,
                                 transform=self.live_calibration)
        self.pipeline.prepare()

    def _make_engine(self, info: SourceInfo, use_raw: bool) -> StreamingAllan:
        from imubench.stats.streaming import StreamingAllan

        a = self.cfg.allan
        scale = None
        if use_raw:
            assert info.gyro_sensitivity_dps is not None
            assert info.accel_sensitivity_g is not None
            g, acc = info.gyro_sensitivity_dps, info.accel_sensitivity_g
            scale = [g, g, g, acc, acc, acc]
        fresh = StreamingAllan(info.odr_hz, taus=a.tau_spec, stats=list(a.stats),
                               max_tau_s=a.max_tau_s, memory=a.memory, scale=scale)
        state = a.state_file(self.name)
        if state is not None and state.exists():
            try:
                saved_at = state.stat().st_mtime
                eng = StreamingAllan.load_state(state.read_bytes())
                changed = _changed_settings(eng, fresh, use_raw, scale)
                if not changed:
                    self._resume(eng, state, saved_at)
                    return eng
                self.say(f"ignoring {state}: it was made with other settings "
                         f"({'; '.join(changed)}); the engine starts empty and the state "
                         "is replaced at the next save")
            except (ImubenchError, OSError, ValueError, KeyError) as exc:
                self.say(f"ignoring {state}: {exc}")
        return fresh

    def _resume(self, eng: StreamingAllan, state: Path, saved_at: float) -> None:
        """Take ``eng`` (loaded from ``state``, written at ``saved_at``, Unix s) as this
        run's engine: the time since it was saved becomes gap rows before the first
        sample, at most :data:`RESUME_GAP_FACTORS` x the longest averaging factor (no
        estimate spans that many samples, so a longer gap gives the same results), and the
        samples it holds are counted in :attr:`resumed_samples`."""
        assert self.engine_consumer is not None
        pause_s = max(0.0, time.time() - saved_at)
        rows = min(round(pause_s * eng.nominal_rate_hz), RESUME_GAP_FACTORS * eng.max_m + 4)
        self.engine_consumer.leading_gap_rows = max(rows, 1)
        lengths, counts = eng.runs(0)
        self.resumed_samples = int(np.sum((lengths - 1) * counts))
        saved = dt.datetime.fromtimestamp(saved_at, dt.UTC).isoformat(timespec="seconds")
        self.say(f"resumed Allan state from {state} ({self.resumed_samples} samples, saved "
                 f"{saved}, {pause_s:.0f} s ago): the runs are kept apart by a gap; samples "
                 "taken after that save and before this start (up to "
                 f"{pause_s * eng.nominal_rate_hz:.0f}, if the last run went on until now; "
                 "its recording holds them) are not in it")

    async def save_state(self) -> None:
        """Write the engine state to ``allan.state_path`` (atomically), when configured;
        the state is made in the engine's thread (:meth:`AllanConsumer.request_state`)."""
        state = self.cfg.allan.state_file(self.name)
        ec = self.engine_consumer
        if state is None or ec is None or ec.engine is None or not ec.n_samples:
            return
        blob = await asyncio.wrap_future(ec.request_state())

        def write() -> None:
            state.parent.mkdir(parents=True, exist_ok=True)
            tmp = state.with_suffix(state.suffix + ".tmp")
            try:
                tmp.write_bytes(blob)
                tmp.replace(state)
            except OSError:  # a full disk left an empty .tmp beside the state
                tmp.unlink(missing_ok=True)
                raise

        await asyncio.to_thread(write)

    @property
    def samples(self) -> int:
        """Samples the engine holds: those resumed from the saved state and those
        delivered to it in this run (lost ones are not samples)."""
        p = self.pipeline
        acc = p.accounts().get("engine") if p is not None else None
        return self.resumed_samples + (acc.delivered if acc is not None else 0)

    def fault_lines(self, now_s: float) -> list[str]:
        """Warnings for the log of what went wrong since the last ones: samples the source
        lost (by reason), its I/O errors, and samples a consumer lost; at most one line
        per :data:`FAULT_LOG_S`. A two-hour bus outage (41934 I/O errors, 749369 samples
        lost) and hundreds of resets and overruns reached MQTT only: stderr, and so the
        journal, stayed empty (an outside reviewer, multi-day runs)."""
        p = self.pipeline
        if p is None or now_s - self._fault_logged_s < FAULT_LOG_S:
            return []
        tel = p.source.telemetry()
        counts = {f"source lost ({reason})": n for reason, n in tel.lost_by_reason.items()}
        counts["I/O errors"] = tel.io_errors
        for name, acc in p.accounts().items():  # a consumer's own losses (the source's
            # gaps reach every consumer and are counted above)
            for reason, n in acc.lost_by_reason.items():
                if reason not in tel.lost_by_reason:
                    counts[f"{name} lost ({reason})"] = n
        grew = {k: n - self._fault_counts.get(k, 0) for k, n in counts.items()
                if n > self._fault_counts.get(k, 0)}
        if not grew:
            return []
        self._fault_counts, self._fault_logged_s = counts, now_s
        return [f"{self.name}: since the last report: "
                + ", ".join(f"{k} +{v}" for k, v in grew.items())
                + " (totals in the snapshot's health)"]

    # -- payloads ------------------------------------------------------------------------
    def health(self) -> dict[str, Any]:
        """Acquisition health for the snapshot payload: source telemetry, what each
        consumer received and lost (by reason), recording state and size."""
        p = self.pipeline
        if p is None:
            return {}
        tel = p.source.telemetry()
        produced, view = p.view()  # one instant: delivered + lost + lag == produced
        out: dict[str, Any] = {
            "phase": self.phase,
            "produced": produced,
            "source": dict(tel.as_dict()),
            "consumers": {name: self._account(name, a) for name, (a, _) in view.items()},
            "lag": {name: lag for name, (_, lag) in view.items()},
            "temperature_c": (None if self.engine_consumer is None
                              else self.engine_consumer.temperature_c),
            "snapshots_skipped": self.skipped_slots,
        }
        if self.live_calibration is not None:
            out["calibration_extrapolated"] = self.live_calibration.samples_extrapolated
        if self.recorder is not None:
            segs = self.recorder.segments
            out["recording"] = {
                "state": self.recorder.state,
                "path": str(segs[-1]) if segs else None,
                "segments": len(segs),
                "bytes": sum(s.stat().st_size for s in segs if s.exists()),
                "not_recorded": self.recorder.not_recorded,
            }
        return out

    def _account(self, name: str, a: Any) -> dict[str, Any]:
        """A consumer's account for ``health.consumers``; the recorder's counts what it
        could not write (disk full) as lost, as the summary line does (the payload said
        4492800 delivered and 0 lost where 2223072 were never written)."""
        delivered, lost, reasons = a.delivered, a.lost, dict(a.lost_by_reason)
        if name == "recorder" and self.recorder is not None and self.recorder.not_recorded:
            unwritten = self.recorder.not_recorded
            delivered, lost = delivered - unwritten, lost + unwritten
            reasons[NOT_RECORDED] = reasons.get(NOT_RECORDED, 0) + unwritten
        return {"delivered": delivered, "lost": lost, "lost_by_reason": reasons}

    def snapshot_payload(self, snap: Snapshot | None) -> dict[str, Any]:
        """The ``allan`` MQTT payload (docs/mqtt.md): the first configured statistic in
        ``statistic``/``channels`` and every configured one under ``statistics``."""
        stats = list(self.cfg.allan.stats)
        per_stat: dict[str, dict[str, Any]] = {s: {} for s in stats}
        if snap is not None:
            for ch, res in zip(CHANNELS, per_channel(snap), strict=True):
                for s in stats:
                    r = res[s]
                    per_stat[s][ch] = {
                        "tau_s": r.tau_s, "m": r.m, "dev": r.dev, "n": r.n,
                        "gaps": r.gaps, "ci_low": r.ci_low,
                        "ci_high": r.ci_high, "alpha": r.alpha, "edf": r.edf,
                        "units": dev_unit(UNITS[ch], s),
                    }
        info = self.pipeline.info if self.pipeline is not None else None
        engine_account = (self.pipeline.accounts().get("engine")
                          if self.pipeline is not None else None)
        return {
            "time": dt.datetime.now(dt.UTC).isoformat(timespec="milliseconds"),
            "station": self.cfg.mqtt.station, "sensor": self.name,
            "chip": info.chip if info else None, "odr_hz": info.odr_hz if info else None,
            # the samples the deviations are computed on (the snapshot is made a little
            # ahead of the publish tick: up to 19 % more had arrived by then in a virtual
            # run), the memory mode the engine runs in
            "samples": self.resumed_samples + (0 if self.engine_consumer is None
                                               else self.engine_consumer.samples_at_snapshot),
            "resumed_samples": self.resumed_samples,
            "lost_samples": engine_account.lost if engine_account is not None else 0,
            "statistic": stats[0],
            "memory": self.engine.memory if self.engine is not None else self.cfg.allan.memory,
            "channels": per_stat[stats[0]],
            "statistics": per_stat,
            "health": self.health(),
        }

    def status_detail(self) -> dict[str, Any]:
        """What the sensor's retained status carries besides its identity."""
        detail: dict[str, Any] = {"phase": self.phase, "source": self.spec.uri,
                                  "publish_interval_s": self.cfg.mqtt.publish_interval_s}
        if self.pipeline is not None:
            info = self.pipeline.info
            detail.update(chip=info.chip, odr_hz=info.odr_hz, source=info.uri)
        if self.recorder is not None:
            detail["recording"] = self.recorder.state
        return detail

    async def snapshot(self) -> Snapshot | None:
        """The engine's snapshot, computed in its own thread (None before any sample)."""
        ec = self.engine_consumer
        if ec is None or not ec.n_samples:
            return None
        return await asyncio.wrap_future(ec.request_snapshot())

    # -- terminal ------------------------------------------------------------------------
    def table(self, snap: Snapshot | None) -> list[str]:
        """Counters, then the deviation per channel at about one tau per decade."""
        stat = next(iter(self.cfg.allan.stats))
        p = self.pipeline
        lines = []
        if p is not None:
            tel = p.source.telemetry()
            acc = p.accounts().get("engine")
            lost = acc.lost if acc is not None else 0
            lines.append(f"{self.name}: {p.info.chip} {p.info.odr_hz:g} Hz  samples "
                         f"{self.samples}  lost "
                         f"{lost}  gaps {tel.gaps}  recording "
                         f"{self.recorder.state if self.recorder is not None else 'off'}")
        if snap is None:
            return lines
        first = per_channel(snap)[0][stat]
        if not len(first):
            return lines
        decades = sorted({int(np.floor(np.log10(t))) for t in first.tau_s})
        cols = [int(np.argmin(np.abs(np.log10(first.tau_s) - d))) for d in decades]
        lines.append(f"{stat:>6} " + "".join(f"{first.tau_s[i]:>11.3g}s" for i in cols))
        for ch, res in zip(CHANNELS, per_channel(snap), strict=True):
            r = res[stat]
            vals = "".join(f"{r.dev[i]:>12.4g}" if i < len(r) else " " * 12 for i in cols)
            lines.append(f"{ch:>2} {UNITS[ch]:>3} {vals}")
        return lines

    def summary(self) -> str:
        """The line printed at the end: produced, delivered and lost per consumer."""
        p = self.pipeline
        if p is None:
            return f"{self.name}: stopped before the acquisition started"
        acc = p.accounts()
        rec = acc.get("recorder")
        eng = acc.get("engine")
        text = (f"stopped after {p.produced} samples produced; engine "
                f"{eng.delivered if eng else 0} delivered, {eng.lost if eng else 0} lost")
        if rec is not None and self.recorder is not None:
            text += (f"; recording {rec.delivered - self.recorder.not_recorded} written, "
                     f"{rec.lost + self.recorder.not_recorded} lost")
        return f"{self.name}: {text}" if self.cfg.sensors else text
