"""Configuration of ``imubench run``: TOML validated with pydantic v2 and pydantic-settings.

Every setting has a default, a unit and a description (``Field(description=...)``), so
the configuration reference in the README is generated from this module
(``imubench run --config-reference``; a test keeps the two equal).

Environment variables override the file: ``IMUBENCH_<SECTION>__<KEY>=value``, e.g.
``IMUBENCH_MQTT__BROKER=mqtt://10.0.0.5:1883``. A value is read as the field's type
(pydantic-settings): ``IMUBENCH_MQTT__PASSWORD=12345`` is the string ``"12345"``,
``IMUBENCH_MQTT__PORT=1884`` the integer 1884, ``IMUBENCH_ALLAN__STATS=oadev,mdev`` a list.

Everything that can be checked before the daemon starts is checked at load time (so
``imubench run --check`` and the daemon's start refuse the same files): the source URI
(scheme, chip, ODR, full scales, the noise model file, the replay file), the tau
specification (through the engine's own parser and constructor), ``log.path``
placeholders and suffix, directories that must be creatable, the memory the ring buffer
(and an exact-memory engine) would take (:data:`MEMORY_FRACTION` of the physical memory at
most), and the TLS files. Errors name the file, the line, the key, the bad value (never a
secret's) and what is allowed, one line each, raised as :class:`ConfigError`.
"""

from __future__ import annotations

import datetime as dt
import os
import re
import socket
import ssl
import string
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from importlib import resources
from importlib.resources.abc import Traversable
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    SecretStr,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)
from pydantic_settings import (
    BaseSettings,
    NoDecode,
    PydanticBaseSettingsSource,
    SettingsConfigDict,
    SettingsError,
)

from imubench.errors import ConfigError, ImubenchError, SourceError

ENV_PREFIX = "IMUBENCH_"

LOG_PLACEHOLDERS = ("station", "sensor", "start")
"""The only ``{...}`` fields ``log.path`` may hold."""

MEMORY_FRACTION = 0.5
"""The ring buffer plus an exact-memory engine's phase history may take at most this
fraction of the machine's physical memory."""

RING_BYTES_PER_SAMPLE = 85
"""Bytes the ring buffer holds per sample: index (8), time (8), six float64 values (48),
temperature (8), six int16 raw counts (12), the raw flag (1)."""

MAX_POINTS_PER_DECADE = 100
"""Largest ``allan.taus`` points-per-decade count (each tau carries its own running sums)."""

MAX_TAU_LIMIT_S = 1e6
"""Largest ``allan.max_tau_s`` (11.6 days): a longer tau cannot be estimated in a run."""

SECRET_KEYS = frozenset({("mqtt", "password")})
"""Key paths whose values never appear in messages, logs or dumps."""


def quickstart_file() -> Traversable:
    """The shipped quick-start configuration (package data, present in a wheel too)."""
    return resources.files("imubench") / "data" / "quickstart.toml"


# -- field checks shared by the validators ----------------------------------------------


def _first_existing(path: Path) -> Path:
    p = path.absolute()
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def _filesystem_errors(check: Callable[[Path], None]) -> Callable[[Path], None]:
    """A path check whose OSError (a name too long, a loop of links) becomes the
    ValueError every check raises."""

    def checked(path: Path) -> None:
        if "\x00" in str(path):
            raise ValueError("a path cannot contain a NUL character")
        try:
            check(path)
        except OSError as exc:
            raise ValueError(f"{str(path)!r}: {exc.strerror}") from None

    return checked


@_filesystem_errors
def check_creatable_file(path: Path) -> None:
    """Refuse a path that names a directory or whose parent cannot be created/written."""
    if path.is_dir():
        raise ValueError(f"{path} is a directory; give a file path")
    if path.exists() and not path.is_file():
        raise ValueError(f"{path} exists and is not a regular file")
    if path.exists() and not os.access(path, os.R_OK | os.W_OK):
        raise ValueError(f"{path} is not readable and writable by this user")
    anchor = _first_existing(path.parent)
    if not anchor.is_dir():
        raise ValueError(f"{anchor} is not a directory, so {path.parent} cannot be created")
    if not os.access(anchor, os.W_OK | os.X_OK):
        raise ValueError(f"directory {anchor} is not writable by this user")


@_filesystem_errors
def check_readable_file(path: Path) -> None:
    """Refuse a path that is not a regular file this user can read."""
    if not path.is_file():
        raise ValueError("no such file" if not path.exists() else "not a regular file")
    with path.open("rb"):
        pass


