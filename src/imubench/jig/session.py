"""One jig run inside pytest: the station, limits, DUT, fixture, captures and the
measurements recorded so far (the plugin's ``jig`` fixture is a :class:`JigSession`)."""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar, cast

import numpy as np

from imubench import __version__
from imubench.jig.dut import Dut, resolve_uri_paths
from imubench.jig.errors import JigError, StationError
from imubench.jig.fixtures.base import Fixture
from imubench.jig.limits import SUITE_UNITS, Limits, load_limits
from imubench.jig.measurement import Measurement
from imubench.jig.procedures import Procedures
from imubench.jig.station import Station, load_station
from imubench.jig.units import conversion_factor
from imubench.recording.commit import replace_text

T = TypeVar("T")
MEASUREMENTS_FILE = "measurements.json"
"""What the plugin leaves in the run directory for the report (measurements, test
outcomes, artifacts for the plots)."""


def make_fixture(station: Station, dut: Dut) -> tuple[Fixture, Any]:
    """The fixture of the station (and the server of a simulated serial fixture, to stop
    at the end, or None)."""
    f = station.fixture
    if f.kind == "manual":
        from imubench.jig.fixtures.manual import ManualFixture

        return ManualFixture(), None
    if f.kind == "serial":
        from imubench.jig.fixtures.serial import SerialFixture

        assert f.port is not None
        return SerialFixture(f.port, f.baudrate, f.timeout_s), None
    if dut.sim is None:
        raise JigError(f"fixture.kind = {f.kind!r} needs a sim:// DUT, got {dut.uri!r}")
    from imubench.jig.fixtures.sim import SimFixture

    sim = SimFixture(dut.sim, f.chamber_time_constant_s)
    if f.kind == "sim":
        return sim, None
    from imubench.jig.fixtures.serial import SerialFixture
    from imubench.jig.fixtures.serial_sim import SimSerialFixtureServer

    server = SimSerialFixtureServer(sim).start()
    return SerialFixture(server.port, f.baudrate, f.timeout_s), server


class JigSession:
    """Everything a jig test needs (see docs/jig.md, "Writing your own tests")."""

    def __init__(self, station_path: str | Path, dut_uri: str | None, serial: str,
                 out_dir: str | Path) -> None:
        self.station = load_station(station_path)
        self.serial = serial
        self.out_dir = Path(out_dir)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.limits: Limits = load_limits(self.station.resolve(self.station.station.limits))
        base = self.station.path.resolve().parent if self.station.path else Path.cwd()
        self.uri = dut_uri or resolve_uri_paths(self.station.dut.uri, base)
        self.dut = Dut(self.uri, self.station.dut.defects)
        try:
            if self.limits.chip != self.dut.info.chip:
                raise StationError(f"{self.limits.path}: limits are for {self.limits.chip}, the"
                               f" DUT is an {self.dut.info.chip}; use"
                               f" config/limits-{self.dut.info.chip}.toml")
            self.fixture, self._server = make_fixture(self.station, self.dut)
        except BaseException:
            self.dut.close()
            raise
        self.procedures = Procedures(self.dut, self.fixture, self.station.capture)
        self.confidence = self.station.capture.confidence
        self.measurements: list[Measurement] = []
        self.artifacts: dict[str, Any] = {}
        self._cache: dict[str, Any] = {}
        self.run_id = self.out_dir.name

    def measure(self, name: str, value: float, ci: tuple[float, float], *,
                unit: str | None = None, low: float | None = None, high: float | None = None,
                method: str = "", test: str = "") -> Measurement:
        """Record one measurement judged against its limits: from the limits file when
        it has ``name``, else from ``low``/``high`` (one of them required)."""
        unit = unit if unit is not None else SUITE_UNITS.get(name)
        if name in self.limits:
            lim = self.limits[name]
            if unit is not None and unit != lim.unit:
                try:
                    k = conversion_factor(unit, lim.unit)
                except JigError as exc:
                    raise StationError(f"measurement {name!r}: its limit in "
                                       f"{self.limits.path}: {exc}") from None
                value, ci = value * k, (ci[0] * k, ci[1] * k)
                method += f" (converted from {unit} to the limit's {lim.unit})"
            unit, low, high = lim.unit, lim.low, lim.high
        elif low is None and high is None:
            raise StationError(f"measurement {name!r}: no limit in {self.limits.path} and "
                               "none given (pass low= and/or high=)")
        m = Measurement.judged(name, value, unit or "", low, high, ci, method, test)
        self.measurements.append(m)
        return m

    def cached(self, key: str, factory: Callable[[], T]) -> T:
        """``factory()`` computed once per run (fits shared by several tests); an error
        is raised again to every test that asks."""
        if key not in self._cache:
            try:
                self._cache[key] = factory()
            except Exception as exc:
                self._cache[key] = exc
        value = self._cache[key]
        if isinstance(value, Exception):
            raise value
        return cast(T, value)

    def typ(self, name: str) -> float:
        """The datasheet-typical value the limits file gives for ``name``."""
        t = self.limits[name].typ
        if t is None or not math.isfinite(t):
            raise JigError(f"{self.limits.path}: limit {name!r} needs 'typ'")
        return t

    def summary(self) -> dict[str, Any]:
        """The run's data for the report (measurements, artifacts, DUT, telemetry)."""
        return {
            "serial": self.serial,
            "run_id": self.run_id,
            "station": self.station.station.name,
            "sensor": self.station.station.sensor,
            "station_file": str(self.station.path),
            "station_sha256": _sha256(self.station.path),
            "limits_file": str(self.limits.path),
            "limits_sha256": _sha256(self.limits.path),
            "software": {"imubench": __version__},
            "dut": {"uri": self.uri, "chip": self.dut.info.chip, "odr_hz": self.dut.info.odr_hz},
            "fixture": self.fixture.describe(),
            "source_time_s": self.dut.elapsed_s,
            "telemetry": self.dut.telemetry(),
            "measurements": [m.as_dict() for m in self.measurements],
            "artifacts": self.artifacts,
        }

    def close(self) -> None:
        try:
            self.fixture.close()
        finally:
            if self._server is not None:
                self._server.stop()
            self.dut.close()


def _sha256(path: Path | None) -> str | None:
    """SHA-256 of a file the run used (the limits or station file as it was), None
    without one: a result names the exact limits it was judged against."""
    return None if path is None else hashlib.sha256(Path(path).read_bytes()).hexdigest()


def write_measurements(out_dir: str | Path, session: JigSession | None,
                       outcomes: list[dict[str, str]]) -> Path:
    """Write :data:`MEASUREMENTS_FILE`: the session's summary (or nothing but the test
    outcomes when the session never started, e.g. the DUT could not be opened)."""
    data: dict[str, Any] = session.summary() if session is not None else {"measurements": []}
    data["tests"] = outcomes
    path = Path(out_dir) / MEASUREMENTS_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    replace_text(path, json.dumps(plain(data), indent=1, allow_nan=False) + "\n")
    return path


def plain(o: Any) -> Any:
    """JSON-ready copy: numpy arrays and scalars to lists and numbers, NaN/inf to None."""
    if isinstance(o, np.ndarray):
        return plain(o.tolist())
    if isinstance(o, np.generic):
        return plain(o.item())
    if isinstance(o, float):
        return o if math.isfinite(o) else None
    if isinstance(o, dict):
        return {str(k): plain(v) for k, v in o.items()}
    if isinstance(o, list | tuple):
        return [plain(v) for v in o]
    return o


__all__ = ["MEASUREMENTS_FILE", "JigSession", "make_fixture", "plain", "write_measurements"]
