"""Where a fitted model's Allan variance lies beyond the scatter of the estimates.

An overlapping Allan variance estimate is distributed as ``A chi2_nu / nu`` about the
true ``A``, with ``nu`` its equivalent degrees of freedom (NIST SP 1065, section 5.3,
eq. 44). The fit adds a relative discrepancy floor ``delta`` to every point (its model
error), so a point's relative variance is ``2 / nu + delta^2`` and it is compared with
``chi2_nu_eff / nu_eff`` at ``nu_eff = 2 / (2 / nu + delta^2)``. A point whose ratio
``avar / model`` lies beyond the two-sided family-wise level :data:`MISFIT_ALPHA`
(Bonferroni over the points and both tails) is one the model cannot have produced.

The model selection compares models by the GLS chi-squared of the AVAR points, a normal
approximation whose variance is taken at the fuller model; for the few degrees of freedom
of the longest taus it counts a point far above a smaller model as about one standard
deviation away, while the chi-squared distribution puts it far out in its tail. An outside
reviewer's phone gyro (Samsung S5 gy, 2 h at 10 Hz): the random walk's drop 4.7 stayed
under its entry level 5.41, and the model's ADEV at 410, 819 and 1638 s was 1.75, 2.6 and
5.1 times below the record's (tail probabilities 8e-6, 4e-9 and 1e-16 at 19, 8 and 3 edf).
The fit then states the misfit (:func:`curve_misfit`) instead of leaving it to the plots.
"""

from __future__ import annotations

import numpy as np
from scipy.stats import chi2 as chi2_dist

from imubench.batch import true_runs

MISFIT_ALPHA = 1e-3
"""Family-wise probability that a correct model's curve is said to misfit somewhere."""


MODEL_FILE_FLOOR = 0.1
"""The relative model error allowed a model that was not fitted to the recording (``imubench
report --model``: another fit of the same sensor, a datasheet model): 10 % in AVAR,
the size of the fits' own floors on real curves (:data:`BROAD_FLOOR`)."""


def curve_misfit(tau_s: np.ndarray, avar: np.ndarray, model_avar: np.ndarray,
                 edf: np.ndarray, delta: float, *, fitted: bool = True) -> list[str]:
    """Sentences naming each run of taus (s) where the model's AVAR lies beyond the
    estimates' scatter (module docstring), worst first; empty where the curve fits.
    ``fitted``: the model was fitted to this curve (the sentences then name the term it
    lacks); else it was given (a model file), and they say that it does not describe the
    recording there."""
    tau_s, avar, model_avar, edf = (np.asarray(v, dtype=float)
                                    for v in (tau_s, avar, model_avar, edf))
    ok = np.isfinite(avar) & np.isfinite(model_avar) & (model_avar > 0) & (edf > 0)
    n = int(ok.sum())
    if n == 0:
        return []
    nu = np.where(ok, 2.0 / (2.0 / np.where(ok, edf, 1.0) + delta * delta), np.nan)
    ratio = np.where(ok, avar / np.where(ok, model_avar, 1.0), np.nan)
    level = MISFIT_ALPHA / (2.0 * n)
    with np.errstate(invalid="ignore"):
        p_hi = np.where(ok, chi2_dist.sf(nu * ratio, nu), 1.0)
        p_lo = np.where(ok, chi2_dist.cdf(nu * ratio, nu), 1.0)
    out: list[tuple[float, str]] = []
    for flags, p, word in ((p_hi < level, p_hi, "under-predicts"),
                           (p_lo < level, p_lo, "over-predicts")):
        for a, b in true_runs(flags):
            adev = np.sqrt(ratio[a:b + 1])
            where = (f"{tau_s[a]:.4g} s" if a == b else f"{tau_s[a]:.4g}-{tau_s[b]:.4g} s")
            ratios = (f"{adev[0]:.3g}x" if a == b else
                      f"{adev.min():.3g}-{adev.max():.3g}x")
            if not fitted:
                cause = ("it does not describe this recording there, and its values there "
                         "are not this sensor's")
            elif word == "over-predicts":
                cause = "a term fitted too large there"
            elif b == len(flags) - 1:  # up to the longest tau
                cause = ("a slow term the selection did not keep (a random walk, ramp, "
                         "flicker or a temperature response; see the upper limits of the "
                         "terms judged absent)")
            else:
                cause = "a term the model lacks there"
            worst = float(p[a:b + 1].min())
            out.append((worst, (
                f"the model {word} the Allan deviation at {where} (the record's is "
                f"{ratios} the model's, beyond the {100 * (1 - MISFIT_ALPHA):g} % "
                f"family-wise band of the estimates' scatter, tail probability "
                f"{worst:.1g} at {nu[a:b + 1][np.argmin(p[a:b + 1])]:.3g} edf): {cause}")))
    return [text for _, text in sorted(out)]


BROAD_FLOOR = 0.4
"""A discrepancy floor from which the model is said to miss the curve broadly
(:func:`broad_misfit`): the fits of the ADIS16405 gyros, the Samsung S5's six axes over
6 h and the MTi-G, which follow their curves, have 0-0.17."""


def broad_misfit(delta: float) -> list[str]:
    """A note (a list of one, or empty) when the fit's discrepancy floor ``delta`` is
    :data:`BROAD_FLOOR` or more: the floor widens every point, so :func:`curve_misfit`
    can then stay silent where the misfit is largest (an outside reviewer: a sine of
    period 300 s over white noise, 3.2x above the model at 327-655 s, delta 0.68;
    `--terms white` on a random walk, delta 2)."""
    if not delta >= BROAD_FLOOR:
        return []
    return [f"the model misses the Allan curve broadly: its AVAR departs from the record's "
            f"by about {100 * delta:.0f} % (rms) beyond the estimates' scatter, a term the "
            "model lacks or one the record does not hold; the per-tau misfit test is "
            "widened by that floor and may name no taus: compare the curves (imubench "
            "report)"]