def check_log_path(value: str) -> None:
    """``{station}``, ``{sensor}``, ``{start}`` only, without format spec or conversion,
    and a recording suffix (``.imbr``, ``.csv``, ``.csv.gz``)."""
    try:
        fields = list(string.Formatter().parse(value))
    except ValueError as exc:
        raise ValueError(f"{exc}; write {{{{ or }}}} for a literal brace") from None
    allowed = ", ".join(f"{{{p}}}" for p in LOG_PLACEHOLDERS)
    for _, name, spec, conversion in fields:
        if name is None:
            continue
        if name not in LOG_PLACEHOLDERS:
            raise ValueError(f"unknown placeholder {{{name}}}; allowed: {allowed}")
        if spec or conversion:
            raise ValueError(f"placeholder {{{name}}} takes no format spec or conversion")
    from imubench.recording import recording_kind

    try:
        kind = recording_kind(value)
    except ImubenchError:
        kind = None
    if kind not in ("native", "csv"):
        raise ValueError("the suffix must be .imbr (native), .csv or .csv.gz")


def _uri_odr_hz(uri: str) -> float | None:
    """The ODR a source URI gives (``odr_hz=`` or the backend's default for it), None
    when its backend has no such parameter (a replay, a SensorTile)."""
    from imubench.sources.registry import SourceURI, backend_for

    parsed = SourceURI.parse(uri)
    backend = backend_for(parsed)
    if not backend.has_param("odr_hz"):
        return None
    odr = parsed.values(backend.params)["odr_hz"]
    return None if odr is None else float(odr)


def _fastest_odr_hz() -> float:
    from lsm6ds.registers import ODR_HZ

    return max(ODR_HZ.values())


def physical_memory_bytes() -> int:
    """Physical memory of this machine (POSIX ``sysconf``)."""
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


# -- the sections ----------------------------------------------------------------------


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_default=True, allow_inf_nan=False)


def _check_source_uri(value: str) -> str:
    from imubench.sources.registry import check_source_uri

    try:  # scheme, parameters, chip, ODR, full scales, model and replay files
        check_source_uri(value)
    except SourceError as exc:
        raise ValueError(str(exc)) from None
    except OSError as exc:
        raise ValueError(f"cannot check it: {exc.strerror}") from None
    return value


def _check_calibration_file(value: str | None) -> str | None:
    if value is None:
        return None
    from imubench.calibration import Calibration, CalibrationError

    try:
        Calibration.load(value)
    except CalibrationError as exc:
        raise ValueError(str(exc)) from None
    return value


def _check_topic_level(value: str, what: str) -> str:
    from imubench.mqtt.errors import MqttError
    from imubench.mqtt.topics import validate_topic_level

    try:
        return validate_topic_level(value, what)
    except MqttError as exc:
        raise ValueError(str(exc)) from None


class SourceConfig(_Section):
    uri: str = Field(
        "sim://lsm6dsl?odr_hz=104&seed=1&clock=wall",
        description="Data source URI (unit: -): `sim://CHIP?...`, `i2c:///dev/i2c-1?addr=0x6a&"
        "chip=lsm6dsl`, `sensortile:///dev/ttyACM0`, `sensortile-sim://?...`, "
        "`replay://PATH`; a `model=` is a noise model file or `datasheet:CHIP`",
    )

    @field_validator("uri")
    @classmethod
    def _uri(cls, value: str) -> str:
        return _check_source_uri(value)


class LogConfig(_Section):
    enabled: bool = Field(True, description="Write a recording of every sample (unit: -)")
    path: str = Field(
        "recordings/{station}_{sensor}_{start}.imbr",
        description="Recording path (unit: -); `{station}`, `{sensor}`, `{start}` (UTC "
        "YYYYmmddTHHMMSSZ) are replaced; suffix `.imbr` (native), `.csv` or `.csv.gz`",
    )
    fsync_interval_s: float = Field(
        1.0, gt=0, le=3600,
        description="Flush and fsync the recording at least this often (unit: s)",
    )

    @field_validator("path")
    @classmethod
    def _path(cls, value: str) -> str:
        check_log_path(value)
        return value


