"""Does a channel's rate follow the die temperature? A check before trusting a noise fit,
and the response itself, for a fit that takes it out first (``imubench fit
--fit-temperature``).

The noise terms of :mod:`.fit` are stationary noise; a rate that drifts with a varying
temperature (the ``temp_coeff`` of a model file) shows in the Allan variance as extra
random walk or flicker at long taus, and the fit then reports those inflated (measured: a
0.01 dps/degC sensitivity over a 4 degC, 900 s cycle gave a random walk 60 times the
true one).

The response: block means of the rate and of the temperature (blocks of
:data:`BLOCK_S`, longer where the record holds more than
:data:`~imubench.noisefit.blockmean.MAX_BLOCKS`), differenced, and the rate's increments
regressed on those of ``dT = T - temp_ref`` (and of ``dT^2``) beside a constant, by
generalised least squares under the covariance of the increments of the channel's
fitted noise (:func:`~imubench.noisefit.model_avar.block_increment_acv`;
:func:`~imubench.noisefit.blockmean.gls_fit`, Aitken 1935). The constant is a linear
trend of the levels, so a ramp or a wandering level's chance trend is not read as a
response; a temperature that only drifts at a constant rate has no response that can be
told from a ramp (None). A random walk or flicker makes the levels of any slow
temperature history look related (Granger & Newbold 1974, J. Econometrics 2, "Spurious
regressions in econometrics"): least squares of levels, with its lag-1 correction for
autocorrelated residuals, called 10 of 40 records of white noise + a random walk of
3e-5 dps/sqrt(s) on a 20 -> 30 degC warm-up a response at |t| > 5; under the noise's own
covariance none is.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np
from lsm6ds_sim.model import ChannelModel
from scipy.linalg import cho_factor, cho_solve, toeplitz

from imubench.noisefit.blockmean import MAX_BLOCKS, gls_fit, only_trend
from imubench.noisefit.model_avar import block_increment_acv

BLOCK_S = 30.0
"""Shortest block (s) of the means the response is fitted to."""
MIN_BLOCKS = 20
MIN_TEMP_SPREAD_C = 0.2
"""Standard deviation of the temperature block means (degC) below which nothing is said."""
T_LIMIT = 5.0
"""|t| above which the rate is said to follow the temperature."""
SCREEN_T = 3.0
"""|t| under the first fit's noise above which the default fit warns, and above which
``--fit-temperature`` makes its refits. That noise carries the drift and widens the
response's error (a 3e-3 dps/degC warm-up: t 4.6 under it, 14 after the refits); under a
right covariance |t| > 3 on 0.3 % of records without a response."""
LIKELIHOOD_GAIN = T_LIMIT**2 / 2
"""Least fall of the block-mean increments' -log L (:func:`increment_nll`) when the
response is taken out and the noise refitted: 12.5, the likelihood ratio 25 of a
one-parameter |t| of 5."""
HALVES_Z = 3.0
"""Difference of the two halves' slopes, in its standard errors, above which the response
is not the same through the record (:attr:`TemperatureResponse.stable`)."""


class TemperatureTerms(NamedTuple):
    """A model's response to the die temperature (the model file's keys): ``temp_coeff
    dT + temp_coeff2 dT^2``, dT = T - temp_ref (unit/degC, unit/degC^2, degC)."""

    temp_coeff: float
    temp_coeff2: float
    temp_ref: float

    def response(self, temp_c: np.ndarray) -> np.ndarray:
        """The response (unit) at the temperatures ``temp_c`` (degC), missing readings
        inside the record linearly interpolated, NaN before the first and after the last
        (:func:`filled_temperature`)."""
        dt = filled_temperature(np.asarray(temp_c, dtype=float)) - self.temp_ref
        return self.temp_coeff * dt + self.temp_coeff2 * dt * dt


def filled_temperature(temp_c: np.ndarray) -> np.ndarray:
    """The temperature with its missing samples linearly interpolated (a response is
    taken out of every sample the rate holds; NaN where the temperature is missing from
    one end on: those samples are not in the blocks the response was fitted to)."""
    ok = np.isfinite(temp_c)
    if ok.all() or not ok.any():
        return temp_c
    idx = np.arange(len(temp_c))
    out = np.interp(idx, idx[ok], temp_c[ok])
    out[(idx < idx[ok][0]) | (idx > idx[ok][-1])] = np.nan
    return out


def sensed(channel: str) -> str:
    """What a channel reads, in words: ``rate`` (gyro) or ``acceleration``."""
    return "rate" if channel.startswith("g") else "acceleration"


@dataclass(frozen=True)
class TemperatureResponse:
    """A channel's response to the die temperature, ``temp_coeff (T - temp_ref_c)`` (the
    model file's keys and units: unit/degC, degC)."""

    temp_coeff: float
    temp_coeff_se: float
    curvature: float
    """Curvature (unit/degC^2) of a quadratic fit beside the slope: reported, never
    written to the model (a quadratic fitted over a few degC and replayed beyond them
    grows without bound: CATS tag gx, 7.8 degC, -0.0057 dps/degC^2, made another
    segment's drift worse 8-fold)."""
    curvature_se: float
    temp_ref_c: float
    """The blocks' mean temperature, to 0.01 degC."""
    blocks: int
    block_s: float
    temp_span_c: float
    """Range of the block temperatures (degC)."""
    halves: tuple[float, float, float, float] | None = None
    """(slope, standard error) of the first and of the second half of the record, under
    the same covariance (:func:`with_halves`); None when not made."""
    likelihood_gain: float | None = None
    """Fall of the block-mean increments' -log L when the response is taken out and the
    noise refitted (:func:`increment_nll`); None when not made."""

    @property
    def t(self) -> float:
        """The slope's t statistic: significant when ``|t| > T_LIMIT``."""
        return self.temp_coeff / self.temp_coeff_se

    @property
    def significant(self) -> bool:
        return abs(self.t) > T_LIMIT

    @property
    def curvature_t(self) -> float:
        """The curvature's t statistic (NaN without a standard error)."""
        return self.curvature / self.curvature_se if self.curvature_se > 0 else math.nan

    @property
    def curved(self) -> bool:
        """The quadratic's curvature is significant (|t| > :data:`T_LIMIT`): the linear
        coefficient is the mean slope over the record's temperatures only (the reviewer's
        CATS gx segment: curvature t -7.8 beside a linear response accepted at t 16)."""
        return abs(self.curvature_t) > T_LIMIT

    @property
    def halves_z(self) -> float | None:
        """|first half's slope - second's| / its standard error, or None."""
        if self.halves is None:
            return None
        a, sa, b, sb = self.halves
        return abs(a - b) / math.hypot(sa, sb)

    @property
    def stable(self) -> bool:
        """The two halves agree within :data:`HALVES_Z` (or a half cannot tell)."""
        z = self.halves_z
        return z is None or z <= HALVES_Z

    @property
    def describes_record(self) -> bool:
        """Taking the response out raised the record's likelihood by more than
        :data:`LIKELIHOOD_GAIN` (False when not compared)."""
        return self.likelihood_gain is not None and self.likelihood_gain > LIKELIHOOD_GAIN

    @property
    def accepted(self) -> bool:
        """Significant, the same in both halves, and describing the record better than
        the noise terms it replaces: the response ``--fit-temperature`` takes out."""
        return self.significant and self.stable and self.describes_record

    @property
    def terms(self) -> TemperatureTerms:
        """The response as a model file holds it (linear: ``temp_coeff2`` 0)."""
        return TemperatureTerms(self.temp_coeff, 0.0, self.temp_ref_c)

    def response(self, temp_c: np.ndarray) -> np.ndarray:
        """The response (unit) at the temperatures ``temp_c`` (degC;
        :meth:`TemperatureTerms.response`)."""
        return self.terms.response(temp_c)

    def to_dict(self, unit: str) -> dict[str, object]:
        """JSON-ready, with ``units``."""
        return {"temp_coeff": self.temp_coeff, "temp_coeff_se": self.temp_coeff_se,
                "t": self.t, "temp_ref_c": self.temp_ref_c, "curvature": self.curvature,
                "curvature_se": self.curvature_se, "blocks": self.blocks,
                "block_s": self.block_s, "temp_span_c": self.temp_span_c,
                "likelihood_gain": self.likelihood_gain, "accepted": self.accepted,
                "curved": self.curved,
                "halves": None if self.halves is None else {
                    "first": self.halves[0], "first_se": self.halves[1],
                    "second": self.halves[2], "second_se": self.halves[3]},
                "units": {"temp_coeff": f"{unit}/degC", "temp_coeff_se": f"{unit}/degC",
                          "temp_ref_c": "degC", "curvature": f"{unit}/degC^2",
                          "curvature_se": f"{unit}/degC^2", "block_s": "s",
                          "temp_span_c": "degC", "halves": f"{unit}/degC"}}


