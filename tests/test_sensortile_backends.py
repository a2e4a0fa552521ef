"""One SensorTile suite parametrised over backends: the simulated firmware on a pty
always, a real kit when ``--hardware sensortile:/dev/ttyACM0`` names one (python-can
back2back style; see docs/drivers.md "Hardware tests" and docs/sensortile.md).

The kit must run the DataLogExtended firmware (binary protocol) and lie still, one axis
vertical. Both backends go through ``sensortile://PORT`` (the real-kit source), on a
wall clock.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
from lsm6ds.sensortile.link import LinkConfig, SensorTileLink

from imubench.batch import Batch
from imubench.sources.registry import open_source

pytestmark = pytest.mark.timeout(120)


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    if "tile_port" in metafunc.fixturenames:
        params = [pytest.param("sim", id="sim-firmware")]
        params += [
            pytest.param(d.split(":", 1)[1], id=d, marks=pytest.mark.hardware)
            for d in metafunc.config.getoption("--hardware")
            if d.startswith("sensortile:")
        ]
        metafunc.parametrize("tile_port", params, indirect=True)


@pytest.fixture
def tile_port(request: pytest.FixtureRequest) -> Iterator[str]:
    """A pyserial URL of a kit: the simulated firmware's pty, or the real port."""
    if request.param != "sim":
        yield request.param
        return
    from lsm6ds_sim.clock import SimClock
    from lsm6ds_sim.sensortile_fw import SensorTileFirmware

    with SensorTileFirmware(clock=SimClock("wall"), seed=5) as fw:
        yield fw.url


def test_ping_and_presentation_identify_the_kit(tile_port: str) -> None:
    with SensorTileLink(tile_port, "binary", LinkConfig()) as link:
        link.ping()
        text = link.presentation()
        firmware_id = link.check_mode()
    assert "STLKT01V1" in text, f"presentation {text!r} should name the SensorTile board"
    assert firmware_id == 101  # DataLogExtended


def test_stream_at_rest_every_frame_once_and_in_order(tile_port: str) -> None:
    src = open_source(f"sensortile://{tile_port}?duration_s=1.5")
    with src:
        batches = list(src)
    batch = Batch.concat(batches)
    assert len(batch) > 50
    assert np.all(np.diff(batch.index) > 0)
    assert len(batch) + src.counters["lost_samples"] == int(batch.index[-1]) + 1
    accel = batch.values[:, 3:]
    assert np.all(np.abs(np.linalg.norm(accel, axis=1) - 1.0) < 0.1)  # at rest: 1 g
    assert np.all(np.abs(batch.values[:, :3]) < 10.0)  # at rest: a few dps of bias at most