class CalibrationConfig(_Section):
    file: str | None = Field(
        None,
        description="Calibration file applied to every sample before it is recorded and "
        "analysed (unit: path); raw counts stay in the recording (.imbr; a CSV holds the "
        "corrected values only), whose header states the "
        "calibration ([docs/calibration.md](docs/calibration.md))",
    )

    @field_validator("file")
    @classmethod
    def _file(cls, value: str | None) -> str | None:
        return _check_calibration_file(value)


class SensorConfig(_Section):
    """One sensor of a daemon that reads several (``[[sensors]]``)."""

    name: str = Field(description="Sensor name, its MQTT topic level and the `{sensor}` of "
                      "log.path and allan.state_path (unit: -)")
    uri: str = Field(description="Its data source URI, as `source.uri` (unit: -)")
    calibration: str | None = Field(
        None, description="Its calibration file, as `calibration.file` (unit: path)")

    @field_validator("name")
    @classmethod
    def _name(cls, value: str) -> str:
        return _check_topic_level(value, "sensors.name")

    @field_validator("uri")
    @classmethod
    def _uri(cls, value: str) -> str:
        return _check_source_uri(value)

    @field_validator("calibration")
    @classmethod
    def _calibration(cls, value: str | None) -> str | None:
        return _check_calibration_file(value)


@dataclass(frozen=True)
class SensorSpec:
    """What the daemon runs for one sensor: its name, source URI and calibration file."""

    name: str
    uri: str
    calibration: str | None


StatName = Literal["oadev", "adev", "mdev", "tdev", "hdev", "ohdev", "stdev", "ostdev"]


class AllanConfig(_Section):
    stats: Annotated[list[StatName], NoDecode] = Field(
        ["oadev"], min_length=1,
        description="Statistics kept live (unit: -): oadev, adev, mdev, tdev, hdev, ohdev, "
        "stdev, ostdev; all are published, the first as the headline `statistic`",
    )
    taus: str = Field(
        "octave",
        description="Taus kept (unit: -): `octave`, `decade`, N (points per decade, 1 to "
        f"{MAX_POINTS_PER_DECADE}) or a comma list of tau in seconds",
    )
    max_tau_s: float = Field(
        3600.0, gt=0, le=MAX_TAU_LIMIT_S, description="Largest tau kept up to date (unit: s)"
    )
    memory: Literal["exact", "bounded"] = Field(
        "bounded",
        description="Streaming engine memory mode (unit: -): `bounded` (state independent of "
        "tau, < 0.5 % EDF lost) or `exact` (3 m_max + 1 phase values per channel: 2.4 GB "
        "for 6 channels at 6.66 kHz up to 3600 s) ([docs/streaming.md](docs/streaming.md))",
    )
    state_path: str | None = Field(
        None,
        description="Save the engine state here on exit and every `state_every_s`, and "
        "resume from it on start, with the time between the runs kept as a gap (unit: "
        "path); empty for none; `{sensor}` is replaced by the sensor name (needed with "
        "several `[[sensors]]`)",
    )
    state_every_s: float = Field(
        300.0, ge=0,
        description="Also save the state this often while running, so that a restart "
        "after a crash or the watchdog resumes from at most this far back (unit: s); 0 "
        "saves on exit only",
    )

    @field_validator("stats", mode="before")
    @classmethod
    def _stats_list(cls, value: Any) -> Any:
        if isinstance(value, str):  # IMUBENCH_ALLAN__STATS=oadev,mdev
            return [s.strip() for s in value.split(",") if s.strip()]
        return value

    @field_validator("taus", mode="before")
    @classmethod
    def _taus_text(cls, value: Any) -> Any:
        # TOML may give `taus = 8` or `taus = [1, 10, 100]`: the same spec as text
        if isinstance(value, int) and not isinstance(value, bool):
            return str(value)
        if isinstance(value, list) and all(
            isinstance(v, int | float) and not isinstance(v, bool) for v in value
        ):
            return ",".join(repr(float(v)) for v in value)
        return value

    @field_validator("taus")
    @classmethod
    def _taus(cls, value: str) -> str:
        from imubench.stats.taus import parse_taus

        try:
            spec = parse_taus(value)
        except ImubenchError as exc:
            raise ValueError(str(exc)) from None
        if spec == "all":
            raise ValueError("'all' is for batch statistics; the live engine takes octave, "
                             "decade, N (points per decade) or a comma list of tau in seconds")
        if isinstance(spec, int) and not 1 <= spec <= MAX_POINTS_PER_DECADE:
            raise ValueError(f"points per decade must be 1 to {MAX_POINTS_PER_DECADE}")
        if isinstance(spec, list) and (
            not spec or not all(0 < t <= MAX_TAU_LIMIT_S for t in spec)
        ):
            raise ValueError(f"tau values must be seconds in (0, {MAX_TAU_LIMIT_S:g}]")
        return value

    @field_validator("state_path")
    @classmethod
    def _state_path(cls, value: str | None) -> str | None:
        if not value:
            return None
        if set(re.findall(r"{(\w*)}", value)) - {"sensor"}:
            raise ValueError("the only placeholder is {sensor}")
        check_creatable_file(Path(value.replace("{sensor}", "imu0")))
        return value

    def state_file(self, sensor: str) -> Path | None:
        """``state_path`` for ``sensor`` (None when unset)."""
        return None if not self.state_path else Path(
            self.state_path.replace("{sensor}", sensor))

    @property
    def tau_spec(self) -> str | int | list[float]:
        """``taus`` parsed (the value :class:`~imubench.stats.streaming.StreamingAllan`
        takes), by the one tau parser :func:`imubench.stats.taus.parse_taus`."""
        from imubench.stats.taus import parse_taus

        return parse_taus(self.taus)


