"""``replay://PATH``: a recording (native or CSV) played back as a source.

Parameters: ``clock=virtual`` (default: as fast as the consumer reads) or ``wall``
(paced to the recording's own timestamps, scaled by ``speed``), ``speed=1.0``,
``batch_s=0.1`` (seconds of data per batch). A replay never loses samples of its own
(``realtime`` is False: a pipeline paces it by its slowest consumer); the recording's own
gaps are replayed as holes in the sample index with the reasons the recording gives.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from imubench.batch import Batch, Gap
from imubench.errors import SourceError
from imubench.recording import Recording, load_recording
from imubench.sources.base import Source, SourceInfo
from imubench.sources.registry import Backend, Param, SourceURI, register_backend

REPLAY_PARAMS: tuple[Param, ...] = (
    Param("clock", str, "virtual", "virtual (as fast as read) or wall (paced)",
          ("virtual", "wall")),
    Param("speed", float, 1.0, "playback speed on a wall clock (2 = twice real time)"),
    Param("batch_s", float, 0.1, "seconds of data per batch, s"),
)


@dataclass(frozen=True)
class ReplayOptions:
    path: Path
    clock: str
    speed: float
    batch_s: float


class ReplaySource(Source):
    """Plays a recording back, whole batches at a time."""

    def __init__(self, uri: SourceURI, opts: ReplayOptions) -> None:
        super().__init__()
        self.path = opts.path
        self.clock = opts.clock
        self.speed = opts.speed
        self.batch_s = opts.batch_s
        self.recording: Recording = load_recording(self.path)
        meta = self.recording.metadata
        raw = self.recording.raw is not None
        self.info = SourceInfo(
            uri=uri.text,
            chip=str(meta.get("chip", "unknown")),
            odr_hz=self.recording.rate_hz,
            realtime=False,
            fs_dps=meta.get("fs_dps"),
            fs_g=meta.get("fs_g"),
            gyro_sensitivity_dps=meta.get("gyro_sensitivity_dps") if raw else None,
            accel_sensitivity_g=meta.get("accel_sensitivity_g") if raw else None,
            channels=tuple(c for c in self.recording.channels if c != "temp"),
            config={"replay_of": str(self.path), "clock": self.clock, "speed": self.speed},
        )
        self._gaps = sorted(self.recording.gaps, key=lambda g: g.at)
        self._pos = 0
        self._gap_pos = 0
        self._t_wall0 = 0.0

    @property
    def expected_samples(self) -> int | None:
        rec = self.recording
        if not len(rec):
            return 0
        return int(rec.index[-1]) + 1 + sum(g.lost for g in self._gaps if g.at > rec.index[-1])

    @property
    def elapsed_s(self) -> float:
        """Recording seconds of the samples replayed so far."""
        rec = self.recording
        return float(rec.t_s[self._pos - 1] - rec.t_s[0]) if self._pos > 0 else 0.0

    def _open(self) -> None:
        self._pos = 0
        self._gap_pos = 0
        self._t_wall0 = time.monotonic()

    def _take_gaps(self, up_to: int | None) -> tuple[Gap, ...]:
        start = self._gap_pos
        while self._gap_pos < len(self._gaps) and (
            up_to is None or self._gaps[self._gap_pos].at <= up_to
        ):
            self._gap_pos += 1
        return tuple(self._gaps[start:self._gap_pos])

    def _read(self) -> Batch | None:
        rec = self.recording
        if self._pos >= len(rec):
            rest = self._take_gaps(None)  # the recording ended in a gap
            return Batch.empty(with_raw=rec.raw is not None, gaps=rest) if rest else None
        n = max(1, round(self.batch_s * rec.rate_hz))
        sl = slice(self._pos, min(self._pos + n, len(rec)))  # the last batch may be short
        self._pos = sl.stop
        index = rec.index[sl]
        batch = Batch(index, rec.t_s[sl], rec.values[sl], rec.temp_c[sl],
                      None if rec.raw is None else rec.raw[sl],
                      self._take_gaps(int(index[-1])))
        if self.clock == "wall":
            due = self._t_wall0 + (batch.t_s[-1] - rec.t_s[0]) / self.speed
            delay = due - time.monotonic()
            if delay > 0 and self._interrupt.wait(delay):
                return None
        return batch

    def _close(self) -> None:
        pass


def replay_options(uri: SourceURI) -> ReplayOptions:
    v = uri.values(REPLAY_PARAMS)
    if not uri.target:
        raise SourceError(
            f"source URI {uri.text!r}: replay:// needs a path, e.g. replay://rec.imbr"
        )
    path = Path(uri.target)
    if not path.is_file():
        raise SourceError(f"source URI {uri.text!r}: no recording at {path}")
    for name in ("speed", "batch_s"):
        if v[name] <= 0:
            raise SourceError(f"source URI {uri.text!r}: {name}={v[name]} must be > 0")
    return ReplayOptions(path, v["clock"], v["speed"], v["batch_s"])


register_backend(Backend("replay", REPLAY_PARAMS, replay_options, ReplaySource,
                         "a recording (native or CSV) played back"))