MIN_FILL = 0.9
"""Share of a block's samples that must hold data for its mean to be used: the increments'
covariance is that of full blocks (a temperature column that stopped one sample into a
block made that block's rate mean a single sample, and a 3e-3 dps/degC response at t 21
was refused)."""


def _block_means(a: np.ndarray, n: int, m: int) -> np.ndarray:
    """Means of n blocks of m samples over their finite values (NaN for a block with less
    than :data:`MIN_FILL` of them)."""
    blocks = np.asarray(a[: n * m], dtype=float).reshape(n, m)
    ok = np.isfinite(blocks)
    count = ok.sum(axis=1)
    total = np.where(ok, blocks, 0.0).sum(axis=1)
    return np.where(count >= MIN_FILL * m, total / np.maximum(count, 1), np.nan)


def _blocks(y: np.ndarray, temp_c: np.ndarray, rate_hz: float
            ) -> tuple[int, np.ndarray, np.ndarray, np.ndarray] | None:
    """(samples per block, rate block means, temperature block means, mask of the blocks
    where both hold data), or None when the record is too short or the temperature too
    steady (:func:`fit_temperature_response`)."""
    n_samples = min(len(y), len(temp_c))
    m = max(int(BLOCK_S * rate_hz), math.ceil(n_samples / MAX_BLOCKS), 1)
    n = n_samples // m
    if n < MIN_BLOCKS:
        return None
    yb, tb = _block_means(y, n, m), _block_means(temp_c, n, m)
    ok = np.isfinite(yb) & np.isfinite(tb)
    if ok.sum() < MIN_BLOCKS or float(np.std(tb[ok])) < MIN_TEMP_SPREAD_C:
        return None
    return m, yb, tb, ok


