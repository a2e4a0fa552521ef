"""The board's tilt error budget before and after each calibration step (worst case and
RSS, the noise multiplier from the station's mission), written as ``tilt_budget.toml``
(``imubench tilt --budget`` prints it) and shown in the report."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from imubench.calibration.means import capture_mean
from imubench.jig import analysis
from imubench.jig.calibrate import fit_board, tilt_budget
from imubench.tilt.budget import load_budget

if TYPE_CHECKING:
    from imubench.jig.session import JigSession


BUDGET_FILE = "tilt_budget.toml"


def test_tilt_budget(jig: JigSession) -> None:
    st = jig.station
    fits = jig.cached("board_fits", lambda: fit_board(jig.procedures, st.calibration))
    static = jig.procedures.static()
    ch = f"a{st.tilt.axis}"
    cap = static.capture
    lsb = float(cap.lsb[3 + "xyz".index(st.tilt.axis)])
    density = analysis.noise_density(cap, ch, jig.confidence).value
    level = [p for p in jig.procedures.six_position()
             if p.specific_force_g["xyz".index(st.tilt.axis)] == 0.0]
    se = capture_mean(level[0].capture.channel(ch), cap.odr_hz, lsb, "level").stderr
    budget = tilt_budget(fits, density, cap.odr_hz, se, st.tilt, st.calibration,
                         f"tilt error budget of board {jig.serial}")
    path = jig.out_dir / BUDGET_FILE
    path.write_text(budget.to_toml())
    jig.artifacts["tilt_budget"] = {"file": BUDGET_FILE, "text": budget.render()}
    back = load_budget(path)
    wc = back.worst_case_g()
    assert np.allclose(wc, budget.worst_case_g())
    # the calibrated worst case is NOT asserted below the raw one: on a board whose raw
    # errors are below the calibration's own 3-standard-error terms, calibrating adds
    # more than it removes (a near-perfect accelerometer, 0.44 -> 0.82 mg, failed the
    # board here); the budget shows both and the user decides