class MqttConfig(_Section):
    broker: str = Field(
        "embedded",
        description="`embedded` (in-process broker on 127.0.0.1) or `mqtt://host:port`, "
        "`mqtts://host:port` (unit: -)",
    )
    port: int = Field(
        1883, ge=0, le=65535,
        description="Port of the embedded broker; the next free one is used if taken "
        "(unit: TCP port)",
    )
    station: str = Field("bench1", description="Station name, one MQTT topic level (unit: -)")
    sensor: str = Field("imu0", description="Sensor name, one MQTT topic level (unit: -); "
                        "with `[[sensors]]` each sensor has its own `name` instead")
    node: str | None = Field(
        None, description="Name of this daemon when it reads several `[[sensors]]` over one "
        "broker connection: its status topic `imubench/<station>/node/<node>/status` carries "
        "the connection's last will (unit: -); default: the host name")
    publish_interval_s: float = Field(
        1.0, ge=0.01, le=86400, description="Interval between Allan snapshots (unit: s)"
    )
    username: str | None = Field(None, description="Broker user name (unit: -)")
    password: SecretStr | None = Field(
        None, description="Broker password (unit: -); never logged, dumped or published"
    )
    tls_ca: str | None = Field(
        None, description="CA certificate file (PEM) for `mqtts://` (unit: path)"
    )
    tls_cert: str | None = Field(
        None, description="Client certificate file (PEM) for brokers that require one, with "
        "`tls_key` (unit: path)")
    tls_key: str | None = Field(
        None, description="Private key of `tls_cert` (PEM, unencrypted) (unit: path)")
    tls_insecure: bool = Field(
        False, description="Skip the check of the broker's host name against its certificate "
        "(the chain is still verified against `tls_ca`) (unit: -)")
    qos: int = Field(
        1, ge=0, le=2, description="QoS of the snapshots (unit: -); 1 (default): a snapshot "
        "the broker did not acknowledge is sent again after reconnecting, none is lost "
        "within `backlog_snapshots`")
    backlog_snapshots: int = Field(
        120, ge=1, le=100_000,
        description="Snapshots per sensor kept while the broker is unreachable, published "
        "when it is back (unit: snapshots); older ones are dropped and counted "
        "(`health.mqtt.dropped_snapshots`)")
    keepalive_s: int = Field(30, ge=5, le=3600, description="MQTT keep-alive (unit: s)")

    @field_validator("station", "sensor", "node")
    @classmethod
    def _topic_level(cls, value: str | None, info: ValidationInfo) -> str | None:
        return None if value is None else _check_topic_level(value, f"mqtt.{info.field_name}")

    @property
    def node_name(self) -> str:
        """``node``, else this host's name (with ``/``, ``+``, ``#`` replaced)."""
        from imubench.mqtt.topics import MAX_LEVEL_LENGTH

        if self.node is not None:
            return self.node
        return re.sub(r"[/+#\s]", "_", socket.gethostname())[:MAX_LEVEL_LENGTH] or "node"

    @field_validator("broker")
    @classmethod
    def _broker(cls, value: str) -> str:
        if value != "embedded":
            from imubench.mqtt.errors import MqttError
            from imubench.mqtt.publisher import parse_broker_url

            try:
                parse_broker_url(value)
            except MqttError as exc:
                raise ValueError(str(exc)) from None
        return value

    @field_validator("tls_cert", "tls_key")
    @classmethod
    def _tls_client_file(cls, value: str | None) -> str | None:
        if not value:
            return None
        check_readable_file(Path(value))
        return value

    @model_validator(mode="after")
    def _tls_pair(self) -> MqttConfig:
        if bool(self.tls_cert) != bool(self.tls_key):
            raise ValueError("mqtt.tls_cert and mqtt.tls_key go together")
        if self.tls_cert:
            try:
                ssl.create_default_context().load_cert_chain(self.tls_cert, self.tls_key)
            except (ssl.SSLError, OSError) as exc:
                raise ValueError(f"mqtt.tls_cert / tls_key: not a PEM certificate and its "
                                 f"key ({exc})") from None
        return self

    @field_validator("tls_ca")
    @classmethod
    def _tls_ca(cls, value: str | None) -> str | None:
        if not value:
            return None
        check_readable_file(Path(value))
        try:
            ssl.create_default_context(cafile=value)
        except (ssl.SSLError, ValueError) as exc:
            raise ValueError(f"not a PEM CA certificate file ({exc})") from None
        return value


