"""One channel of a record, its parts (fit, held out, replicate) and the model's realisations.

:class:`Series` is a channel with its temperature; :func:`simulate_channel` draws K
realisations of the model over a series' length, rate and temperature history;
:class:`PartSetup` holds the taus, bands and real features of one part and compares
realisations with it (:mod:`imubench.gap.curves`).
"""

from __future__ import annotations

import copy
import functools
import math
from dataclasses import dataclass

import numpy as np
from lsm6ds_sim.model import ChannelModel, NoiseModel
from lsm6ds_sim.physics import simulate
from lsm6ds_sim.temperature import ReplayTemperature
from scipy.linalg import cho_factor, toeplitz

from imubench.gap.curves import (
    Comparison,
    SimFeatures,
    analysis_afs,
    band_edges,
    block_length,
    block_means,
    compare,
    features,
    gls_against,
    gls_slopes,
    oavar_at,
    psd_segment,
    stack,
    welch_psd,
)
from imubench.gap.errors import GapError
from imubench.noisefit.blockmean import gls_fit, only_trend
from imubench.noisefit.covariance import oavar_correlation
from imubench.noisefit.model_avar import (
    block_increment_acv,
    block_increment_key,
    stochastic_amplitudes,
)
from imubench.stats import oadev


@dataclass
class Series:
    """One channel of one record: rate samples, temperature (or None), rate."""

    y: np.ndarray
    temp_c: np.ndarray | None
    rate_hz: float
    name: str = "<record>"

    def part(self, start: int, stop: int) -> Series:
        t = None if self.temp_c is None else self.temp_c[start:stop]
        return Series(self.y[start:stop], t, self.rate_hz, self.name)

    @property
    def has_temperature(self) -> bool:
        return self.temp_c is not None and bool(np.isfinite(self.temp_c).sum() > 1)



def seeds_of(seed: int, k: int) -> list[int]:
    return [int(s) for s in np.random.SeedSequence(int(seed)).generate_state(k)]


def _profile(series: Series) -> ReplayTemperature | None:
    if not series.has_temperature:
        return None
    assert series.temp_c is not None
    t = np.arange(len(series.temp_c)) / series.rate_hz
    return ReplayTemperature(t, series.temp_c, name=series.name)


def simulate_channel(model: NoiseModel, channel: str, series: Series, seeds: list[int]
                     ) -> np.ndarray:
    """(K, n) realisations of ``channel`` over the series' length and temperature."""
    prof = _profile(series)
    n = len(series.y)
    out = np.empty((len(seeds), n))
    for i, s in enumerate(seeds):
        out[i] = simulate(model, n, series.rate_hz, s, temperature=prof,
                          channels=[channel])[channel]
    nan = ~np.isfinite(series.y)
    if nan.any():
        out[:, nan] = np.nan
    return out


def tau_correlation(cm: ChannelModel, afs: np.ndarray, n: int, rate_hz: float) -> np.ndarray:
    """Model correlation of the OAVAR estimates at averaging factors ``afs`` of n samples.

    From the channel's stochastic terms (:func:`imubench.noisefit.covariance.
    oavar_correlation`); the global test (:func:`imubench.gap.curves.global_chi2`) needs it.
    """
    amp2 = stochastic_amplitudes(cm)
    tau_c = float(cm.markov_tau) if "markov" in amp2 else 0.0
    m = np.asarray(afs, dtype=np.int64)
    return oavar_correlation(m, n - 2 * m, amp2, rate_hz, tau_c_s=tau_c,
                             bandwidth_hz=float(cm.bandwidth_hz),
                             filter_order=int(cm.filter_order),
                             resonance=(cm.resonance_freq_hz, cm.resonance_width_hz))