def _increment_chol(noise: ChannelModel, m: int, n_inc: int, rate_hz: float,
                    inc: np.ndarray) -> tuple[np.ndarray, bool]:
    """Cholesky factor of the covariance of the block-mean increments kept by ``inc``."""
    acv = block_increment_acv(noise, m, n_inc, rate_hz)
    return cho_factor(toeplitz(acv)[np.ix_(inc, inc)])


def fit_temperature_response(y: np.ndarray, temp_c: np.ndarray, rate_hz: float,
                             noise: ChannelModel) -> TemperatureResponse | None:
    """The rate's response to the temperature under the covariance of ``noise`` (the
    channel's fitted noise terms; module docstring), or None when the record is too short
    (fewer than :data:`MIN_BLOCKS` blocks with data), the temperature too steady (block
    means' standard deviation below :data:`MIN_TEMP_SPREAD_C`) or a straight line in time
    (:func:`~imubench.noisefit.blockmean.only_trend`)."""
    found = _blocks(y, temp_c, rate_hz)
    if found is None:
        return None
    m, yb, tb, ok = found
    inc = ok[1:] & ok[:-1]  # increments between two blocks with data
    ref = round(float(tb[ok].mean()), 2)
    dt = tb - ref
    dy, dx, dx2 = np.diff(yb)[inc], np.diff(dt)[inc], np.diff(dt * dt)[inc]
    if len(dy) < MIN_BLOCKS or only_trend(dx):
        return None
    chol = _increment_chol(noise, m, len(inc), rate_hz, inc)
    one = np.ones_like(dx)
    c1, se1 = gls_fit(dy[None, :], np.column_stack([one, dx]), chol)
    c2, se2 = gls_fit(dy[None, :], np.column_stack([one, dx, dx2]), chol)
    slope, slope_se = float(c1[1, 0]), float(se1[1, 0])
    if not (math.isfinite(slope) and slope_se > 0):
        return None
    return TemperatureResponse(
        temp_coeff=slope, temp_coeff_se=slope_se, curvature=float(c2[2, 0]),
        curvature_se=float(se2[2, 0]), temp_ref_c=ref, blocks=int(ok.sum()),
        block_s=m / rate_hz, temp_span_c=float(np.ptp(tb[ok])))


