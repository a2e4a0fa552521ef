"""One driver suite parametrised over backends: the simulated bus always, a real device
when ``--hardware i2c:/dev/i2c-1@0x6a:lsm6dsl`` names one (python-can back2back style).

The hardware runs need a board at rest (gravity on one axis); they are skipped unless
``--hardware`` is given (see tests/conftest.py and docs/drivers.md).
"""

from __future__ import annotations

import re
import time
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import pytest
from lsm6ds.driver import LSM6DS, ImuConfig
from lsm6ds.stream import FifoStream
from lsm6ds_sim.chip import SimChip
from lsm6ds_sim.clock import SimClock
from lsm6ds_sim.i2c import SimI2CBus

_HW = re.compile(r"^i2c:(?P<path>[^@]+)@(?P<addr>0x[0-9a-fA-F]+|\d+):(?P<chip>\w+)$")


@dataclass
class Backend:
    dev: LSM6DS
    sim: SimChip | None
    close: object


def hardware_i2c_devices(config: pytest.Config) -> list[str]:
    """``--hardware`` entries that name an I2C chip (``i2c:PATH@ADDR:CHIP``)."""
    return [d for d in config.getoption("--hardware") if d.startswith("i2c:")]


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    if "backend" in metafunc.fixturenames:
        params = [
            pytest.param("sim:lsm6dsl", id="sim-lsm6dsl"),
            pytest.param("sim:lsm6ds3h", id="sim-lsm6ds3h"),
        ]
        params += [
            pytest.param(d, id=d, marks=pytest.mark.hardware)
            for d in hardware_i2c_devices(metafunc.config)
        ]
        metafunc.parametrize("backend", params, indirect=True)


@pytest.fixture
def backend(request: pytest.FixtureRequest) -> Iterator[Backend]:
    spec: str = request.param
    if spec.startswith("sim:"):
        clock = SimClock()
        chip = spec.split(":", 1)[1]
        sim = SimChip(chip, clock, sim_counting=True)
        bus = SimI2CBus(clock, 400e3)
        bus.attach(0x6A, sim)
        yield Backend(
            LSM6DS(bus, chip, 0x6A, sleep=clock.sleep, monotonic=clock.now), sim, bus.close
        )
        return
    m = _HW.match(spec)
    if m is None:
        pytest.fail(f"--hardware {spec!r}: expected i2c:/dev/i2c-N@0xAA:CHIP")
    from smbus2 import SMBus

    bus = SMBus(m["path"])
    dev = LSM6DS(bus, m["chip"], int(m["addr"], 0), sleep=time.sleep, monotonic=time.monotonic)
    yield Backend(dev, None, bus.close)
    bus.close()


def test_probe_reset_configure_readback(backend: Backend) -> None:
    dev = backend.dev
    dev.probe()
    dev.reset()
    cfg = ImuConfig(odr_hz=104, fs_dps=250, fs_g=2)
    dev.configure(cfg)
    assert dev.config_intact()
    dev.wait_data_ready()
    _gyro, accel, temp = dev.read_outputs()
    assert 0.9 < np.linalg.norm(accel) < 1.1  # at rest: 1 g
    assert -40 < temp < 85


def test_self_test_passes_on_healthy_chip(backend: Backend) -> None:
    if backend.sim is not None:
        backend.sim.sim_counting = False  # the counting test signal replaces gyro X
    dev = backend.dev
    dev.probe()
    dev.reset()
    dev.configure(ImuConfig())
    result = dev.self_test()
    assert result.passed, str(result)
    assert len(result.axes) == 6


def test_self_test_fails_naming_the_axis(backend: Backend) -> None:
    if backend.sim is None:
        pytest.skip("needs the simulator's self-test control")
    backend.sim.sim_counting = False
    backend.sim.sim_self_test_gyro_lsb[1] = 500.0  # gyro Y deflection 35 dps at 2000 dps
    dev = backend.dev
    dev.configure(ImuConfig())
    result = dev.self_test()
    assert not result.passed
    assert [(a.sensor, a.axis) for a in result.failures] == [("gyro", "Y")]
    assert "gyro Y: 35.000 dps (limits 150..700) FAIL" in str(result)
    assert dev.config is not None and dev.config_intact()  # configuration restored


def test_fifo_stream_delivers_every_sample_once(backend: Backend) -> None:
    dev = backend.dev
    stream = FifoStream(dev, ImuConfig(odr_hz=208), watermark_s=0.1, bus_hz=400e3)
    stream.start()
    chunks = []
    t_end = dev.monotonic() + 3.0
    while dev.monotonic() < t_end:
        chunk, left = stream.poll()
        if chunk is not None:
            chunks.append(chunk)
        dev.sleep(stream.time_to_watermark_s(left))
    stream.stop()
    index = np.concatenate([c.index for c in chunks])
    assert np.array_equal(index, np.arange(len(index)))
    assert 600 - 64 <= len(index) <= 624
    t = np.concatenate([c.t_s for c in chunks])
    assert np.allclose(np.diff(t), 1 / 208, rtol=0.05)
    if backend.sim is not None:  # the counting signal proves identity and order
        gx = np.concatenate([c.raw[:, 0] for c in chunks]).astype(np.int64) & 0xFFFF
        assert len(np.unique((gx - index) & 0xFFFF)) == 1