class RecordTemperature:
    """The temperature level test of a series' blocks: on the WHOLE record (twice the fit
    part's data) here, and its covariance (:attr:`chol`) for each part's level test
    (:class:`PartSetup`).

    The fit part's test (:func:`imubench.gap.curves.temp_level_against`) sees half the
    record: a response of 5e-4 dps/degC on the blind set's temperatures (+-3 and +-1.2
    degC at periods of 25 and 7 min, white 0.004 dps/sqrt(Hz), flicker 0.0008 dps) gives
    z ~3.3 on 30 min, ~4.7 on the hour. As the bias-step and drift tests, it is a test
    of the record; the temperature coefficient is still fitted on the fit part alone and
    checked on the held-out part. Blocks of :func:`imubench.gap.curves.block_length`
    over the series; the covariance (the Cholesky factor of the model's Toeplitz
    covariance of the block-mean increments,
    :func:`imubench.noisefit.model_avar.block_increment_acv`) is that of ``cm``'s noise,
    and :meth:`for_model` gives the test under another model's."""

    def __init__(self, cm: ChannelModel, series: Series) -> None:
        self.n_block = block_length(len(series.y), series.rate_hz)
        self.rate_hz = series.rate_hz
        self.key = block_increment_key(cm)
        """The noise of the model whose covariance :attr:`chol` is."""
        self._views: dict[tuple[float, ...], RecordTemperature] = {self.key: self}
        self.tb: np.ndarray | None = None
        self.temp_c: np.ndarray | None = None
        self.chol: tuple[np.ndarray, bool] | None = None
        self.note = ""
        """Why the test cannot be made although the record has a temperature (empty
        otherwise)."""
        if series.has_temperature:
            assert series.temp_c is not None
            tb = block_means(series.temp_c, self.n_block)
            if not (len(tb) >= 5 and np.isfinite(tb).all()):
                self.note = "the temperature has missing blocks: no whole-record test"
            elif np.ptp(tb) <= 1e-6:
                self.note = "the temperature is constant: no response can be seen"
            elif only_trend(np.diff(tb)):
                self.note = ("the temperature only drifts, at a constant rate: a response "
                             "to it cannot be told from a ramp (a ramp candidate takes "
                             "it), nor a curved response from a drift that curves in time "
                             "(no candidate has that shape)")
            else:
                self.tb, self.temp_c = tb, series.temp_c
                self.chol = self._chol(cm)

    def _chol(self, cm: ChannelModel) -> tuple[np.ndarray, bool]:
        assert self.tb is not None
        return cho_factor(toeplitz(block_increment_acv(cm, self.n_block, len(self.tb) - 1,
                                                       self.rate_hz)))

    def for_model(self, cm: ChannelModel) -> RecordTemperature:
        """This test under the covariance of ``cm``'s noise (the same blocks; made once per
        distinct noise, :func:`imubench.noisefit.model_avar.block_increment_key`).

        The tests of a model with kept noise processes are made under that model's
        covariance, the one their GLS slope is efficient under (Aitken 1935). Under the
        base model's, the slow increments a kept random walk dominates are weighed as if
        they were the base model's flicker: the realisations' chance slopes spread wide,
        and a response beside the walk was not seen (added blind pairs temperature 1e-3
        dps/degC + random walk 3e-4 dps/sqrt(s), tune and fresh: the whole-record z,
        6.0 and 4.4 before the walk, was 1.5 and 2.6 after it, and the response was
        never examined again; under the walk's covariance 3.1 and 2.9)."""
        key = block_increment_key(cm)
        if key not in self._views:
            view = copy.copy(self)
            view.key = key
            if self.chol is not None:
                view.chol = self._chol(cm)
            self._views[key] = view
        return self._views[key]

    def z(self, y: np.ndarray, sims: np.ndarray, det_sum: np.ndarray | float) -> float:
        """z of the record ``y``'s temperature slope against the realisations less the
        kept effects' deterministic parts ``det_sum`` (NaN without temperature)."""
        if self.chol is None or self.tb is None:
            return float("nan")
        sims_yb = np.array([block_means(s - det_sum, self.n_block) for s in sims])
        return gls_against(block_means(y, self.n_block), sims_yb, self.tb, self.chol)

    def less_response(self, ys: np.ndarray, step_at: int | None = None) -> np.ndarray:
        """Each row of ``ys`` (k, n) less its own temperature response: the GLS slope of
        its block-mean increments on the temperature's (:func:`imubench.gap.curves.
        gls_slopes`, beside a constant) times the temperature about its mean. ``ys``
        unchanged without the test (:attr:`note`) or where a slope is NaN.

        ``step_at``: a bias step located at that sample is fitted beside the slope (its
        increments: ``1 - f`` on the one into its block, ``f`` on the one out of it, ``f``
        its place in the block). Without it a step under a temperature that only rises
        took part of the slope, and the record less that response kept 18 % of a
        permanent -0.92 dps step (an outside reviewer's CATS segment: the step was
        refused as a transient)."""
        if self.chol is None or self.tb is None or self.temp_c is None:
            return ys
        extra = None
        if step_at is not None:
            j, f = divmod(step_at, self.n_block)
            extra = np.zeros(len(self.tb) - 1)
            if 1 <= j <= len(extra):
                extra[j - 1] = 1.0 - f / self.n_block
            if j < len(extra):
                extra[j] += f / self.n_block
            if not extra.any():
                extra = None
        slopes = self.slopes(ys, extra)
        slopes = np.where(np.isfinite(slopes), slopes, 0.0)
        return ys - slopes[:, None] * (self.temp_c - np.nanmean(self.temp_c))[None, :]

    def curvature_z(self, y: np.ndarray, temp_ref_c: float) -> float:
        """z of the curvature of ``y``'s temperature response (unit/degC^2 over its GLS
        standard error): the block-mean increments regressed on those of ``T - temp_ref``
        and ``(T - temp_ref)^2`` beside a constant, under the base model's covariance
        (:func:`imubench.noisefit.blockmean.gls_fit`); NaN without the test (:attr:`note`).

        The quadratic candidate's least squares of the block means weighs every block
        alike; on a slow temperature (+-1.5 degC at periods of 19 and 27 min, flicker
        0.0008 dps) the flicker's wander gave a curvature of 6e-4 dps/degC^2 to a linear
        response of 1e-3 dps/degC, and the coefficient at temp_ref 25 degC read -5.2e-4
        (the slope at the record's 26.5 degC was right)."""
        if self.chol is None or self.tb is None or self.temp_c is None:
            return float("nan")
        tb2 = block_means((self.temp_c - temp_ref_c) ** 2, self.n_block)
        yb = block_means(y, self.n_block)
        if not (np.isfinite(tb2).all() and np.isfinite(yb).all()):
            return float("nan")
        dx = np.diff(self.tb)
        x = np.column_stack([np.ones_like(dx), dx, np.diff(tb2)])
        coef, se = gls_fit(np.diff(yb)[None, :], x, self.chol)
        return float(coef[2, 0] / se[2, 0])

    def slopes(self, ys: np.ndarray, extra: np.ndarray | None = None) -> np.ndarray:
        """The temperature response (unit/degC) of each row of ``ys`` (k, n): the GLS slope
        of its block-mean increments on the temperature's, beside a constant (a linear
        trend of the level, so a ramp does not enter it) and ``extra``
        (:func:`imubench.gap.curves.gls_slopes`); NaN without the test (:attr:`note`) or
        where undefined."""
        if self.chol is None or self.tb is None:
            return np.full(len(ys), np.nan)
        yb = np.array([block_means(y, self.n_block) for y in ys])
        return gls_slopes(np.diff(yb, axis=1), np.diff(self.tb), self.chol, extra)[0]


