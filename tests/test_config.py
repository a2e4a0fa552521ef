"""Configuration: defaults, env overrides, and one-line errors naming key and allowed values."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from imubench.config import Config, env_overrides, load_config, reference_markdown
from imubench.errors import ConfigError

REPO = Path(__file__).resolve().parents[1]


def write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "c.toml"
    p.write_text(text)
    return p


def test_quickstart_config_is_valid() -> None:
    cfg = load_config(REPO / "config" / "quickstart.toml", environ={})
    assert cfg.mqtt.broker == "embedded"
    assert cfg.source.uri.startswith("sim://lsm6dsl")


def test_every_setting_has_default_unit_and_description() -> None:
    for section in Config.model_fields.values():
        for name, field in section.annotation.model_fields.items():  # type: ignore[union-attr]
            assert field.description and "unit:" in field.description, name
    assert "`mqtt.broker`" in reference_markdown()


def test_unknown_key_names_key_line_and_known_keys(tmp_path: Path) -> None:
    p = write(tmp_path, "[mqtt]\nbroker = 'embedded'\nstaton = 'x'\n")
    with pytest.raises(ConfigError) as err:
        load_config(p, environ={})
    msg = str(err.value)
    assert f"{p}:3" in msg and "mqtt.staton" in msg and "station" in msg
    assert "\n" not in msg


def test_wrong_type_names_key_and_value(tmp_path: Path) -> None:
    p = write(tmp_path, "[mqtt]\nport = 'abc'\n")
    with pytest.raises(ConfigError) as err:
        load_config(p, environ={})
    assert f"{p}:2: mqtt.port = 'abc'" in str(err.value)


def test_odr_not_available_lists_allowed_values(tmp_path: Path) -> None:
    p = write(tmp_path, '[source]\nuri = "sim://lsm6dsl?odr_hz=100"\n')
    with pytest.raises(ConfigError) as err:
        load_config(p, environ={})
    msg = str(err.value)
    assert "source.uri" in msg and "100" in msg
    for allowed in ("12.5", "104", "6660"):
        assert allowed in msg


def test_gyro_odr_limit_of_lsm6ds3h(tmp_path: Path) -> None:
    p = write(tmp_path, '[source]\nuri = "sim://lsm6ds3h?odr_hz=3330"\n')
    with pytest.raises(ConfigError, match="gyro ODR 3330"):
        load_config(p, environ={})


@pytest.mark.parametrize("bad", ["a/b", "a+b", "#", "", "$SYS"])
def test_station_names_refuse_mqtt_wildcards_and_separators(tmp_path: Path, bad: str) -> None:
    p = write(tmp_path, f'[mqtt]\nstation = "{bad}"\n')
    with pytest.raises(ConfigError, match=r"mqtt\.station"):
        load_config(p, environ={})


def test_env_override_nested_and_typed(tmp_path: Path) -> None:
    env = {"IMUBENCH_MQTT__PORT": "1999", "IMUBENCH_MQTT__BROKER": "mqtt://10.1.2.3:1884",
           "OTHER": "x"}
    assert env_overrides(env) == {"mqtt": {"port": 1999, "broker": "mqtt://10.1.2.3:1884"}}
    cfg = load_config(write(tmp_path, "[mqtt]\nport = 1000\n"), environ=env)
    assert cfg.mqtt.port == 1999 and cfg.mqtt.broker.endswith(":1884")


def test_cli_reports_one_line_and_nonzero(tmp_path: Path) -> None:
    p = write(tmp_path, '[source]\nuri = "sim://lsm6dsl?odr_hz=100"\n')
    proc = subprocess.run([sys.executable, "-m", "imubench.cli", "run", "--config", str(p)],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "source.uri" in lines[0] and "104" in lines[0]
