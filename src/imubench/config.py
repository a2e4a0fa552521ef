"""Configuration of ``imubench run``: TOML validated with pydantic v2.

Every setting has a default, a unit and a description (``Field(description=...)``), so
the configuration reference in the README is generated from this module
(``imubench config --reference``). Environment variables override the file:
``IMUBENCH_<SECTION>__<KEY>=value`` (value parsed as a TOML value when it parses, else
taken as a string), e.g. ``IMUBENCH_MQTT__BROKER=mqtt://10.0.0.5:1883``.

Errors name the file, the key path (and line where it can be found), the bad value and
what is allowed, on one line each: they are raised as :class:`ConfigError`.
"""

from __future__ import annotations

import os
import re
import tomllib
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, ValidationInfo, field_validator

from imubench.errors import ConfigError, SourceError
from imubench.mqtt.errors import MqttError
from imubench.mqtt.topics import validate_topic_level

ENV_PREFIX = "IMUBENCH_"


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_default=True)


class SourceConfig(_Section):
    uri: str = Field(
        "sim://lsm6dsl?odr_hz=104&seed=1&clock=wall",
        description="Data source URI (unit: -): sim://CHIP?..., i2c:///dev/i2c-1?addr=0x6a&"
        "chip=lsm6dsl, sensortile:///dev/ttyACM0, sensortile-sim://?..., replay://PATH",
    )

    @field_validator("uri")
    @classmethod
    def _uri(cls, value: str) -> str:
        from imubench.sources.check import check_source_uri

        try:
            check_source_uri(value)
        except SourceError as exc:
            raise ValueError(str(exc)) from None
        return value


class LogConfig(_Section):
    enabled: bool = Field(True, description="Write a recording of every sample (unit: -)")
    path: str = Field(
        "recordings/{station}_{sensor}_{start}.imbr",
        description="Recording path (unit: -); {station}, {sensor}, {start} (UTC "
        "YYYYmmddTHHMMSSZ) are replaced; suffix .imbr (native) or .csv",
    )
    fsync_interval_s: float = Field(
        1.0, gt=0, description="Flush and fsync the recording at least this often (unit: s)"
    )


class AllanConfig(_Section):
    stats: list[Literal["oadev", "adev", "mdev", "tdev", "hdev", "ohdev", "stdev", "ostdev"]] = (
        Field(["oadev"], description="Statistics kept live (unit: -); the first is published")
    )
    taus: str = Field(
        "octave",
        description="Averaging factors (unit: -): octave, decade, N (points per decade), or "
        "a comma list of tau in seconds",
    )
    max_tau_s: float = Field(
        3600.0, gt=0, description="Largest tau kept up to date (unit: s)"
    )
    memory: Literal["exact", "bounded"] = Field(
        "bounded",
        description="Streaming engine memory mode (unit: -): bounded (state independent of "
        "tau, < 0.5 % EDF lost) or exact (keeps 3 m_max + 1 phase values per channel: "
        "2.4 GB for 6 channels at 6.66 kHz up to 3600 s)",
    )
    state_path: str | None = Field(
        None,
        description="Save the engine state here on exit and resume from it on start "
        "(unit: -); empty for none",
    )


class MqttConfig(_Section):
    broker: str = Field(
        "embedded",
        description="'embedded' (in-process broker on 127.0.0.1) or mqtt://host:port, "
        "mqtts://host:port (unit: -)",
    )
    port: int = Field(
        1883, ge=0, le=65535,
        description="Port of the embedded broker; the next free one is used if taken "
        "(unit: TCP port)",
    )
    station: str = Field("bench1", description="Station name, one MQTT topic level (unit: -)")
    sensor: str = Field("imu0", description="Sensor name, one MQTT topic level (unit: -)")
    publish_interval_s: float = Field(
        1.0, gt=0, description="Interval between Allan snapshots (unit: s)"
    )
    username: str | None = Field(None, description="Broker user name (unit: -)")
    password: str | None = Field(None, description="Broker password (unit: -)")
    tls_ca: str | None = Field(None, description="CA file for mqtts:// (unit: path)")
    qos: int = Field(0, ge=0, le=2, description="QoS of the snapshots (unit: -)")
    keepalive_s: int = Field(30, ge=5, le=3600, description="MQTT keep-alive (unit: s)")

    @field_validator("station", "sensor")
    @classmethod
    def _topic_level(cls, value: str, info: ValidationInfo) -> str:
        try:
            return validate_topic_level(value, f"mqtt.{info.field_name}")
        except MqttError as exc:
            raise ValueError(str(exc)) from None

    @field_validator("broker")
    @classmethod
    def _broker(cls, value: str) -> str:
        if value != "embedded":
            from imubench.mqtt.publisher import parse_broker_url

            try:
                parse_broker_url(value)
            except MqttError as exc:
                raise ValueError(str(exc)) from None
        return value


class DisplayConfig(_Section):
    live_table: Literal["auto", "on", "off"] = Field(
        "auto", description="Live table on the terminal (unit: -): auto = when stdout is a tty"
    )
    interval_s: float = Field(1.0, gt=0, description="Live table refresh interval (unit: s)")