KURTOSIS_MIN_TERMS = 2000
"""Fewest non-overlapping block-mean differences an excess kurtosis is estimated from
(:func:`difference_kurtosis`; its standard error is sqrt(24 / n), 0.11 here). Impulses
show at the short averaging factors, where there are many differences; over a few
hundred, one deterministic jump is itself a heavy tail (a 0.03 dps bias step on white
0.004 dps/sqrt(Hz), 30 min at 104 Hz: excess kurtosis 11 over the 365 differences at
m = 512, though the step adds nothing random to the Allan estimate)."""
KURTOSIS_Z = 3.0
"""Standard errors an excess kurtosis must exceed to widen the spread (below it, 0)."""


def difference_kurtosis(y: np.ndarray, afs: np.ndarray) -> np.ndarray:
    """The excess kurtosis ``gamma_m`` of the differences of consecutive non-overlapping
    means of ``m`` samples of ``y``, per averaging factor ``m`` of ``afs``: the terms the
    Allan variance at ``m`` averages the squares of. 0 where it is not beyond
    :data:`KURTOSIS_Z` of its standard error sqrt(24 / n) (Gaussian noise and an LSB's
    rounding give 0); where fewer than :data:`KURTOSIS_MIN_TERMS` differences hold it, the
    last estimated value times ``m_last / m`` (a sum of m independent terms has 1/m of
    their excess kurtosis). Blocks holding a missing sample are left out."""
    out = np.zeros(len(afs))
    last: tuple[int, float] | None = None
    for i, m in enumerate(int(a) for a in afs):
        nb = len(y) // m
        if nb - 1 < KURTOSIS_MIN_TERMS:
            if last is not None:
                out[i] = last[1] * last[0] / m
            continue
        dm = np.diff(y[:nb * m].reshape(nb, m).mean(axis=1))
        dm = dm[np.isfinite(dm)]
        if len(dm) < KURTOSIS_MIN_TERMS:
            continue
        dm = dm - dm.mean()
        v = float(np.mean(dm**2))
        g = float(np.mean(dm**4)) / (v * v) - 3.0 if v > 0 else 0.0
        out[i] = g if g > KURTOSIS_Z * math.sqrt(24.0 / len(dm)) else 0.0
        last = (m, out[i])
    return out


