"""Allan-curve-shaped effects fitted on the residual between the real and model curves.

The model's expected AVAR (mean of K realisations) plus one term's analytic AVAR
(:mod:`lsm6ds_sim.noise`, IEEE Std 952-1997 Annex C) is fitted to the real AVAR by
weighted least squares in ln AVAR; weights are the combined band of
:mod:`imubench.gap.curves`. The term's parameter is the one that ADDS to the model; the
reported value is the model-file key's total (for noise powers ``sqrt(p0^2 + p^2)``).

====================  ==========================  ===============================
effect                model keys                  AVAR added (tau = m tau0)
====================  ==========================  ===============================
flicker               flicker B                   (2 ln2 / pi) B^2
random_walk           random_walk K               K^2 tau / 3
quantization          quantization Q              3 Q^2 / tau^2
markov                markov_sigma, markov_tau    IEEE 952 C.6
base_model            bandwidth_hz, filter_order  exact sampled AVAR of the filtered
                      and white, refitted         model, imubench.noisefit.model_avar
====================  ==========================  ===============================

The base model (white level, output filter) is not additive: its refit scales the model's
expected curve by ``model_avar(cm') / model_avar(cm)`` where ``cm'`` carries the filter
(Butterworth, bilinear; the noise fit's exact sampled-data AVAR) and a refitted white density (a
filter lowers the short-tau curve; the white level that the unfiltered model had fitted
usually compromised between both ends). The ramp is fitted in time, not here
(:mod:`imubench.gap.evidence`: least-squares slope of the block means).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from lsm6ds_sim.model import ChannelModel
from lsm6ds_sim.noise import (
    avar_flicker,
    avar_markov,
    avar_quantization,
    avar_random_walk,
)
from scipy.optimize import minimize_scalar

Basis = Callable[[np.ndarray, float], np.ndarray]

BASES: dict[str, Basis] = {
    "flicker": avar_flicker,
    "random_walk": avar_random_walk,
    "quantization": avar_quantization,
}
"""Single-coefficient effects fitted on the Allan curve (the ramp is fitted in time)."""


TINY_AVAR = float(np.finfo(float).tiny)
"""The Allan variance a prediction that is not positive is scored as (:func:`_loss`)."""


def _loss(real_avar: np.ndarray, model_avar: np.ndarray, add: np.ndarray,
          sigma_ln_adev: np.ndarray) -> float:
    """Weighted sum of squares of ``ln ADEV_real - ln ADEV_predicted`` over the taus where
    both are defined (a tau whose real AVAR is not positive, or whose realisations' mean
    is not finite, is left out for every candidate alike); a finite prediction that is
    not positive where the record has variance is scored as the smallest positive double
    (:data:`TINY_AVAR`), a misfit beyond any positive prediction's, as no noise process
    has a negative variance (dropping that tau instead favoured the prediction: the
    Markov AVAR before 21f7db3 went negative far below tau_c). Not infinite: the bounded
    Brent searches that minimise this loss interpolate through its values, and an
    infinite one made their arithmetic NaN (numpy's "invalid value" warnings on the
    user's terminal; Samsung S5 gy, the base model's refit of the white level)."""
    pred = model_avar + add
    have = np.isfinite(real_avar) & (real_avar > 0) & np.isfinite(pred)
    w = 1.0 / np.maximum(sigma_ln_adev[have], 1e-3) ** 2
    r = 0.5 * np.log(real_avar[have] / np.maximum(pred[have], TINY_AVAR))
    return float(np.sum(w * r**2))


def scaled_loss(real_avar: np.ndarray, model_avar: np.ndarray, ratio: np.ndarray,
                sigma_ln_adev: np.ndarray) -> float:
    """The weighted ln-AVAR misfit of the model's expected curve scaled per tau by
    ``ratio`` (a term of the model itself changed, as the base model's refit does)."""
    return _loss(real_avar, model_avar * ratio, np.zeros_like(model_avar), sigma_ln_adev)


def _scale_range(tau_s: np.ndarray, model_avar: np.ndarray, unit_avar: np.ndarray
                 ) -> tuple[float, float]:
    """log10 range of the parameter whose AVAR spans 1e-4..1e4 of the model's."""
    ratio = model_avar / np.maximum(unit_avar, 1e-300)
    lo = 0.5 * math.log10(max(float(np.min(ratio)), 1e-300)) - 2.0
    hi = 0.5 * math.log10(max(float(np.max(ratio)), 1e-300)) + 2.0
    return lo, hi


def fit_single(effect: str, tau_s: np.ndarray, real_avar: np.ndarray,
               model_avar: np.ndarray, sigma_ln_adev: np.ndarray) -> float:
    """The added parameter p >= 0 of ``effect`` minimising the weighted ln-AVAR misfit."""
    basis = BASES[effect]
    unit = basis(tau_s, 1.0)
    lo, hi = _scale_range(tau_s, model_avar, unit)
    res = minimize_scalar(
        lambda lp: _loss(real_avar, model_avar, unit * 10.0 ** (2 * lp), sigma_ln_adev),
        bounds=(lo, hi), method="bounded", options={"xatol": 1e-4},
    )
    return float(10.0 ** res.x)


def fit_base_model(cm: ChannelModel, tau_s: np.ndarray, rate_hz: float,
                   real_avar: np.ndarray, model_avar_sim: np.ndarray,
                   sigma_ln_adev: np.ndarray, local_avar: np.ndarray | float = 0.0
                   ) -> tuple[float, int, float]:
    """Refit of the base model: (bandwidth_hz, filter_order, white).

    The model's own filter (unchanged) and a grid over bandwidth (0.01-0.49 of the rate,
    order 1 and 2), each with the white density refitted by a 1-D search (within a decade
    of the model's; from zero up to all of the shortest tau's Allan variance when the
    model has no white term, e.g. a fit that took a decimated record's white noise for a
    short Markov process); uses the linearity of AVAR in the terms' powers (two model_avar
    calls per bandwidth). The best grid bandwidth is then refined by a bounded 1-D search
    between its neighbours: the grid steps by 14 %, and a fit that jumps between grid
    points when the input curve moves by a hair made the refit fitted again beside a
    negligible candidate (a random walk of 6e-7 dps/sqrt(s)) move the white level by
    0.5 % and the record's band chi-squared by 160 (:func:`imubench.gap.diagnose.
    _evaluate`).

    ``local_avar``: the part of ``model_avar_sim`` that ``cm``'s terms do not describe
    (effects added to the realisations after the simulator, a sine, telegraph, resonance
    or outliers, :mod:`imubench.gap.extras`); the refit leaves it as it is. Scaled with
    the white level and filter it was counted against them (Samsung S5 az with a 0.575 mg
    sine at 1.02 Hz: refitted beside the sine, white fell from 7.6e-5 to 2.7e-5
    g/sqrt(Hz), and the sine raised the chi-squared by 1070 and was not kept)."""
    from imubench.noisefit import model_avar

    own = np.maximum(model_avar_sim - local_avar, 1e-3 * model_avar_sim)

    base = model_avar(cm, tau_s, rate_hz)
    if cm.white > 0:
        lw_lo, lw_hi = math.log10(cm.white) - 1.0, math.log10(cm.white) + 1.0
    else:  # no white in the model: up to all of the shortest tau's AVAR (AVAR = N^2 / tau)
        lw_hi = 0.5 * math.log10(max(float(real_avar[0] * tau_s[0]), 1e-300)) + 0.5
        lw_lo = lw_hi - 4.0

    def at(bw: float, order: int) -> tuple[float, float]:
        """(misfit, white) with the white density refitted for this filter."""
        filt = cm.replace(bandwidth_hz=bw, filter_order=order)
        a_other = model_avar(filt.replace(white=0.0), tau_s, rate_hz)
        a_white = model_avar(filt.replace(white=1.0), tau_s, rate_hz) - a_other

        def loss(lw: float) -> float:
            pred = own * (a_other + a_white * 10.0 ** (2 * lw)) / base + local_avar
            return _loss(real_avar, pred, np.zeros_like(pred), sigma_ln_adev)

        res = minimize_scalar(loss, bounds=(lw_lo, lw_hi), method="bounded",
                              options={"xatol": 1e-5})
        val, white = float(res.fun), float(10.0 ** res.x)
        if cm.white == 0:  # keeping no white at all is a candidate too
            none = loss(-300.0)
            if none <= val:
                val, white = none, 0.0
        return val, white

    given = (float(cm.bandwidth_hz), int(cm.filter_order))
    best = (*at(*given), *given)
    lbw = np.log10(np.geomspace(0.01 * rate_hz, 0.49 * rate_hz, 30))
    for order in (1, 2):
        vals = [at(float(10.0 ** x), order) for x in lbw]
        i = int(np.argmin([v for v, _ in vals]))
        lo, hi = lbw[max(i - 1, 0)], lbw[min(i + 1, lbw.size - 1)]
        res = minimize_scalar(lambda x, o=order: at(float(10.0 ** x), o)[0],
                              bounds=(lo, hi), method="bounded", options={"xatol": 1e-4})
        bw = float(10.0 ** res.x)
        cand = (*at(bw, order), bw, order) if res.fun < vals[i][0] else (
            *vals[i], float(10.0 ** lbw[i]), order)
        if cand[0] < best[0]:
            best = cand
    return best[2], best[3], best[1]


def fit_markov(tau_s: np.ndarray, real_avar: np.ndarray, model_avar: np.ndarray,
               sigma_ln_adev: np.ndarray) -> tuple[float, float]:
    """(markov_sigma, markov_tau): grid over tau_c (20 per decade), sigma by 1-D search."""
    best = (math.inf, 0.0, 1.0)
    decades = max(1, math.ceil(math.log10(4 * tau_s[-1] / tau_s[0])))
    for tc in np.geomspace(tau_s[0] / 2.0, tau_s[-1] * 2.0, 20 * decades + 1):
        unit = avar_markov(tau_s, 1.0, float(tc))
        lo, hi = _scale_range(tau_s, model_avar, unit)
        res = minimize_scalar(
            lambda lp, u=unit: _loss(real_avar, model_avar, u * 10.0 ** (2 * lp),
                                     sigma_ln_adev),
            bounds=(lo, hi), method="bounded", options={"xatol": 1e-3},
        )
        if res.fun < best[0]:
            best = (float(res.fun), float(10.0 ** res.x), float(tc))
    return best[1], best[2]


def markov_over_lookalikes(tau_s: np.ndarray, real_avar: np.ndarray, model_avar: np.ndarray,
                           sigma_ln_adev: np.ndarray, sigma: float, tau_c_s: float) -> float:
    """How much better a fitted Gauss-Markov term (``sigma``, ``tau_c_s``) fits the Allan
    curve than the better of its one-parameter look-alikes, a random walk and flicker,
    each fitted the same way (:func:`fit_single`): the drop of the weighted ln-AVAR misfit
    of :func:`fit_markov`.

    A Gauss-Markov ADEV rises as a random walk's below ~tau_c and falls as white noise's
    beyond ~3 tau_c (IEEE 952 C.6); between them it is flat like flicker. Only its
    turnover, the rise and the descent together, tells it apart, and this is that
    evidence: a likelihood-ratio-like statistic with one parameter more (Wilks 1938),
    read against :data:`imubench.gap.candidates.MARKOV_DESCENT`."""
    markov = _loss(real_avar, model_avar, avar_markov(tau_s, sigma, tau_c_s), sigma_ln_adev)
    alike = []
    for effect in ("random_walk", "flicker"):
        p = fit_single(effect, tau_s, real_avar, model_avar, sigma_ln_adev)
        alike.append(_loss(real_avar, model_avar, BASES[effect](tau_s, p), sigma_ln_adev))
    return min(alike) - markov


QUANTIZATION_LAW_TAUS = 4
"""Shortest taus (octaves from tau0) on which the quantization law is checked."""


def quantization_law(tau_s: np.ndarray, real_avar: np.ndarray, model_avar: np.ndarray,
                     sigma_ln_adev: np.ndarray) -> tuple[float, int, float]:
    """Misfit of the short-tau excess to the quantization law: (chi-squared, its dof,
    what the quantization part adds).

    Angle quantization adds ``3 Q^2 / tau^2`` (IEEE Std 952-1997 C.2) and a change of the
    white level adds ``dN^2 / tau`` (either sign); over the first QUANTIZATION_LAW_TAUS
    taus the excess ``e = AVAR_real - AVAR_model`` is fitted with ``a / tau + b / tau^2``
    by weighted least squares, one-sigma ``2 s AVAR_model`` (``s`` the one-sigma spread of
    ln ADEV, the diagonal only: neighbouring octaves correlate, so the statistic is
    conservative against a true quantization), and the residual chi-squared with
    ``n - 2`` dof is returned. A decimation filter or a short Markov process that departs
    at the shortest tau alone (Samsung S5 gyro: +77 % at tau0, +3 % at 2 tau0, -26 % at
    4 tau0) does not follow it; quantization over any white level does.

    The third value is the chi-squared drop from ``a / tau`` alone to ``a / tau + b /
    tau^2`` with ``b > 0`` (0 when the best ``b`` is not positive): the evidence for the
    quantization part beyond a change of the white level, chi-squared with 1 dof when
    there is none (a likelihood-ratio statistic of nested linear models).
    """
    n = min(QUANTIZATION_LAW_TAUS, len(tau_s))
    t, e = tau_s[:n], (real_avar - model_avar)[:n]
    sd = 2.0 * np.maximum(sigma_ln_adev[:n], 1e-6) * model_avar[:n]
    ok = np.isfinite(e) & np.isfinite(sd) & (sd > 0)
    if ok.sum() < 3:
        return 0.0, 0, math.inf
    x = np.column_stack([1.0 / t, 1.0 / t**2])[ok] / sd[ok, None]
    y = e[ok] / sd[ok]
    coef, *_ = np.linalg.lstsq(x, y, rcond=None)
    r = y - x @ coef
    a_only, *_ = np.linalg.lstsq(x[:, :1], y, rcond=None)
    r1 = y - x[:, :1] @ a_only
    drop = float(r1 @ r1 - r @ r) if coef[1] > 0 else 0.0
    return float(r @ r), int(ok.sum()) - 2, drop
