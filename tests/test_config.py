"""Configuration: defaults, typed environment overrides, every value checked at load time,
one-line errors naming file, line, key, value and what is allowed, secrets never shown."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from imubench.config import (
    MAX_POINTS_PER_DECADE,
    Config,
    config_sections,
    load_config,
    quickstart_file,
    reference_markdown,
)
from imubench.errors import ConfigError

REPO = Path(__file__).resolve().parents[1]
SECRET = "hunter2-s3cret"


@pytest.fixture(autouse=True)
def _no_imubench_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in list(os.environ):
        if name.upper().startswith("IMUBENCH_"):
            monkeypatch.delenv(name)


def write(tmp_path: Path, text: str, name: str = "c.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def refused(path: Path) -> str:
    """The ConfigError message of ``path`` (asserting there is one, on one line)."""
    with pytest.raises(ConfigError) as err:
        load_config(path)
    msg = str(err.value)
    assert "\n" not in msg, msg
    return msg


def test_quickstart_config_is_valid() -> None:
    cfg = load_config(quickstart_file())
    assert cfg.mqtt.broker == "embedded"
    assert cfg.source.uri.startswith("sim://lsm6dsl")
    assert "model=datasheet:lsm6dsl" in cfg.source.uri


JIG_FILES = ("limits-", "station-", "tilt-budget-")
"""config/ also ships jig limit, station and tilt-budget files (docs/jig.md)."""


def test_example_configs_are_valid() -> None:
    examples = sorted(p for p in (REPO / "config").glob("*.toml")
                      if not p.name.startswith(JIG_FILES))
    assert examples, "config/ holds the example daemon configurations"
    for p in examples:
        load_config(p)


def test_every_setting_has_default_unit_and_description() -> None:
    sections = config_sections()
    assert {name for name, _ in sections} >= set(Config.model_fields) - {"sensors"}
    for _, section in sections:
        for name, field in section.model_fields.items():
            assert field.description and "unit:" in field.description, name
    assert "`mqtt.broker`" in reference_markdown()


def test_readme_table_is_the_generated_reference() -> None:
    readme = (REPO / "README.md").read_text()
    assert reference_markdown() in readme, "README table differs: paste `imubench run " \
        "--config-reference` into README.md"


def test_unknown_key_names_key_line_and_known_keys(tmp_path: Path) -> None:
    p = write(tmp_path, "[mqtt]\nbroker = 'embedded'\nstaton = 'x'\n")
    msg = refused(p)
    assert f"{p}:3" in msg and "mqtt.staton" in msg and "station" in msg


def test_wrong_type_names_key_and_value(tmp_path: Path) -> None:
    p = write(tmp_path, "[mqtt]\nport = 'abc'\n")
    assert f"{p}:2: mqtt.port = 'abc'" in refused(p)


def test_odr_not_available_lists_allowed_values(tmp_path: Path) -> None:
    msg = refused(write(tmp_path, '[source]\nuri = "sim://lsm6dsl?odr_hz=100"\n'))
    assert "source.uri" in msg and "100" in msg
    for allowed in ("12.5", "104", "6660"):
        assert allowed in msg


def test_gyro_odr_limit_of_lsm6ds3h(tmp_path: Path) -> None:
    p = write(tmp_path, '[source]\nuri = "sim://lsm6ds3h?odr_hz=3330"\n')
    with pytest.raises(ConfigError, match="gyro ODR 3330"):
        load_config(p)


@pytest.mark.parametrize("bad", ["a/b", "a+b", "#", "", "$SYS"])
def test_station_names_refuse_mqtt_wildcards_and_separators(tmp_path: Path, bad: str) -> None:
    p = write(tmp_path, f'[mqtt]\nstation = "{bad}"\n')
    with pytest.raises(ConfigError, match=r"mqtt\.station"):
        load_config(p)


# -- environment overrides, typed by field -------------------------------------------


def test_env_values_are_typed_by_the_field(tmp_path: Path, monkeypatch: pytest.MonkeyPatch
                                           ) -> None:
    monkeypatch.setenv("IMUBENCH_MQTT__PASSWORD", "12345")
    monkeypatch.setenv("IMUBENCH_MQTT__USERNAME", "007")
    monkeypatch.setenv("IMUBENCH_MQTT__PORT", "1999")
    monkeypatch.setenv("IMUBENCH_MQTT__BROKER", "mqtt://10.1.2.3:1884")
    monkeypatch.setenv("IMUBENCH_ALLAN__STATS", "mdev,oadev")
    monkeypatch.setenv("IMUBENCH_LOG__ENABLED", "false")
    cfg = load_config(write(tmp_path, "[mqtt]\nport = 1000\nusername = 'file'\n"))
    assert cfg.mqtt.password is not None and cfg.mqtt.password.get_secret_value() == "12345"
    assert cfg.mqtt.username == "007"  # a string, not the integer 7
    assert cfg.mqtt.port == 1999 and cfg.mqtt.broker.endswith(":1884")  # env beats the file
    assert cfg.allan.stats == ["mdev", "oadev"] and cfg.log.enabled is False


def test_env_error_names_the_variable(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("IMUBENCH_MQTT__PORT", "abc")
    with pytest.raises(ConfigError) as err:
        load_config(None)
    assert str(err.value).startswith("environment IMUBENCH_MQTT__PORT: mqtt.port = 'abc'")


@pytest.mark.parametrize("name", ["IMUBENCH_MQTT_PORT", "IMUBENCH_MQTT__PROT"])
def test_misspelt_env_variable_is_refused(monkeypatch: pytest.MonkeyPatch, name: str) -> None:
    monkeypatch.setenv(name, "1884")
    with pytest.raises(ConfigError, match=f"environment {name}"):
        load_config(None)


# -- values that used to pass --check and fail at run time (issue #12) ------------------


@pytest.mark.parametrize(("toml", "key", "allowed"), [
    ('[allan]\ntaus = "abc"', "allan.taus = 'abc'", "octave"),
    ('[allan]\ntaus = "all"', "allan.taus = 'all'", "octave, decade"),
    (f'[allan]\ntaus = "{MAX_POINTS_PER_DECADE + 1}"', "allan.taus",
     f"1 to {MAX_POINTS_PER_DECADE}"),
    ('[allan]\ntaus = "1e-9,1e-8"', "allan.taus", "no averaging factor"),
    ('[log]\npath = "{nope}"', "log.path = '{nope}'", "{station}, {sensor}, {start}"),
    ('[log]\npath = "r/{start:%Y}.imbr"', "log.path", "no format spec"),
    ('[log]\npath = "r/{station.imbr"', "log.path", "literal brace"),
    ('[log]\npath = "r/{station}.txt"', "log.path", ".imbr"),
    ("[buffer]\ncapacity_s = 1e9", "buffer.capacity_s = 1000000000.0", "capacity_s <="),
    ('[allan]\nmemory = "exact"\nmax_tau_s = 1e6\n[source]\nuri = "sim://lsm6dsl?odr_hz=6660"',
     "buffer.capacity_s", "allan.memory = 'bounded'"),
    ("[allan]\nmax_tau_s = 1e300", "allan.max_tau_s", "less than or equal to 1000000"),
    ("[mqtt]\npublish_interval_s = 1e-300", "mqtt.publish_interval_s", "greater than"),
    ("[run]\nduration_s = inf", "run.duration_s", "finite"),
    ('[source]\nuri = "sim://lsm6dsl?model=datasheet:lsm6dsx"', "source.uri", "lsm6dsm"),
    ('[source]\nuri = "sim://lsm6dsl?model=nope/m.toml"', "source.uri", "No such file"),
    ('[source]\nuri = "replay://nope/rec.imbr"', "source.uri", "no recording at"),
    ('[mqtt]\nbroker = "mqtts://localhost:8883"\ntls_ca = "nope/ca.pem"', "mqtt.tls_ca", "no such"),
])
def test_run_time_failures_are_refused_at_load(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                               toml: str, key: str, allowed: str) -> None:
    monkeypatch.chdir(tmp_path)
    p = write(tmp_path, toml + "\n")
    msg = refused(p)
    assert msg.startswith(f"{p}:"), msg  # file and line
    assert key in msg and allowed in msg, msg


def test_state_path_is_a_file_whose_folder_can_be_made(tmp_path: Path) -> None:
    assert f"{tmp_path} is a directory" in refused(
        write(tmp_path, f'[allan]\nstate_path = "{tmp_path}"\n'))
    blocker = tmp_path / "plain-file"
    blocker.write_text("x")
    msg = refused(write(tmp_path, f'[allan]\nstate_path = "{blocker}/sub/state.npz"\n'))
    assert "allan.state_path" in msg and "is not a directory" in msg
    cfg = load_config(write(tmp_path, f'[allan]\nstate_path = "{tmp_path}/new/dir/s.npz"\n'))
    assert cfg.allan.state_path == f"{tmp_path}/new/dir/s.npz"
    assert not (tmp_path / "new").exists()  # checking creates nothing


def test_log_folder_must_be_creatable(tmp_path: Path) -> None:
    blocker = tmp_path / "plain-file"
    blocker.write_text("x")
    msg = refused(write(tmp_path, f'[log]\npath = "{blocker}/{{station}}.imbr"\n'))
    assert "log.path" in msg and "is not a directory" in msg


@pytest.mark.skipif(shutil.which("openssl") is None, reason="openssl not installed")
def test_tls_ca_must_be_a_pem_ca_and_need_mqtts(tmp_path: Path) -> None:
    ca = tmp_path / "ca.pem"
    subprocess.run(["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1",
                    "-subj", "/CN=imubench-test", "-keyout", str(tmp_path / "k.pem"),
                    "-out", str(ca)], check=True, capture_output=True, timeout=60)
    good = f'[mqtt]\nbroker = "mqtts://127.0.0.1:8883"\ntls_ca = "{ca}"\n'
    assert load_config(write(tmp_path, good)).mqtt.tls_ca == str(ca)
    junk = tmp_path / "junk.pem"
    junk.write_text("not a certificate\n")
    assert "not a PEM CA certificate" in refused(write(tmp_path, good.replace(str(ca), str(junk))))
    msg = refused(write(tmp_path, good.replace("mqtts://", "mqtt://")))
    assert "mqtt.tls_ca" in msg and "mqtts://" in msg
    # A client certificate needs its key, a matching one, and an mqtts:// broker.
    key = tmp_path / "k.pem"
    with_cert = good + f'tls_cert = "{ca}"\n'
    assert "go together" in refused(write(tmp_path, with_cert))
    both = with_cert + f'tls_key = "{key}"\n'
    assert load_config(write(tmp_path, both)).mqtt.tls_key == str(key)
    other_key = tmp_path / "k2.pem"
    subprocess.run(["openssl", "genrsa", "-out", str(other_key), "2048"], check=True,
                   capture_output=True, timeout=60)
    msg = refused(write(tmp_path, both.replace(str(key), str(other_key))))
    assert "mqtt.tls_cert" in msg and "key values mismatch" in msg, msg
    msg = refused(write(tmp_path, both.replace("mqtts://", "mqtt://")))
    assert "mqtt.tls_cert" in msg and "mqtts://" in msg


def test_tau_specs_from_toml_numbers_and_lists(tmp_path: Path) -> None:
    cfg = load_config(write(tmp_path, "[allan]\ntaus = [1, 10, 100]\n"))
    assert cfg.allan.tau_spec == [1.0, 10.0, 100.0]
    assert load_config(write(tmp_path, "[allan]\ntaus = 8\n")).allan.tau_spec == 8
    assert load_config(write(tmp_path, '[allan]\ntaus = "decade"\n')).allan.tau_spec == "decade"


# -- secrets --------------------------------------------------------------------------


def test_password_never_in_dumps_reprs_or_messages(tmp_path: Path,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    cfg = load_config(write(tmp_path, f'[mqtt]\nusername = "u"\npassword = "{SECRET}"\n'))
    assert cfg.mqtt.password is not None and cfg.mqtt.password.get_secret_value() == SECRET
    for text in (repr(cfg), str(cfg), str(cfg.public_dump()), cfg.model_dump_json()):
        assert SECRET not in text
    assert cfg.public_dump()["mqtt"]["password"] == "**********"
    # a refused password is not echoed either (file and environment)
    msg = refused(write(tmp_path, "[mqtt]\npassword = 424242\n"))
    assert "mqtt.password" in msg and "424242" not in msg
    monkeypatch.setenv("IMUBENCH_MQTT__PASSWORD", SECRET)
    monkeypatch.setenv("IMUBENCH_MQTT__PORT", "99999")
    with pytest.raises(ConfigError) as err:
        load_config(None)
    assert SECRET not in str(err.value)


# -- through the command line -----------------------------------------------------------


def test_cli_reports_one_line_and_exit_2(tmp_path: Path) -> None:
    p = write(tmp_path, '[source]\nuri = "sim://lsm6dsl?odr_hz=100"\n')
    proc = subprocess.run([sys.executable, "-m", "imubench", "run", "--config", str(p),
                           "--check"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "source.uri" in lines[0] and "104" in lines[0]


def test_cli_check_and_print_quickstart(tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if not k.startswith("IMUBENCH_")}
    shown = subprocess.run([sys.executable, "-m", "imubench", "run", "--print-quickstart"],
                           capture_output=True, text=True, timeout=60, env=env, check=True)
    assert shown.stdout == quickstart_file().read_text()
    copy = write(tmp_path, shown.stdout, "mine.toml")
    ok = subprocess.run([sys.executable, "-m", "imubench", "run", "--config", str(copy),
                         "--check"], capture_output=True, text=True, timeout=60, env=env)
    assert ok.returncode == 0 and ok.stdout.strip() == f"{copy}: configuration is valid"
    ref = subprocess.run([sys.executable, "-m", "imubench", "run", "--config-reference"],
                         capture_output=True, text=True, timeout=60, env=env, check=True)
    assert ref.stdout.strip() == reference_markdown()
    assert re.search(r"^\| `mqtt\.password` \| \(none\) \|", ref.stdout, re.M)


def test_a_sim_model_resonance_above_the_sources_nyquist_is_refused_at_load(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """`run --check` said "valid" for a model whose resonance the sim source's ODR cannot
    carry; the daemon then refused it only when the first sample was drawn."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "m.toml").write_text("[channels.gz]\nresonance_freq_hz = 60.0\n"
                                     "resonance_width_hz = 2.0\nresonance_height = 1e-3\n")
    msg = refused(write(tmp_path, '[source]\nuri = "sim://lsm6dsl?odr_hz=104&model=m.toml"\n'))
    assert "source.uri" in msg and "m.toml: [channels.gz] resonance_freq_hz = 60 Hz" in msg
    assert "Nyquist frequency 52 Hz" in msg, msg
    ok = write(tmp_path, '[source]\nuri = "sim://lsm6dsl?odr_hz=208&model=m.toml"\n')
    assert load_config(ok).source.uri.endswith("model=m.toml")


def test_a_long_path_never_cuts_the_fix_out_of_an_error(tmp_path: Path) -> None:
    """With a temporary path a few characters longer, the shortening of long quoted
    values took the text between two of them for one and cut the fix away."""
    deep = tmp_path / ("d" * 60) / ("e" * 40)
    deep.mkdir(parents=True)
    ca = deep / "ca.pem"
    subprocess.run(["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1",
                    "-subj", "/CN=imubench-test", "-keyout", str(deep / "k.pem"),
                    "-out", str(ca)], check=True, capture_output=True, timeout=60)
    msg = refused(write(deep, f'[mqtt]\nbroker = "mqtt://127.0.0.1:8883"\ntls_ca = "{ca}"\n'))
    assert "only used with an mqtts:// broker" in msg, msg
