"""Noise model file (TOML): loading, rules and their error messages, round trip, copies."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest
from lsm6ds_sim.model import KEYS, ChannelModel, NoiseModel, load_model

from imubench.errors import ModelError

ISSUE_EXAMPLE = """\
[defaults]               # optional, applies to every channel
[channels.gx]            # gx gy gz in dps, ax ay az in g; omitted keys are zero
white = 0.004            # N, unit/sqrt(Hz)        AVAR term N^2/tau
flicker = 0.0005         # B, unit                 (2 ln2/pi) B^2  (flat ADEV 0.664 B)
random_walk = 0.0        # K, unit/sqrt(s)         K^2 tau/3
ramp = 0.0               # R, unit/s               R^2 tau^2/2
quantization = 0.0       # Q, unit*s               3 Q^2/tau^2
markov_sigma = 0.0       # unit, stationary std of a first-order Gauss-Markov process
markov_tau = 0.0         # s, its correlation time
sine_amplitude = 0.0     # unit, peak
sine_freq = 0.0          # Hz
outlier_rate = 0.0       # impulses per second
outlier_amplitude = 0.0  # unit, standard deviation of an impulse
bias = 0.0               # unit
temp_coeff = 0.0         # unit/degC
temp_coeff2 = 0.0        # unit/degC^2
temp_ref = 25.0          # degC
"""


def write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "model.toml"
    p.write_text(text, encoding="utf-8")
    return p


def test_issue_example_loads(tmp_path: Path) -> None:
    m = load_model(write(tmp_path, ISSUE_EXAMPLE))
    assert m["gx"].white == 0.004
    assert m["gx"].flicker == 0.0005
    assert m["gy"] == ChannelModel()  # omitted channel: every key zero, temp_ref 25
    assert m["gy"].temp_ref == 25.0


def test_defaults_apply_to_every_channel_and_channels_override(tmp_path: Path) -> None:
    m = load_model(
        write(tmp_path, "[defaults]\nwhite = 0.01\nbias = -0.2\n[channels.az]\nwhite = 0.0001\n")
    )
    assert [m[ch].white for ch in ("gx", "gy", "gz", "ax", "ay")] == [0.01] * 5
    assert m["az"].white == 0.0001
    assert m["az"].bias == -0.2  # bias is signed


@pytest.mark.parametrize("chip", ["lsm6dsl", "lsm6dsm", "lsm6ds3h"])
def test_shipped_models_load(chip: str) -> None:
    m = load_model(f"datasheet:{chip}")
    assert m.meta["chip"] == chip
    assert "unverified" in m.meta["white_source"]
    for ch in ("gx", "gy", "gz"):
        assert 0.003 <= m[ch].white <= 0.005  # dps/sqrt(Hz), reference section 11
    for ch in ("ax", "ay", "az"):
        assert 7e-5 <= m[ch].white <= 1e-4  # g/sqrt(Hz)


def test_unknown_key_names_file_table_key_and_line(tmp_path: Path) -> None:
    p = write(tmp_path, "[channels.gx]\nwhite = 0.004\nflicker_noise = 0.1\n")
    with pytest.raises(ModelError) as err:
        load_model(p)
    msg = str(err.value)
    assert str(p) in msg and "[channels.gx]" in msg and "'flicker_noise'" in msg
    assert "line 3" in msg
    assert "did you mean 'flicker'" in msg


def test_negative_magnitude_is_an_error(tmp_path: Path) -> None:
    p = write(tmp_path, "[defaults]\nwhite = 0.004\n\n[channels.ay]\nrandom_walk = -1e-5\n")
    with pytest.raises(ModelError, match=r"line 5, \[channels\.ay\] key 'random_walk'.*>= 0"):
        load_model(p)


def test_negative_in_defaults_is_an_error(tmp_path: Path) -> None:
    with pytest.raises(ModelError, match=r"line 2, \[defaults\] key 'outlier_rate'"):
        load_model(write(tmp_path, "[defaults]\noutlier_rate = -2\n"))


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("[channels.gw]\nwhite = 1\n", "unknown channel 'gw'"),
        ("[noise]\nwhite = 1\n", "unknown table or key 'noise'"),
        ('[channels.gx]\nwhite = "0.1"\n', "must be a number"),
        ("[channels.gx]\nwhite = true\n", "must be a number"),
        ("[channels.gx]\nwhite = nan\n", "must be finite"),
        ("[channels.gx]\nmarkov_sigma = 0.1\n", "needs markov_tau > 0"),
        ("[channels.gx]\nsine_amplitude = 0.1\n", "needs sine_freq > 0"),
        ("[channels.ax]\ng_sensitivity_x = 0.1\n", "gyro channels only"),
        ("[channels.gx]\ncross_x = 0.01\n", "couples gx into itself"),
        ("[defaults]\ncross_y = 0.01\n", "axis-specific"),
        ("[channels.gx]\nfilter_order = 3\n", "must be 1 or 2"),
        ("[channels.gx\nwhite = 1\n", "not valid TOML"),
    ],
)
def test_rule_violations(tmp_path: Path, text: str, needle: str) -> None:
    p = write(tmp_path, text)
    with pytest.raises(ModelError, match=needle) as err:
        load_model(p)
    assert str(p) in str(err.value)


def test_missing_file_is_a_model_error(tmp_path: Path) -> None:
    with pytest.raises(ModelError, match="cannot read"):
        load_model(tmp_path / "absent.toml")


def test_signed_keys_accept_negative_values(tmp_path: Path) -> None:
    m = load_model(
        write(
            tmp_path,
            "[channels.gz]\nbias = -0.5\nramp = -1e-4\ntemp_coeff = -0.01\n"
            "temp_coeff2 = -1e-4\ntemp_ref = -10\nscale_error = -0.02\ng_sensitivity_x = -0.1\n",
        )
    )
    assert m["gz"].bias == -0.5 and m["gz"].scale_error == -0.02


def test_to_toml_round_trip(tmp_path: Path) -> None:
    m = load_model("datasheet:lsm6dsm")
    m2 = m.with_channel("gx", markov_sigma=0.01, markov_tau=30.0, bandwidth_hz=20.0)
    p = write(tmp_path, m2.to_toml())
    back = load_model(p)
    assert back.channels == m2.channels
    assert back.meta == m2.meta


def test_written_model_states_the_units_of_its_keys() -> None:
    """A model file read by a person had no units (a reviewer's finding): every key of a
    channel table is named in the header comment with its unit."""
    from dataclasses import fields

    from lsm6ds_sim.model import UNITS_HEADER, ChannelModel

    text = NoiseModel.single_term("gx", white=0.004).to_toml()
    assert text.startswith(UNITS_HEADER) and "random_walk: u/sqrt(s)" in text
    for f in fields(ChannelModel):
        if f.name == "filter_order":  # a count
            continue
        key = f.name[:-2] + "_x/y/z" if f.name.endswith(("_x", "_y", "_z")) else f.name
        assert re.search(rf"(?<![\w/]){re.escape(key)}(?![\w])", UNITS_HEADER), f.name


def test_from_dict_names_its_source() -> None:
    with pytest.raises(ModelError, match=r"fit-output, \[channels\.gx\] key 'whte'"):
        NoiseModel.from_dict({"channels": {"gx": {"whte": 1.0}}}, source="fit-output")


def test_copy_and_modify() -> None:
    m = NoiseModel.quiet().with_all(white=0.01)
    m2 = m.with_channel("ax", white=0.0, random_walk=1e-5)
    assert m["ax"].white == 0.01 and m2["ax"].white == 0.0 and m2["ax"].random_walk == 1e-5
    assert m2["ay"] is m["ay"]
    m3 = dataclasses.replace(m2, meta={"note": "test"})
    assert m3.meta["note"] == "test" and m3.channels == m2.channels
    with pytest.raises(ModelError, match="'white'"):
        m.with_channel("gx", white=-1.0)
    with pytest.raises(ModelError, match="unknown key 'wite'"):
        m.with_channel("gx", wite=1.0)
    with pytest.raises(ModelError, match="no channel 'gq'"):
        m.with_channel("gq", white=1.0)
    assert "white" in KEYS and ChannelModel().is_quiet and not m["gx"].is_quiet
