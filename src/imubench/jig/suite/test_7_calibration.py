"""The calibration file: built from the six-position, rate-table and temperature fits,
written to the run directory, read back and checked to undo the errors it was fitted on."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from imubench.calibration.file import Calibration
from imubench.jig.calibrate import build_calibration, fit_board, provenance

if TYPE_CHECKING:
    from imubench.jig.session import JigSession


CALIBRATION_FILE = "calibration.toml"


def test_calibration_file(jig: JigSession) -> None:
    cal_cfg = jig.station.calibration
    fits = jig.cached("board_fits", lambda: fit_board(jig.procedures, cal_cfg))
    prov = provenance(jig.serial, jig.station.station.name, jig.dut.info.chip, jig.uri,
                      jig.run_id)
    info = jig.dut.info
    saved = build_calibration(fits, cal_cfg, prov, info.fs_dps, info.fs_g).save(
        jig.out_dir / CALIBRATION_FILE)
    jig.artifacts["calibration_file"] = CALIBRATION_FILE
    assert saved.path is not None
    back = Calibration.load(saved.path)
    assert back.accel is not None
    # read back, the file undoes the six-position errors it was fitted on, to the fit's
    # residuals (at the reference temperature, where the temperature terms are zero)
    six = jig.procedures.six_position()
    means = np.array([p.mean(slice(3, 6)) for p in six])
    truth = np.array([p.specific_force_g for p in six])
    corrected = back.accel.correct(means, np.full(len(six), back.accel.temp_ref_c))
    assert np.max(np.abs(corrected - truth)) < 3.0 * np.max(np.abs(fits.accel.residuals)) + 1e-5
