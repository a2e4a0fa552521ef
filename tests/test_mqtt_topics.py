"""Topic names, topic-filter matching (MQTT 3.1.1 §4.7 examples), packet framing, URLs, JSON."""

from __future__ import annotations

import json

import numpy as np
import pytest

from imubench.errors import ImubenchError
from imubench.mqtt.errors import MqttError
from imubench.mqtt.packets import encode_remaining_length
from imubench.mqtt.publisher import BrokerAddress, encode_json, parse_broker_url
from imubench.mqtt.topics import (
    allan_topic,
    is_valid_topic_filter,
    is_valid_topic_name,
    status_topic,
    topic_matches,
    validate_topic_level,
)


@pytest.mark.parametrize("name", ["lab1", "bench-3", "lsm6dsl_0x6a", "Küche", "a" * 64, "x.y"])
def test_validate_topic_level_accepts_plain_names(name: str) -> None:
    assert validate_topic_level(name, "mqtt.station") == name


@pytest.mark.parametrize(
    ("name", "needle"),
    [
        ("", "empty"),
        ("lab/1", "'/'"),
        ("lab+", "'+'"),
        ("lab#", "'#'"),
        ("a\x00b", "NUL"),
        ("a" * 65, "65 characters"),
        (" lab", "whitespace"),
        ("$SYS", "'$'"),
        ("lab\n1", "control character"),
    ],
)
def test_validate_topic_level_rejects_with_a_clear_message(name: str, needle: str) -> None:
    with pytest.raises(MqttError) as info:
        validate_topic_level(name, "mqtt.station")
    message = str(info.value)
    assert "mqtt.station" in message
    assert needle in message
    assert "use 1 to 64 printable characters" in message
    assert isinstance(info.value, ImubenchError)


def test_allan_and_status_topics() -> None:
    assert allan_topic("lab1", "imu0") == "imubench/lab1/imu0/allan"
    assert status_topic("lab1", "imu0") == "imubench/lab1/imu0/status"
    with pytest.raises(MqttError, match="sensor name"):
        status_topic("lab1", "imu/0")


# Examples of OASIS MQTT 3.1.1 §4.7.1.2, §4.7.1.3 and §4.7.2 (non-normative comments).
SPEC_MATCHES = [
    ("sport/tennis/player1/#", "sport/tennis/player1", True),
    ("sport/tennis/player1/#", "sport/tennis/player1/ranking", True),
    ("sport/tennis/player1/#", "sport/tennis/player1/score/wimbledon", True),
    ("sport/#", "sport", True),
    ("#", "sport/tennis", True),
    ("sport/tennis/+", "sport/tennis/player1", True),
    ("sport/tennis/+", "sport/tennis/player2", True),
    ("sport/tennis/+", "sport/tennis/player1/ranking", False),
    ("sport/+", "sport", False),
    ("sport/+", "sport/", True),
    ("+/+", "/finance", True),
    ("/+", "/finance", True),
    ("+", "/finance", False),
    ("#", "$SYS/broker/clients", False),
    ("+/monitor/Clients", "$SYS/monitor/Clients", False),
    ("$SYS/#", "$SYS/monitor/Clients", True),
    ("$SYS/monitor/+", "$SYS/monitor/Clients", True),
    ("ACCOUNTS", "Accounts", False),  # §4.7.3: case sensitive
    ("sport/tennis", "sport/tennis/player1", False),
]


@pytest.mark.parametrize(("topic_filter", "topic", "expected"), SPEC_MATCHES)
def test_topic_matches_spec_examples(topic_filter: str, topic: str, expected: bool) -> None:
    assert topic_matches(topic_filter, topic) is expected