class BufferConfig(_Section):
    capacity_s: float = Field(
        30.0, gt=0, description="Ring buffer capacity (unit: s of data at the source ODR)"
    )


class RunConfig(_Section):
    duration_s: float | None = Field(
        None, gt=0, description="Stop after this much data (unit: s); empty = run until signalled"
    )


class Config(_Section):
    """The whole configuration file."""

    source: SourceConfig = Field(default_factory=SourceConfig)
    log: LogConfig = Field(default_factory=LogConfig)
    allan: AllanConfig = Field(default_factory=AllanConfig)
    mqtt: MqttConfig = Field(default_factory=MqttConfig)
    display: DisplayConfig = Field(default_factory=DisplayConfig)
    buffer: BufferConfig = Field(default_factory=BufferConfig)
    run: RunConfig = Field(default_factory=RunConfig)


# -- loading -------------------------------------------------------------------------


def _parse_env_value(raw: str) -> Any:
    try:
        return tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        return raw


def env_overrides(environ: dict[str, str] | None = None) -> dict[str, Any]:
    """Nested dict from ``IMUBENCH_SECTION__KEY`` variables."""
    environ = dict(os.environ) if environ is None else environ
    out: dict[str, Any] = {}
    for name, raw in environ.items():
        if not name.startswith(ENV_PREFIX) or "__" not in name:
            continue
        path = [p.lower() for p in name[len(ENV_PREFIX):].split("__")]
        node = out
        for part in path[:-1]:
            node = node.setdefault(part, {})
        node[path[-1]] = _parse_env_value(raw)
    return out


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    merged = dict(base)
    for key, value in over.items():
        if isinstance(value, dict) and isinstance(merged.get(key), dict):
            merged[key] = _merge(merged[key], value)
        else:
            merged[key] = value
    return merged


def _find_line(text: str, loc: tuple[Any, ...]) -> int | None:
    """Best-effort 1-based line of key path ``loc`` in TOML ``text``."""
    keys = [str(k) for k in loc if not isinstance(k, int)]
    if not keys:
        return None
    section, key = keys[:-1], keys[-1]
    current: list[str] = []
    for lineno, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        m = re.fullmatch(r"\[([^\[\]]+)\]\s*(#.*)?", stripped)
        if m:
            current = [p.strip().strip('"') for p in m.group(1).split(".")]
            continue
        if current == section and re.match(rf'"?{re.escape(key)}"?\s*=', stripped):
            return lineno
    return None


def _allowed(model: type[BaseModel], loc: tuple[Any, ...]) -> str:
    """Describe what is allowed at ``loc``: known keys for an unknown key."""
    node: Any = model
    for part in loc[:-1]:
        field = getattr(node, "model_fields", {}).get(part)
        if field is None:
            return ""
        node = field.annotation
    fields = getattr(node, "model_fields", None)
    if fields is not None and loc[-1] not in fields:
        return "known keys: " + ", ".join(fields)
    return ""


def format_validation_error(
    exc: ValidationError, origin: str, text: str = "", env: dict[str, Any] | None = None
) -> str:
    lines = []
    for err in exc.errors():
        loc = tuple(err["loc"])
        key = ".".join(str(p) for p in loc) or "(top level)"
        where = origin
        env_name = ENV_PREFIX + "__".join(str(p).upper() for p in loc)
        if env and env_name in os.environ:
            where = f"environment {env_name}"
        else:
            line = _find_line(text, loc)
            if line:
                where = f"{origin}:{line}"
        msg = err["msg"]
        if err["type"] == "extra_forbidden":
            allowed = _allowed(Config, loc)
            lines.append(f"{where}: unknown key {key!r}" + (f" ({allowed})" if allowed else ""))
            continue
        if msg.startswith("Value error, "):
            msg = msg[len("Value error, "):]
        value = err.get("input")
        shown = "" if isinstance(value, dict) else f" = {value!r}"
        lines.append(f"{where}: {key}{shown}: {msg}")
    return "\n".join(lines)


def load_config(path: str | Path | None, environ: dict[str, str] | None = None) -> Config:
    """Read, merge with environment overrides, and validate a configuration file."""
    text = ""
    data: dict[str, Any] = {}
    origin = "(defaults)"
    if path is not None:
        origin = str(path)
        try:
            text = Path(path).read_text(encoding="utf-8")
        except OSError as exc:
            raise ConfigError(f"{path}: cannot read configuration: {exc.strerror}") from None
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"{path}: invalid TOML: {exc}") from None
    env = env_overrides(environ)
    try:
        return Config.model_validate(_merge(data, env))
    except ValidationError as exc:
        raise ConfigError(format_validation_error(exc, origin, text, env)) from None


def reference_markdown() -> str:
    """The configuration reference (every key, default, unit, description) as Markdown."""
    rows = ["| key | default | description |", "|---|---|---|"]
    for section_name, section_field in Config.model_fields.items():
        section = section_field.annotation
        for key, field in section.model_fields.items():  # type: ignore[union-attr]
            default = field.default if field.default_factory is None else field.default_factory()
            shown = "(none)" if default is None else f"`{default!r}`"
            rows.append(f"| `{section_name}.{key}` | {shown} | {field.description} |")
    return "\n".join(rows)