def _allan_spread(series: Series, afs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The taus (s) of the averaging factors ``afs`` of the series and its OADEV's
    one-sigma spread in ln ADEV there: from the confidence interval (NIST SP 1065 sec.
    5.3, whose equivalent degrees of freedom are those of Gaussian noise), widened by
    ``sqrt(1 + gamma_m / 2)`` with ``gamma_m`` the excess kurtosis of the differences the
    Allan variance averages (:func:`difference_kurtosis`): the variance of a mean of
    squares is ``(2 + gamma) sigma^4 / n`` where a Gaussian's is ``2 sigma^4 / n``
    (Cramer, Mathematical Methods of Statistics, 1946, eq. 27.4.2). Impulsive noise
    makes the short-tau Allan variance far less certain than its EDF says: 0.1 % of
    samples hit by impulses of 15 sigma (excess kurtosis 39 at one sample) left a held-out
    half 2.4 % below the realisations at tau0, 13 of the Gaussian sigmas and about one of
    its own, and the impulses were refused there (an outside reviewer's telegraph +
    outliers: the white level was refitted instead and the verdict told the user to
    refit it)."""
    full = oadev(series.y, series.rate_hz, "freq", afs=afs)
    with np.errstate(divide="ignore", invalid="ignore"):
        ci_s = 0.5 * np.log(np.asarray(full.ci_high) / np.asarray(full.ci_low))
    tau_s = np.asarray(full.tau_s)
    gamma = difference_kurtosis(np.asarray(series.y, dtype=float), afs[:len(tau_s)])
    return tau_s, ci_s * np.sqrt(1.0 + 0.5 * gamma)


class PartSetup:
    """Taus, bands and the real features of one part (fit, holdout or a replicate)."""

    def __init__(self, series: Series, cm: ChannelModel | None = None) -> None:
        n = len(series.y)
        if np.isfinite(series.y).sum() < 64:
            raise GapError(f"{series.name}: fewer than 64 valid samples to analyse")
        self.series = series
        self.afs = analysis_afs(n, series.rate_hz)
        self.nperseg = psd_segment(n)
        f, _ = welch_psd(series.y[:self.nperseg], series.rate_hz, self.nperseg)
        self.f_hz = f
        self.edges = band_edges(f)
        self.tau_s, self.ci_s = _allan_spread(series, self.afs)
        self.real = features(series.y, series.rate_hz, self.afs, self.edges, self.nperseg,
                             series.temp_c)
        self.corr = (None if cm is None
                     else tau_correlation(cm, self.afs, n, series.rate_hz)[:len(self.tau_s),
                                                                           :len(self.tau_s)])
        # a block the real part lacks makes its increments' count differ from the
        # covariance's, and the level test NaN (curves.gls_against)
        self.temp = None if cm is None else RecordTemperature(cm, series)
        """The part's temperature blocks and the covariance of their increments under the
        model it was set up with (None without a model; :meth:`compare` makes the test
        under another model's, :meth:`RecordTemperature.for_model`)."""
        self.det: np.ndarray | float = 0.0
        """The deterministic part taken out of the record and of every realisation
        compared with it (:meth:`less`; 0.0 for the part as recorded)."""

    @functools.cached_property
    def temperature_tau_s(self) -> float:
        """The temperature's own time scale (s): the analysed tau at which the part's
        temperature has its largest overlapping Allan variance; inf where none is finite
        (or without a temperature). Unchanged by :meth:`less`, whose copies keep it."""
        s = self.series
        if s.temp_c is None:
            return math.inf
        avar = oavar_at(np.asarray(s.temp_c, dtype=float), s.rate_hz,
                        self.afs)[:len(self.tau_s)]
        ok = np.isfinite(avar)
        return float(self.tau_s[ok][np.argmax(avar[ok])]) if ok.any() else math.inf

    def less(self, det: np.ndarray | float) -> PartSetup:
        """This part with ``det`` (a deterministic part over its samples: the kept
        effects' temperature response, ramp and bias step; 0.0 for none) taken out of the
        record, and out of each realisation :meth:`sim_features` is given: the
        realisations of a model with those effects carry the same ``det``, so what each
        holds then is noise. The forward selection fits its candidates on such a view
        (:attr:`imubench.gap.step.Step.noise_feats` says why)."""
        if np.ndim(det) == 0 and float(det) == 0.0:
            return self
        view = copy.copy(self)
        view.det = det
        s = self.series
        view.series = Series(s.y - det, s.temp_c, s.rate_hz, s.name)
        view.ci_s = _allan_spread(view.series, self.afs)[1]
        view.real = features(view.series.y, s.rate_hz, self.afs, self.edges, self.nperseg,
                             s.temp_c)
        return view

    def sim_features(self, sims: np.ndarray) -> SimFeatures:
        """The features of each realisation (rows of ``sims``) less :attr:`det`."""
        if np.ndim(self.det) > 0:
            sims = sims - self.det
        return stack([features(s, self.series.rate_hz, self.afs, self.edges, self.nperseg,
                               self.series.temp_c) for s in sims])

    def compare(self, sims: SimFeatures, noise: ChannelModel | None = None) -> Comparison:
        """The part against the realisations' features ``sims``; the temperature level
        test under the covariance of ``noise``'s noise (the model realised in ``sims``;
        None: the model this part was set up with, :meth:`RecordTemperature.for_model`)."""
        temp = self.temp if noise is None or self.temp is None else self.temp.for_model(noise)
        return compare(self.real, self.ci_s, sims, self.tau_s, self.edges, self.corr,
                       None if temp is None else temp.chol)