@pytest.mark.parametrize(
    ("topic_filter", "valid"),
    [
        ("sport/tennis/#", True),
        ("#", True),
        ("+", True),
        ("+/tennis/#", True),
        ("sport/+/player1", True),
        ("sport/tennis#", False),
        ("sport/tennis/#/ranking", False),
        ("sport+", False),
        ("", False),
        ("a\x00b", False),
    ],
)
def test_topic_filter_validity(topic_filter: str, valid: bool) -> None:
    assert is_valid_topic_filter(topic_filter) is valid


def test_topic_name_validity() -> None:
    assert is_valid_topic_name("sport/tennis")
    assert is_valid_topic_name("/")
    assert not is_valid_topic_name("")
    assert not is_valid_topic_name("sport/+")
    assert not is_valid_topic_name("sport/#")


# §2.2.3 Table 2.4: size of remaining length field, boundary values.
@pytest.mark.parametrize(
    ("value", "encoded"),
    [
        (0, "00"),
        (127, "7f"),
        (128, "8001"),
        (16_383, "ff7f"),
        (16_384, "808001"),
        (2_097_151, "ffff7f"),
        (2_097_152, "80808001"),
        (268_435_455, "ffffff7f"),
    ],
)
def test_remaining_length_encoding_spec_table(value: int, encoded: str) -> None:
    assert encode_remaining_length(value).hex() == encoded


def test_remaining_length_out_of_range() -> None:
    with pytest.raises(ValueError, match="268435455"):
        encode_remaining_length(268_435_456)


@pytest.mark.parametrize(
    ("url", "expected"),
    [
        ("mqtt://broker.lan", BrokerAddress("broker.lan", 1883, False)),
        ("mqtt://10.0.0.2:1884", BrokerAddress("10.0.0.2", 1884, False)),
        ("mqtts://broker.lan", BrokerAddress("broker.lan", 8883, True)),
        ("mqtts://[::1]:9000/", BrokerAddress("::1", 9000, True)),
    ],
)
def test_parse_broker_url(url: str, expected: BrokerAddress) -> None:
    assert parse_broker_url(url) == expected


@pytest.mark.parametrize(
    ("url", "needle"),
    [
        ("http://x", "scheme 'http'"),
        ("mqtt://", "no host"),
        ("mqtt://x:99999", "not a valid URL"),
        ("mqtt://x/topic", "path"),
        ("broker.lan:1883", "scheme"),
    ],
)
def test_parse_broker_url_errors(url: str, needle: str) -> None:
    with pytest.raises(MqttError) as info:
        parse_broker_url(url)
    assert needle in str(info.value)
    assert url in str(info.value)


def test_embedded_names_no_broker_to_listen_to() -> None:
    """``embedded`` is a daemon setting; a view or a fleet listener is told to give the
    URL the daemon printed."""
    with pytest.raises(MqttError, match="--broker 'embedded': give the URL"):
        parse_broker_url("embedded", option="--broker")
    assert "or 'embedded'" not in _message("mqtt://", "--broker")
    assert "or 'embedded'" in _message("mqtt://", "mqtt.broker")


def _message(url: str, option: str) -> str:
    with pytest.raises(MqttError) as info:
        parse_broker_url(url, option=option)
    return str(info.value)


def test_encode_json_numpy_and_non_finite() -> None:
    payload = {
        "time": 1.5,
        "n_samples": np.int64(4096),
        "gx": {"tau_s": np.array([0.01, 0.02]), "dev": np.array([1e-3, np.nan]), "n": [3, 1]},
        "flag": np.bool_(True),
        "inf": float("inf"),
    }
    decoded = json.loads(encode_json(payload))
    assert decoded == {
        "time": 1.5,
        "n_samples": 4096,
        "gx": {"tau_s": [0.01, 0.02], "dev": [1e-3, None], "n": [3, 1]},
        "flag": True,
        "inf": None,
    }


def test_encode_json_names_the_bad_key() -> None:
    with pytest.raises(MqttError, match=r"payload\.gx\.dev holds a set"):
        encode_json({"gx": {"dev": {1, 2}}})
