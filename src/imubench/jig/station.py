"""The station file (TOML): which board, which fixture, how long to capture, which
limits, where to publish. Validated with pydantic; every error names the file and the
key path. Relative paths (limits, extra test directories, a DUT's ``model=``) are
relative to the station file. Reference: docs/jig.md, "Station file".
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, PrivateAttr, ValidationError, field_validator

from imubench.jig.errors import JigError
from imubench.tomlread import read_toml

FIXTURE_KINDS = ("sim", "manual", "serial", "serial-sim")
CHANNELS = ("gx", "gy", "gz", "ax", "ay", "az")


class _Section(BaseModel):
    """A station file's table: unknown keys refused, and values of the type they are
    (strict: ``settle_s = "2"``, a string, was taken as 2 s)."""

    model_config = ConfigDict(extra="forbid", strict=True)


class StationSection(_Section):
    name: str = Field("station1", description="station name (one MQTT topic level)")
    sensor: str = Field("dut", description="sensor name in the MQTT topic (one level)")
    limits: str = Field("limits-lsm6dsl.toml", description="limits file, relative to here")
    tests: list[str] = Field(default_factory=list,
                             description="extra test directories or files run with the suite")
    select: str | None = Field(None, description="pytest -k expression selecting tests")
    suite: bool = Field(True, description="run the shipped acceptance suite")

    @field_validator("name", "sensor")
    @classmethod
    def _level(cls, v: str) -> str:
        from imubench.mqtt.errors import MqttError
        from imubench.mqtt.topics import validate_topic_level

        try:
            return validate_topic_level(v, "name")
        except MqttError as exc:
            raise ValueError(str(exc)) from None


class DefectsSection(_Section):
    """Defects injected into a simulated DUT (``sim://`` only)."""

    self_test_gyro_dps: float | None = Field(None, ge=0, description="gyro self-test"
                                             " deflection at 2000 dps full scale, dps")
    self_test_accel_g: float | None = Field(None, ge=0, description="accelerometer"
                                            " self-test deflection, g")
    stuck_axis: Literal["gx", "gy", "gz", "ax", "ay", "az"] | None = Field(
        None, description="an output axis frozen at its value")
    fifo_drop_rate: float = Field(0.0, ge=0, le=1, description="probability the FIFO loses"
                                  " each pattern")

    @property
    def any(self) -> bool:
        return bool(self.self_test_gyro_dps is not None or self.self_test_accel_g is not None
                    or self.stuck_axis or self.fifo_drop_rate)


class DutSection(_Section):
    uri: str = Field("sim://lsm6dsl?odr_hz=104&seed=1&clock=virtual",
                     description="source URI of the board under test")
    serial: str | None = Field(None, description="board serial number (or --serial)")
    defects: DefectsSection = Field(default_factory=lambda: DefectsSection.model_validate({}))


class FixtureSection(_Section):
    kind: Literal["sim", "manual", "serial", "serial-sim"] = "sim"
    port: str | None = Field(None, description="pyserial URL of a serial fixture")
    baudrate: int = Field(115200, gt=0)
    timeout_s: float = Field(120.0, gt=0, description="longest wait for one fixture command")
    chamber_time_constant_s: float = Field(
        120.0, gt=0, description="simulated die-to-chamber thermal time constant, s")
    chamber_accuracy_c: float = Field(
        0.5, ge=0, description="chamber temperature accuracy (uniform +-), degC")


class CaptureSection(_Section):
    confidence: float = Field(0.95, gt=0, lt=1, description="confidence of every interval")
    settle_s: float = Field(2.0, ge=0, description="wait after each move before capturing")
    static_s: float = Field(60.0, gt=0, description="static capture (noise, levels, FIFO)")
    position_s: float = Field(5.0, gt=0, description="capture per calibration position")
    rates_dps: list[float] = Field(default_factory=lambda: [100.0, 200.0],
                                   description="rate-table magnitudes, each turned both ways")
    rate_s: float = Field(5.0, gt=0, description="capture per rate-table rate")
    temperatures_c: list[float] = Field(
        default_factory=lambda: [25.0, 45.0, 65.0, 85.0, 0.0, -20.0, -40.0, 25.0],
        description="chamber set points in the order visited (must hold ambient, hot, cold;"
        " ambient again at the end shows the drift over the sweep to the fit)")
    ambient_c: float = 25.0
    hot_c: float = 85.0
    cold_c: float = -40.0
    temp_capture_s: float = Field(10.0, gt=0, description="capture per temperature and face")
    temp_stable_c: float = Field(0.1, gt=0, description="die temperature change allowed"
                                 " over temp_window_s once settled, degC")
    temp_window_s: float = Field(60.0, gt=0)
    temp_timeout_s: float = Field(7200.0, gt=0)

    @field_validator("rates_dps")
    @classmethod
    def _rates(cls, v: list[float]) -> list[float]:
        if not v or any(r <= 0 for r in v):
            raise ValueError("rates_dps must be positive magnitudes (each is turned both ways)")
        return v


class CalibrationSection(_Section):
    temperature_method: Literal["polynomial", "three-point-note", "three-point-exact"] = Field(
        "polynomial", description="which temperature fit the calibration file applies")
    nonlinearity: bool = Field(True, description="fit the quadratic term of accel and gyro")


class TiltSection(_Section):
    axis: Literal["x", "y", "z"] = Field("x", description="accelerometer axis used for tilt")
    range_used_g: float = Field(0.5, gt=0, le=2, description="input range actually used, g")
    average_samples: int = Field(104, ge=1, description="samples averaged per tilt reading")
    uses: float = Field(146000.0, gt=0, description="readings over the mission")
    expected_exceedances: float = Field(1.0, gt=0, description="readings beyond the budget"
                                        " allowed over the mission (sets the noise multiplier)")


class MqttSection(_Section):
    broker: str | None = Field(None, description="mqtt://host:port or mqtts://; none: no"
                               " publication")
    username: str | None = None
    password: str | None = None
    tls_ca: str | None = None
    qos: Literal[0, 1, 2] = 1
    timeout_s: float = Field(10.0, gt=0)


class Station(_Section):
    station: StationSection = Field(default_factory=lambda: StationSection.model_validate({}))
    dut: DutSection = Field(default_factory=lambda: DutSection.model_validate({}))
    fixture: FixtureSection = Field(default_factory=lambda: FixtureSection.model_validate({}))
    capture: CaptureSection = Field(default_factory=lambda: CaptureSection.model_validate({}))
    calibration: CalibrationSection = Field(
        default_factory=lambda: CalibrationSection.model_validate({}))
    tilt: TiltSection = Field(default_factory=lambda: TiltSection.model_validate({}))
    mqtt: MqttSection = Field(default_factory=lambda: MqttSection.model_validate({}))

    _path: Path | None = PrivateAttr(None)

    @property
    def path(self) -> Path | None:
        """The station file (None when built in code)."""
        return self._path

    def resolve(self, rel: str) -> Path:
        """``rel`` relative to the station file's directory."""
        p = Path(rel).expanduser()
        if p.is_absolute() or self.path is None:
            return p
        return self.path.parent / p

    def check(self) -> None:
        """Rules across sections."""
        c = self.capture
        where = str(self.path or "station")
        for name in ("ambient_c", "hot_c", "cold_c"):
            if getattr(c, name) not in c.temperatures_c:
                raise JigError(f"{where}: capture.{name} = {getattr(c, name)} must be one of"
                               f" capture.temperatures_c {c.temperatures_c}")
        if not c.cold_c < c.ambient_c < c.hot_c:
            raise JigError(f"{where}: need capture.cold_c < ambient_c < hot_c")
        if self.fixture.kind == "serial" and not self.fixture.port:
            raise JigError(f"{where}: fixture.kind = 'serial' needs fixture.port")
        sim_dut = self.dut.uri.startswith("sim://")
        if self.dut.defects.any and not sim_dut:
            raise JigError(f"{where}: dut.defects apply to sim:// DUTs only")
        if self.fixture.kind in ("sim", "serial-sim") and not sim_dut:
            raise JigError(f"{where}: fixture.kind = {self.fixture.kind!r} drives a simulated"
                           " chip; the DUT must be sim://")


def load_station(path: str | Path) -> Station:
    p = Path(path)
    data, _ = read_toml(p, "station file", JigError)
    try:
        station = Station.model_validate(data)
    except ValidationError as exc:
        lines = []
        for err in exc.errors():
            key = ".".join(str(x) for x in err["loc"])
            value = f" (got {err['input']!r})" if "input" in err and err["type"] != "missing" \
                else ""
            lines.append(f"{p}: key {key}: {err['msg']}{value}")
        raise JigError("\n".join(lines)) from None
    station._path = p
    station.check()
    return station


__all__ = ["CHANNELS", "FIXTURE_KINDS", "Station", "load_station"]