class DisplayConfig(_Section):
    live_table: Literal["auto", "on", "off"] = Field(
        "auto", description="Live table on the terminal (unit: -): `auto` (when stdout is a "
        "tty), `on`, `off`"
    )
    interval_s: float = Field(
        1.0, ge=0.05, le=3600, description="Live table refresh interval (unit: s)"
    )


class WebConfig(_Section):
    enabled: bool = Field(
        False, description="Serve the live view from the daemon (unit: -); "
        "[docs/live-view.md](docs/live-view.md)"
    )
    listen: str = Field(
        "127.0.0.1:8080", description="Address of the live view (unit: HOST:PORT; port 0 "
        "= any free port); anything but loopback needs `web.password`"
    )
    user: str = Field("imubench", description="HTTP basic-auth user of the live view (unit: -)")
    password: SecretStr | None = Field(
        None, description="HTTP basic-auth password of the live view (unit: -); never "
        "stored in recordings or payloads"
    )

    @model_validator(mode="after")
    def _exposed(self) -> WebConfig:
        from imubench.fleet import FleetError
        from imubench.fleet.address import check_exposure, parse_listen

        try:
            host, _ = parse_listen(self.listen)
            check_exposure(host, None if self.password is None else "set")
        except FleetError as exc:
            raise ValueError(str(exc)) from None
        return self


class BufferConfig(_Section):
    capacity_s: float = Field(
        30.0, gt=0,
        description="Ring buffer capacity (unit: s of data at the source ODR); the ring "
        f"({RING_BYTES_PER_SAMPLE} B a sample) plus an exact-memory engine must fit in "
        f"{MEMORY_FRACTION:.0%} of the physical memory",
    )


class RunConfig(_Section):
    duration_s: float | None = Field(
        None, gt=0, description="Stop after this much data: duration_s x the nominal ODR "
        "samples, so a chip whose clock runs fast gets there sooner (unit: s); unset = until "
        "signalled",
    )


