"""Bias factors against Stable32 outputs and an independent TOTDEV estimator."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from imubench.errors import StatsError
from imubench.stats.bias import bias_factor
from tests.test_stats_ci_limits import load_stable32

S32 = "allantools-stable32"


def test_theo1_flicker_pm_factor_from_stable32(reference_dir: Path) -> None:
    _, corrected = load_stable32(reference_dir / S32 / "phasedat" / "phase_dat_theo1.txt")
    _, raw = load_stable32(reference_dir / S32 / "phasedat" / "phase_dat_theo1_alpha0.txt")
    assert np.array_equal(corrected[:, 0], raw[:, 0]) and len(raw) == 181
    for row_c, row_r in zip(corrected, raw, strict=True):
        m = int(row_c[0])
        assert bias_factor("theo1", 0, m, 1001) == 1.0
        expected = row_r[5] ** 2 / bias_factor("theo1", 1, m, 1001)
        assert expected == pytest.approx(row_c[5] ** 2, rel=3e-4)


def test_htot_factor_from_stable32(reference_dir: Path) -> None:
    _, corrected = load_stable32(reference_dir / S32 / "phasedat" / "phase_dat_htotdev_octave.txt")
    _, raw = load_stable32(reference_dir / S32 / "phasedat" / "phase_dat_htotdev_octave_nobias.txt")
    for row_c, row_r in zip(corrected, raw, strict=True):
        m, alpha = int(row_c[0]), int(row_c[3])
        b = bias_factor("htotdev", alpha, m, 1001)
        assert row_r[5] ** 2 / b == pytest.approx(row_c[5] ** 2, rel=2e-4), (m, alpha)
    assert bias_factor("htotvar", 0, 2, 1001) == pytest.approx(0.995)


def test_totvar_factor_against_allantools_on_ocxo(reference_dir: Path) -> None:
    """Stable32's corrected TOTDEV = allantools' raw TOTDEV / sqrt(B) at FFM/RWFM rows."""
    allantools = pytest.importorskip("allantools")
    f = np.loadtxt(reference_dir / S32 / "ocxo" / "ocxo_frequency.txt")
    y = f / 1e7 - 1.0
    n_phase = y.size + 1
    _, rows = load_stable32(reference_dir / S32 / "ocxo" / "totdev_octave.txt")
    rows = rows[(rows[:, 3] < 0) & (rows[:, 0] >= 128)]
    taus = rows[:, 0]
    _, raw, _, _ = allantools.totdev(y, rate=1.0, data_type="freq", taus=taus)
    for row, dev_raw in zip(rows, raw, strict=True):
        m, alpha = int(row[0]), int(row[3])
        b = bias_factor("totdev", alpha, m, n_phase)
        assert b < 1.0
        assert dev_raw / np.sqrt(b) == pytest.approx(row[5], rel=2e-3), m
    # without the factor the large-m rows miss by more than the file's 2e-3 noise
    assert abs(raw[-1] / rows[-1, 5] - 1) > 5e-3


def test_no_bias_stats_and_errors() -> None:
    for stat in ("adev", "oadev", "mdev", "tdev", "hdev", "ohdev", "mtotdev", "ttotdev"):
        assert bias_factor(stat, -1, 8, 1000) == 1.0
    assert bias_factor("totvar", 0, 8, 1000) == 1.0
    assert bias_factor("htotvar", -1, 1, 1000) == 1.0
    with pytest.raises(StatsError, match="unknown statistic"):
        bias_factor("foo", 0, 1, 10)
    with pytest.raises(StatsError, match="too large"):
        bias_factor("totvar", -2, 2000, 1000)
