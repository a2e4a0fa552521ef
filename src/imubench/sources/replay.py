"""``replay://PATH``: a recording (native or CSV) played back as a source.

Parameters: ``clock=virtual`` (default: as fast as the consumer reads) or ``wall``
(paced to the recording's own timestamps, scaled by ``speed``), ``speed=1.0``,
``batch_s=0.1`` (seconds of data per batch). Lost samples in the recording stay holes
in the sample index and are counted in ``lost_samples``.
"""

from __future__ import annotations

import time

from imubench.batch import Batch
from imubench.errors import SourceError
from imubench.recording import load_recording
from imubench.sources.base import Source, SourceInfo
from imubench.sources.registry import SourceURI, register_source

_KNOWN = {"clock", "speed", "batch_s"}


class ReplaySource(Source):
    """Plays a recording back, whole batches at a time."""

    def __init__(self, uri: SourceURI) -> None:
        super().__init__()
        uri.check_known(_KNOWN)
        if not uri.target:
            raise SourceError(
                f"source URI {uri.text!r}: replay:// needs a path, e.g. replay://rec.imbr"
            )
        self.path = uri.target
        self.clock = uri.get_choice("clock", ("virtual", "wall"), "virtual")
        self.speed = float(uri.get_float("speed", 1.0) or 1.0)
        self.batch_s = float(uri.get_float("batch_s", 0.1) or 0.1)
        self.recording = load_recording(self.path)
        meta = self.recording.metadata
        self.info = SourceInfo(
            uri=uri.text,
            chip=str(meta.get("chip", "unknown")),
            odr_hz=self.recording.rate_hz,
            fs_dps=meta.get("fs_dps"),
            fs_g=meta.get("fs_g"),
            gyro_sensitivity_dps=meta.get("gyro_sensitivity_dps"),
            accel_sensitivity_g=meta.get("accel_sensitivity_g"),
            channels=tuple(c for c in self.recording.channels if c != "temp"),
            config={"replay_of": str(self.path), "clock": self.clock, "speed": self.speed},
        )
        self._pos = 0
        self._t_wall0 = 0.0
        self._last_index: int | None = None

    def _open(self) -> None:
        self._pos = 0
        self._t_wall0 = time.monotonic()

    def _read(self) -> Batch | None:
        rec = self.recording
        if self._pos >= len(rec):
            return None
        n = max(1, round(self.batch_s * rec.rate_hz))
        sl = slice(self._pos, self._pos + n)
        self._pos += n
        batch = Batch(rec.index[sl], rec.t_s[sl], rec.values[sl], rec.temp_c[sl],
                      None if rec.raw is None else rec.raw[sl])
        if self.clock == "wall":
            due = self._t_wall0 + (batch.t_s[-1] - rec.t_s[0]) / self.speed
            delay = due - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        lost = int(batch.index[-1] - batch.index[0] + 1 - len(batch))
        if self._last_index is not None:
            lost += int(batch.index[0] - self._last_index - 1)
        if lost:
            self.counters["lost_samples"] += lost
            self.counters["gaps"] += len(batch.internal_gaps) + int(
                self._last_index is not None and batch.index[0] > self._last_index + 1
            )
        self._last_index = int(batch.index[-1])
        return batch

    def _close(self) -> None:
        pass


@register_source("replay")
def _open_replay(uri: SourceURI) -> Source:
    return ReplaySource(uri)