class Config(BaseSettings):
    """The whole configuration: a TOML file, then ``IMUBENCH_<SECTION>__<KEY>`` overrides."""

    model_config = SettingsConfigDict(
        env_prefix=ENV_PREFIX, env_nested_delimiter="__", extra="forbid",
        validate_default=True, case_sensitive=False,
    )

    source: SourceConfig = Field(default_factory=lambda: SourceConfig())
    log: LogConfig = Field(default_factory=lambda: LogConfig())
    allan: AllanConfig = Field(default_factory=lambda: AllanConfig())
    mqtt: MqttConfig = Field(default_factory=lambda: MqttConfig())
    display: DisplayConfig = Field(default_factory=lambda: DisplayConfig())
    buffer: BufferConfig = Field(default_factory=lambda: BufferConfig())
    run: RunConfig = Field(default_factory=lambda: RunConfig())
    calibration: CalibrationConfig = Field(default_factory=lambda: CalibrationConfig())
    web: WebConfig = Field(default_factory=lambda: WebConfig())
    sensors: list[SensorConfig] = Field(
        default_factory=list,
        description="Several sensors in one daemon (`[[sensors]]` tables of name, uri, "
        "calibration), each with its own pipeline, recording, engine state and topics over "
        "one broker connection; replaces `[source]`, `mqtt.sensor` and `[calibration]`")

    @model_validator(mode="after")
    def _sensors(self) -> Config:
        if not self.sensors:
            return self
        names = [s.name for s in self.sensors]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ValueError(f"sensors: name {', '.join(twice)} appears more than once")
        given = [f"[{k}]" for k in ("source", "calibration") if k in self.model_fields_set]
        if "sensor" in self.mqtt.model_fields_set:
            given.append("mqtt.sensor")
        if given:
            raise ValueError(f"sensors: [[sensors]] replaces {' and '.join(given)}; give "
                             "each sensor's uri, name and calibration in its table")
        if len(self.sensors) > 1:
            if self.log.enabled and "{sensor}" not in self.log.path:
                raise ValueError("sensors: with several sensors log.path needs {sensor}, "
                                 f"or their recordings collide (log.path = {self.log.path!r})")
            if self.allan.state_path and "{sensor}" not in self.allan.state_path:
                raise ValueError("sensors: with several sensors allan.state_path needs "
                                 "{sensor}, or their engine states collide")
        return self

    def sensor_specs(self) -> list[SensorSpec]:
        """The sensors this daemon runs: the ``[[sensors]]`` tables, else one sensor from
        ``[source]``, ``mqtt.sensor`` and ``[calibration]``."""
        if self.sensors:
            return [SensorSpec(s.name, s.uri, s.calibration) for s in self.sensors]
        return [SensorSpec(self.mqtt.sensor, self.source.uri, self.calibration.file)]

    @classmethod
    def settings_customise_sources(
        cls,
        settings_cls: type[BaseSettings],
        init_settings: PydanticBaseSettingsSource,
        env_settings: PydanticBaseSettingsSource,
        dotenv_settings: PydanticBaseSettingsSource,
        file_secret_settings: PydanticBaseSettingsSource,
    ) -> tuple[PydanticBaseSettingsSource, ...]:
        """The environment overrides the file (the file's values arrive as init kwargs)."""
        return env_settings, init_settings

    def public_dump(self) -> dict[str, Any]:
        """JSON-ready dict of every setting with secrets masked (``mqtt.password`` is
        ``'**********'`` when set): what recording headers and status payloads carry."""
        return self.model_dump(mode="json")


# -- checks across sections ------------------------------------------------------------


@dataclass(frozen=True)
class Problem:
    """One refused value: key path, value, what is wrong and allowed."""

    loc: tuple[str, ...]
    value: Any
    message: str


def cross_checks(cfg: Config) -> list[Problem]:
    """What no single field can check: memory at the sources' ODRs (all sensors together),
    the taus against each ODR and ``max_tau_s``, ``log.path``'s directory, TLS files
    against the broker."""
    problems: list[Problem] = []
    specs = cfg.sensor_specs()
    several = bool(cfg.sensors)
    odrs = [_uri_odr_hz(spec.uri) for spec in specs]
    rates = [odr if odr is not None else _fastest_odr_hz() for odr in odrs]
    ring = sum(cfg.buffer.capacity_s * rate * RING_BYTES_PER_SAMPLE for rate in rates)
    engine = 0.0
    if cfg.allan.memory == "exact":
        engine = sum((3 * cfg.allan.max_tau_s * rate + 1) * 6 * 8 for rate in rates)
    budget = MEMORY_FRACTION * physical_memory_bytes()
    if ring + engine > budget:
        at = ", ".join(f"{rate:g} Hz" for rate in rates) + (
            "" if None not in odrs else " (the fastest ODR where the URI states none)")
        per_s = sum(rates) * RING_BYTES_PER_SAMPLE
        room_s = max(0.0, budget - engine) / per_s
        problems.append(Problem(
            ("buffer", "capacity_s"), cfg.buffer.capacity_s,
            f"the ring buffer{'s need' if several else ' needs'} {_size(ring)}"
            + (f" and the exact-memory engine {_size(engine)}" if engine else "")
            + f" at {at}; at most {MEMORY_FRACTION:.0%} of the physical memory "
            f"({_size(budget)}) may be used: capacity_s <= {room_s:.4g}"
            + ("" if room_s > 0 else " (use allan.memory = 'bounded')"),
        ))
    from imubench.stats.taus import streaming_factors

    for i, (spec, odr) in enumerate(zip(specs, odrs, strict=True)):
        if odr is None:
            continue
        try:  # the streaming engine's own rule, without loading its kernels
            streaming_factors(cfg.allan.stats, cfg.allan.tau_spec, odr, cfg.allan.max_tau_s)
        except ImubenchError as exc:
            problems.append(Problem(("allan", "taus"), cfg.allan.taus,
                                    f"{exc} (allan.max_tau_s = {cfg.allan.max_tau_s:g} s, "
                                    f"ODR {odr:g} Hz"
                                    + (f" of sensors[{i}] {spec.name!r})" if several
                                       else ")")))
    if cfg.log.enabled:
        start = dt.datetime.now(dt.UTC).strftime("%Y%m%dT%H%M%SZ")
        for spec in specs:
            sample = cfg.log.path.format(station=cfg.mqtt.station, sensor=spec.name,
                                         start=start)
            try:
                check_creatable_file(Path(sample))
            except ValueError as exc:
                problems.append(Problem(("log", "path"), cfg.log.path, str(exc)))
                break
    tls_files = [(field, path) for field, path in (
        ("tls_ca", cfg.mqtt.tls_ca), ("tls_cert", cfg.mqtt.tls_cert),
        ("tls_key", cfg.mqtt.tls_key)) if path]
    if tls_files and not cfg.mqtt.broker.startswith("mqtts://"):
        given = ", ".join(f"mqtt.{field}" for field, _ in tls_files)
        problems.append(Problem(("mqtt", tls_files[0][0]), tls_files[0][1],
                                f"only used with an mqtts:// broker ({given} given); "
                                f"mqtt.broker is {cfg.mqtt.broker!r}"))
    return problems