def increment_nll(y: np.ndarray, temp_c: np.ndarray, rate_hz: float, noise: ChannelModel
                  ) -> float:
    """-log L (without the 2 pi term) of the record's block-mean increments (the blocks of
    :func:`fit_temperature_response`) less their generalised-least-squares mean (a linear
    trend of the levels), under the covariance of ``noise``: ``(log det C + e' C^-1 e) /
    2``. Compared between the noise fitted to the record as it is and the noise fitted
    to the record less a response (with that response taken out), it says whether the
    response describes the record's slow variation better than the noise terms it
    replaces. NaN when there are no blocks to compare."""
    found = _blocks(y, temp_c, rate_hz)
    if found is None:
        return math.nan
    m, yb, _, ok = found
    inc = ok[1:] & ok[:-1]
    dy = np.diff(yb)[inc]
    chol = _increment_chol(noise, m, len(inc), rate_hz, inc)
    mean, _ = gls_fit(dy[None, :], np.ones((len(dy), 1)), chol)
    e = dy - float(mean[0, 0])
    return float(np.log(np.diag(chol[0])).sum() + 0.5 * e @ cho_solve(chol, e))


def with_halves(response: TemperatureResponse, y: np.ndarray, temp_c: np.ndarray,
                rate_hz: float, noise: ChannelModel) -> TemperatureResponse:
    """``response`` with the slopes of the record's two halves (:attr:`halves`), each under
    the covariance of ``noise``: a check that the response is one property of the sensor
    through the record. A response the model cannot describe (a rate that also follows
    something the temperature tracks in part of the record, a hysteresis) can show as
    halves that disagree; it need not: on the CATS tag's gyro x, fitted on one 8.5 h
    segment of each static orientation (+0.0067, -0.023 and -0.032 dps/degC at |t| 6-16),
    the halves agreed (z 0.7 and 1.6, or not compared) while the other segments read
    -0.002 to -0.012 (docs/noise-fit.md, Limits)."""
    half = min(len(y), len(temp_c)) // 2
    a = fit_temperature_response(y[:half], temp_c[:half], rate_hz, noise)
    b = fit_temperature_response(y[half:], temp_c[half:], rate_hz, noise)
    if a is None or b is None:
        return response
    return replace(response, halves=(a.temp_coeff, a.temp_coeff_se, b.temp_coeff,
                                     b.temp_coeff_se))


