"""The fit's temperature check: a rate that follows a varying die temperature is named
with its slope; a rate that does not (white, flicker-like and random-walk noise with the
same temperature cycle) is not, at the stated |t| limit."""

from __future__ import annotations

import numpy as np

from imubench.noisefit.temperature import T_LIMIT, temperature_slope, temperature_warning

RATE = 104.0
N = int(3600 * RATE)


def _record(seed: int, coeff: float) -> tuple[np.ndarray, np.ndarray]:
    """White 0.004 dps/sqrt(Hz) + random walk 3e-5 dps/sqrt(s) (numpy, not the simulator)
    + coeff x (25 + 4 sin(2 pi t / 900 s))."""
    rng = np.random.default_rng(seed)
    t = np.arange(N) / RATE
    temp = 25.0 + 4.0 * np.sin(2 * np.pi * t / 900.0)
    y = (0.004 * np.sqrt(RATE) * rng.standard_normal(N)
         + np.cumsum(3e-5 / np.sqrt(RATE) * rng.standard_normal(N)) + coeff * (temp - 25.0))
    return y, temp


def test_a_temperature_slope_is_found_and_measured() -> None:
    y, temp = _record(1, 0.01)
    found = temperature_slope(y, temp, RATE)
    assert found is not None
    slope, t, _ = found
    assert abs(slope / 0.01 - 1) < 0.05 and t > T_LIMIT
    text = temperature_warning("gx", "dps", y, temp, RATE)
    assert text is not None and "dps/degC" in text and text.startswith("gx: the rate follows")


def test_no_warning_without_a_temperature_effect_or_a_varying_temperature() -> None:
    warned = sum(temperature_warning("gx", "dps", *_record(seed, 0.0), RATE) is not None
                 for seed in range(100, 130))
    assert warned <= 1  # |t| > 5 on about 0 of 30 nulls, allowing one
    y, _ = _record(7, 0.01)
    assert temperature_slope(y, np.full(N, 25.0), RATE) is None  # steady: nothing to say


def test_a_recording_without_temperature_is_checked_silently() -> None:
    """A CSV without a temp column gives an all-NaN temperature: no slope, no numpy
    "Mean of empty slice" warning on the user's terminal; blocks partly lost still count."""
    import warnings

    y, temp = _record(3, 0.01)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert temperature_slope(y, np.full(N, np.nan), RATE) is None
        gappy = temp.copy()
        gappy[: 40 * int(30 * RATE)] = np.nan  # the first 40 blocks lost entirely
        found = temperature_slope(y, gappy, RATE)
    assert found is not None and abs(found[0] / 0.01 - 1) < 0.05