def _size(n_bytes: float) -> str:
    for unit, scale in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20)):
        if n_bytes >= scale:
            return f"{n_bytes / scale:.3g} {unit}"
    return f"{n_bytes / 1024:.3g} KiB"


# -- loading ---------------------------------------------------------------------------


def _find_line(text: str, loc: tuple[Any, ...]) -> int | None:
    """Best-effort 1-based line of key path ``loc`` in TOML ``text`` (``("sensors", 1,
    "uri")`` is the ``uri`` of the second ``[[sensors]]`` table)."""
    keys = [str(k) for k in loc if not isinstance(k, int)]
    if not keys:
        return None
    index = next((k for k in loc if isinstance(k, int)), None)
    section, key = keys[:-1], keys[-1]
    current: list[str] = []
    seen: dict[str, int] = {}  # tables of an array seen so far, by name
    current_index: int | None = None
    for lineno, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        m = re.fullmatch(r"(\[\[?)([^\[\]]+)\]\]?\s*(#.*)?", stripped)
        if m:
            current = [p.strip().strip('"') for p in m.group(2).split(".")]
            current_index = None
            if m.group(1) == "[[":
                name = ".".join(current)
                current_index = seen[name] = seen.get(name, -1) + 1
                if not section and current == keys and current_index == index:
                    return lineno  # the table itself (a check across its keys)
            continue
        if (current == section and (index is None or current_index == index)
                and re.match(rf'"?{re.escape(key)}"?\s*=', stripped)):
            return lineno
        if not current and section and re.match(
            rf'{re.escape(".".join(section))}\s*\.\s*"?{re.escape(key)}"?\s*=', stripped
        ):
            return lineno
    return None


def _known_keys(loc: tuple[Any, ...]) -> str:
    """The keys allowed beside the unknown key at ``loc``."""
    fields: dict[str, Any] = dict(Config.model_fields)
    for part in loc[:-1]:
        field = fields.get(str(part))
        annotation = None if field is None else field.annotation
        if not (isinstance(annotation, type) and issubclass(annotation, BaseModel)):
            return ""
        fields = dict(annotation.model_fields)
    return "known keys: " + ", ".join(fields)


def _env_name(loc: tuple[Any, ...]) -> str:
    return ENV_PREFIX + "__".join(str(p).upper() for p in loc)


def _where(origin: str, text: str, loc: tuple[Any, ...]) -> str:
    name = _env_name(loc)
    if len(loc) > 1 and name in {k.upper() for k in os.environ}:
        return f"environment {name}"
    line = _find_line(text, loc)
    return f"{origin}:{line}" if line else origin


def _shown(loc: tuple[Any, ...], value: Any) -> str:
    if tuple(str(p) for p in loc[:2]) in SECRET_KEYS:
        return " = (secret, not shown)"
    if isinstance(value, dict):
        return ""
    text = repr(value)
    return f" = {text[:80]}..." if len(text) > 80 else f" = {text}"