def temperature_warning(channel: str, unit: str, response: TemperatureResponse | None,
                        refitted: bool) -> str | None:
    """A warning, in words, when the rate may follow the temperature (|t| >
    :data:`SCREEN_T`) and the response was left in the data the noise terms are fitted
    to: by default (``refitted`` False: the first fit's response), or because
    ``--fit-temperature`` did not accept it (the refitted response; the reason is
    given)."""
    if response is None or abs(response.t) <= SCREEN_T:
        return None
    what = sensed(channel)
    verb = "follows" if response.significant else "may follow"
    head = (f"{channel}: the {what} {verb} the die temperature ({response.temp_coeff:.3g} "
            f"+- {response.temp_coeff_se:.2g} {unit}/degC, t {response.t:.1f} over "
            f"{response.blocks} blocks of {response.block_s:g} s); the fitted long-tau terms "
            "(random walk, flicker, ramp) include that drift")
    curves = (f"; the response curves (curvature {response.curvature:.3g} +- "
              f"{response.curvature_se:.2g} {unit}/degC^2, t "
              f"{response.curvature_t:.1f}): a linear temp_coeff "
              "cannot describe it (its slope differs between temperatures); fit it over "
              "the temperatures the model will be used at" if response.curved else "")
    if refitted and not response.significant:
        return (head + f"; it was not taken out: after the refits |t| is {abs(response.t):.1f}, "
                f"at most {T_LIMIT:g} (a response this weak is not told from the noise)"
                + curves)
    if refitted and not response.stable:
        assert response.halves is not None
        a, sa, b, sb = response.halves
        return (head + f"; no response can be taken out: the record's halves disagree "
                f"({a:.3g} +- {sa:.2g} and {b:.3g} +- {sb:.2g} {unit}/degC, "
                f"{response.halves_z:.1f} standard errors apart), so one response would "
                "not describe the sensor" + curves)
    if refitted and not response.describes_record:
        gain = response.likelihood_gain
        return (head + "; no response can be taken out: with it taken out and the noise "
                "refitted, the record's block means are not described better (-log L "
                f"falls by {gain if gain is not None else math.nan:.1f}, at least "
                f"{LIKELIHOOD_GAIN:g} needed): the rate follows something that moves with "
                "the temperature here, not the temperature alone" + curves)
    return head + (": give --fit-temperature to fit the response and take it out first, "
                   "or fit a recording at constant temperature" + curves)


def no_response_note(channel: str) -> str:
    """What ``--fit-temperature`` says when no response could be estimated."""
    return (f"{channel}: --fit-temperature: no response to the temperature could be "
            "estimated (no temperature column, or one that is missing, steady within "
            f"{MIN_TEMP_SPREAD_C:g} degC, shorter than {MIN_BLOCKS} blocks of "
            f"{BLOCK_S:g} s, or a straight line in time, whose response is a ramp); "
            "nothing was taken out")


def removal_note(channel: str, unit: str, response: TemperatureResponse) -> str:
    """What ``--fit-temperature`` did, in words."""
    what = sensed(channel)
    checks = f"; -log L falls by {response.likelihood_gain:.1f}" \
        if response.likelihood_gain is not None else ""
    if response.halves is not None:
        a, sa, b, sb = response.halves
        checks += f"; halves {a:.3g} +- {sa:.2g} and {b:.3g} +- {sb:.2g}"
    else:
        checks += "; halves not compared: one half's temperature is too steady"
    curvature = (f"a curvature of {response.curvature:.3g} +- {response.curvature_se:.2g} "
                 f"{unit}/degC^2")
    linear = (f"linear, although the response curves ({curvature}, t "
              f"{response.curvature_t:.1f}): temp_coeff is its mean "
              f"slope over this record's {response.temp_span_c:.2g} degC about "
              f"{response.temp_ref_c:g} degC, not its slope beyond them; measure it over the "
              "temperatures the model will be used at" if response.curved else
              f"linear: {curvature} is not written, since a quadratic replayed beyond the "
              "temperatures it was fitted on grows without bound")
    return (f"{channel}: the {what}'s response to the die temperature, "
            f"{response.temp_coeff:.4g} +- {response.temp_coeff_se:.2g} {unit}/degC about "
            f"{response.temp_ref_c:g} degC (t {response.t:.1f}, {response.blocks} blocks of "
            f"{response.block_s:g} s over {response.temp_span_c:.2g} degC{checks}), was "
            f"taken out before the noise terms were fitted and is written as temp_coeff, "
            f"temp_ref ({linear})")
