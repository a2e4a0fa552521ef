"""Shared pytest fixtures and options."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_REFERENCE = REPO.parent / "shared" / "reference"


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--hardware",
        action="append",
        default=[],
        metavar="DEVICE",
        help="run hardware tests on DEVICE, e.g. i2c:/dev/i2c-1@0x6a:lsm6dsl or "
        "sensortile:/dev/ttyACM0 (repeatable)",
    )


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if config.getoption("--hardware"):
        return
    skip = pytest.mark.skip(reason="hardware test: pass --hardware DEVICE to run it")
    for item in items:
        if "hardware" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(scope="session")
def reference_dir() -> Path:
    """``../shared/reference`` beside the repo; skips the test cleanly when absent."""
    if not SHARED_REFERENCE.is_dir():
        pytest.skip(f"shared reference data not found at {SHARED_REFERENCE}")
    return SHARED_REFERENCE


from mqtt_fixtures import embedded_broker, mqtt_broker, private_mosquitto  # noqa: E402, F401