_LONG_QUOTED = re.compile(r"'([^'\n]{100})[^'\n]+'")


def _one_line(line: str) -> str:
    """Whitespace folded; a quoted value longer than 100 characters (echoed by a check
    deeper down) cut to its first 100, so a line stays readable. A "quoted run" that holds
    ``: `` is the message between two quoted values, never cut (with a long temporary
    path the fix itself, "only used with an mqtts:// broker", was cut away)."""
    def cut(m: re.Match[str]) -> str:
        return m.group(0) if ": " in m.group(0) else f"'{m.group(1)}...'"

    return _LONG_QUOTED.sub(cut, " ".join(line.split()))


def format_validation_error(exc: ValidationError, origin: str, text: str = "") -> str:
    """One line per problem: where (file:line or environment variable), key, value, why."""
    lines = []
    for err in exc.errors():
        loc = tuple(err["loc"])
        key = ".".join(str(p) for p in loc) or "(top level)"
        where = _where(origin, text, loc)
        if err["type"] == "extra_forbidden":
            allowed = _known_keys(loc)
            lines.append(f"{where}: unknown key {key!r}" + (f" ({allowed})" if allowed else ""))
            continue
        msg = err["msg"]
        if msg.startswith("Value error, "):
            msg = msg[len("Value error, "):]
        lines.append(f"{where}: {key}{_shown(loc, err.get('input'))}: {msg}")
    return "\n".join(_one_line(line) for line in lines)


def load_config(path: str | Path | Traversable | None) -> Config:
    """Read ``path`` (TOML; None: the defaults), apply the environment overrides, validate
    every value (:func:`cross_checks` included). Raises :class:`ConfigError`."""
    text = ""
    data: dict[str, Any] = {}
    origin = "(defaults)"
    if path is not None:
        origin = str(path)
        source = Path(path) if isinstance(path, str) else path
        try:
            text = source.read_text(encoding="utf-8")
        except OSError as exc:
            raise ConfigError(f"{origin}: cannot read configuration: {exc.strerror}") from None
        except UnicodeDecodeError as exc:
            raise ConfigError(f"{origin}: not a UTF-8 text file ({exc.reason} at byte "
                              f"{exc.start})") from None
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"{origin}: invalid TOML: {exc}") from None
    early = [f"{_where(origin, text, (key,))}: unknown key {key!r} (known keys: "
             f"{', '.join(Config.model_fields)})" for key in data if key.startswith("_")]
    early += [f"environment {name}: not a configuration variable; use "
              f"{ENV_PREFIX}<SECTION>__<KEY>, e.g. {ENV_PREFIX}MQTT__PORT"
              for name in sorted(os.environ) if name.upper().startswith(ENV_PREFIX)
              and "__" not in name[len(ENV_PREFIX):]]
    if early:  # keys pydantic-settings would take as its own options; misspelt variables
        raise ConfigError("\n".join(early))
    try:
        cfg = Config(**data)
    except ValidationError as exc:
        raise ConfigError(format_validation_error(exc, origin, text)) from None
    except SettingsError as exc:
        raise ConfigError(f"environment: {exc}") from None
    problems = cross_checks(cfg)
    if problems:
        raise ConfigError("\n".join(_one_line(
            f"{_where(origin, text, p.loc)}: {'.'.join(p.loc)}{_shown(p.loc, p.value)}: "
            f"{p.message}") for p in problems
        ))
    return cfg


def config_sections() -> list[tuple[str, type[BaseModel]]]:
    """Every table of the configuration: ``(name, model)``, the ``[[sensors]]`` tables
    as ``sensors[]``."""
    sections: list[tuple[str, type[BaseModel]]] = [
        (name, f.annotation) for name, f in Config.model_fields.items()
        if isinstance(f.annotation, type) and issubclass(f.annotation, BaseModel)]
    sections.append(("sensors[]", SensorConfig))
    return sections


def reference_markdown() -> str:
    """The configuration reference (every key, default, unit, description) as Markdown."""
    rows = ["| key | default | description |", "|---|---|---|"]
    for section_name, section in config_sections():
        for key, field in section.model_fields.items():
            default = field.get_default(call_default_factory=True)
            shown = ("(required)" if field.is_required() else "(none)" if default is None
                     else f"`{default!r}`")
            rows.append(f"| `{section_name}.{key}` | {shown} | {field.description} |")
    return "\n".join(rows)
