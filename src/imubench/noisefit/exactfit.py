"""``fit_channel(..., method="exact")``: Whittle for the structure, exact likelihood for B and K.

Two likelihoods, each where it is accurate, with no datum counted twice:

1. The debiased Whittle fit (:mod:`.whittle`, Whittle 1953; Sykulski et al. 2019) of the
   whole periodogram chooses the structure (``terms="auto"``: filter, Gauss-Markov,
   quantization) and gives every high-frequency term: white N, quantization Q, output
   filter, ``output_white``, Gauss-Markov. Their information comes from thousands of
   frequencies above ~0.02 Hz, where Whittle is efficient.
2. Flicker B and random walk K are then re-estimated by the *exact* Gaussian likelihood of
   the differenced block means (:mod:`.blockmean`), with the terms of step 1 held at their
   Whittle values inside the block means' covariance. Only this likelihood speaks about B
   and K, so nothing is counted twice. Holding N fixed costs nothing measurable: N's
   relative spread is 1e-3, and in the whole record's Fisher information the correlation
   of ln N^2 with ln K^2 is 0.06 (bench configuration); the block means alone hardly see
   N (their Cramer-Rao spread of ln K is 0.230 with N free, 0.216 with N known).

Why: the random walk is visible only in the lowest ~10 Fourier frequencies of a 3 h
record. There the Whittle likelihood (exponential ordinates of a tapered periodogram) is
far from its asymptotics: on the independent-generator bench its ln K spread was 0.34,
while the Cramer-Rao bound is 0.217 (expected information of the whole record,
sum_j (d ln S_j / d ln theta)^2 over the Fourier frequencies of the increments; the
tapered, debiased Whittle information gives 0.221, the exact block-mean likelihood with N
known 0.216 at m = 540). The price: B is estimated from the block means only (Cramer-Rao
spread of ln B 0.045 against 0.038 for the whole record).

**Estimates.** theta = (B^2, K^2) maximise the block likelihood; the search is a Newton
iteration in phi = log theta with a finite-difference gradient and Hessian (step
:data:`STEP`), halving steps that do not lower -log L; the boundary K = 0 is fitted
separately (1-D) and kept when its likelihood is not lower.

**Selection** (``terms="auto"``): K is kept when LR = 2 (l_{K=0} - l_hat) >= ``TERM_LR``
(5.41: under K = 0, LR ~ 1/2 chi2_0 + 1/2 chi2_1, Self & Liang 1987, so a 1 % false-term
rate, the level :mod:`.whittle` uses for every linear term). Flicker is fitted when step 1
kept it.

**Intervals.** K: profile likelihood, {K: 2 (l_p(K) - l_hat) <= 3.84} with l_p(K) the
likelihood minimised over B (Cox & Hinkley 1974, sec. 9.3; honest near the boundary where
a Wald interval is not); the lower end is 0 when the boundary is inside. A dropped K
gets (0, one-sided 95 % upper limit), 2 (l_p - l_hat) = 2.71. B: Wald in log B^2 from
the observed information (the Newton Hessian). N and the other step-1 terms keep their
Whittle intervals.

**Not supported**: NaN gaps (the block means of a gappy record are not a Toeplitz
problem): refused with a message pointing to ``whittle``. Ramp and sine as for whittle.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from imubench.noisefit.blockmean import (
    block_increments,
    block_length,
    term_acv,
    toeplitz_nll,
)
from imubench.noisefit.errors import FitError
from imubench.noisefit.fit import ChannelFit, check_series, parse_terms
from imubench.noisefit.whittle import TERM_LR, Z95, fit_whittle

STEP: float = 0.05
"""Finite-difference step in log theta for the gradient and Hessian."""
CHI2_1_95: float = 3.841459
"""chi2_1 0.95 quantile: two-sided 95 % profile interval."""
CHI2_1_90: float = 2.705543
"""chi2_1 0.90 quantile: one-sided 95 % upper limit."""
FREE: tuple[str, ...] = ("flicker", "random_walk")
FIXED_KEYS: dict[str, str] = {"white": "white", "quantization": "quantization",
                              "markov": "markov_sigma", "output_white": "output_white"}
_LOG_FLOOR: float = -80.0
PROFILE_SPAN: float = 46.0
"""Farthest the profile interval of log K^2 is searched from the estimate (K^2 x 1e+-20)."""


@dataclass
class BlockModel:
    """Block-mean increments and the unit covariances of the free terms."""

    d: np.ndarray
    fixed: np.ndarray
    unit: dict[str, np.ndarray]

    def nll(self, thetas: np.ndarray, names: Sequence[str]) -> np.ndarray:
        """-log L at each row of ``thetas`` (squared amplitudes of ``names``)."""
        acv = np.tile(self.fixed, (thetas.shape[0], 1))
        for j, name in enumerate(names):
            acv += thetas[:, j:j + 1] * self.unit[name][None, :]
        return toeplitz_nll(acv, self.d)


def _newton(f: Callable[[np.ndarray], np.ndarray], x0: np.ndarray, max_iter: int = 30
            ) -> tuple[np.ndarray, float, np.ndarray]:
    """Minimise f (batched: rows -> values) by Newton with a finite-difference stencil.

    Returns (x, f(x), Hessian at x). The stencil is the centre, +-h on each axis and +h
    on each pair (the cross derivatives), evaluated in one batch.
    """
    p = x0.size
    h = STEP
    x = x0.astype(np.float64).copy()
    eye = np.eye(p)
    pairs = [(a, b) for a in range(p) for b in range(a + 1, p)]
    hess = np.eye(p)
    fx = float(f(x[None, :])[0])
    for _ in range(max_iter):
        pts = [x] + [x + h * eye[a] for a in range(p)] + [x - h * eye[a] for a in range(p)]
        pts += [x + h * (eye[a] + eye[b]) for a, b in pairs]
        v = f(np.array(pts))
        f0, fp, fm = v[0], v[1:p + 1], v[p + 1:2 * p + 1]
        grad = (fp - fm) / (2 * h)
        hess = np.diag((fp - 2 * f0 + fm) / h**2)
        for k, (a, b) in enumerate(pairs):
            hess[a, b] = hess[b, a] = (v[2 * p + 1 + k] - fp[a] - fp[b] + f0) / h**2
        fx = float(f0)
        w, vecs = np.linalg.eigh(hess)
        step = -(vecs @ ((vecs.T @ grad) / np.maximum(np.abs(w), 1e-3)))
        step = np.clip(step, -3.0, 3.0)
        moved = False
        for _half in range(8):
            cand = np.maximum(x + step, _LOG_FLOOR)
            fc = float(f(cand[None, :])[0])
            if fc < fx:
                moved = True
                break
            step *= 0.5
        if not moved:
            break
        done = fx - fc < 1e-6
        x, fx = cand, fc
        if done:
            break
    return x, fx, hess


@dataclass
class _Profile:
    """Profile likelihood of log K^2, minimised over the other free terms."""

    model: BlockModel
    names: tuple[str, ...]
    k_index: int
    others_start: np.ndarray

    def at(self, log_k2: float) -> float:
        others = [j for j in range(len(self.names)) if j != self.k_index]
        if not others:
            return float(self.model.nll(np.array([[math.exp(log_k2)]]), self.names)[0])

        def f(rows: np.ndarray) -> np.ndarray:
            full = np.empty((rows.shape[0], len(self.names)))
            full[:, others] = np.exp(rows)
            full[:, self.k_index] = math.exp(log_k2)
            return self.model.nll(full, self.names)

        if len(others) > 1:
            x, fx, _ = _newton(f, self.others_start, max_iter=6)
            self.others_start = x
            return fx
        return self._parabola(f)

    def _parabola(self, f: Callable[[np.ndarray], np.ndarray]) -> float:
        """1-D minimum from one batch of 5 points at +-STEP, +-2 STEP (least-squares
        parabola), recentred while the vertex falls outside them: -log L is close to
        quadratic in log B^2 over such ranges (its spread is ~0.1)."""
        offsets = STEP * np.array([-2.0, -1.0, 0.0, 1.0, 2.0])
        centre = float(self.others_start[0])
        value = math.inf
        for _ in range(4):
            xs = centre + offsets
            vals = f(xs[:, None])
            c2, c1, c0 = np.polyfit(offsets, vals, 2)
            if not c2 > 0:
                i = int(np.argmin(vals))
                centre, value = float(xs[i]), float(vals[i])
                continue
            shift = -c1 / (2.0 * c2)
            value = float(c0 - c1 * c1 / (4.0 * c2))
            if abs(shift) <= 2.0 * STEP:
                centre += shift
                break
            centre += float(np.clip(shift, -6.0 * STEP, 6.0 * STEP))
        self.others_start = np.array([centre])
        return value


def _profile_end(prof: _Profile, best: float, start: float, se: float, level: float,
                 sign: float) -> float:
    """log K^2 where 2 (l_p - best) = level on the side ``sign`` (+1 up, -1 down).

    The signed root r(psi) = sign sqrt(2 (l_p - best)) is nearly linear in psi; secant
    steps on r from the Wald guess, bracketing as needed.
    """
    target = math.sqrt(level)
    psi0, r0 = start, 0.0
    psi1 = start + sign * max(se, 0.05) * target
    edge = start + sign * PROFILE_SPAN
    for _ in range(12):
        r1 = math.sqrt(max(2.0 * (prof.at(psi1) - best), 0.0))
        if abs(r1 - target) < 0.02 or psi1 == edge:
            return psi1
        slope = (r1 - r0) / abs(psi1 - psi0) if abs(psi1 - psi0) > 0 else 0.0
        nxt = psi1 + sign * ((target - r1) / slope if slope > 1e-6 else 2.0 * abs(psi1 - psi0))
        # a flat profile (K barely identified) sends the secant far: stop at the span's
        # edge, where the interval end is "not bounded by the data" (K^2 x e^46 ~ 1e20)
        nxt = min(nxt, edge) if sign > 0 else max(nxt, edge)
        psi0, r0, psi1 = psi1, r1, nxt
    return psi1


def _scan_start(f: Callable[[np.ndarray], np.ndarray], start: np.ndarray, k: int
                ) -> np.ndarray:
    """Start for log K^2: the best of a batch spanning 8 decades around the start (the
    likelihood is flat in log K^2 far below its estimate, so Newton cannot climb there)."""
    grid = start[k] + np.linspace(-4.0, 14.0, 10)
    rows = np.tile(start, (grid.size, 1))
    rows[:, k] = grid
    best = rows[int(np.argmin(f(rows)))]
    return np.asarray(best)


def fit_exact(y: np.ndarray, rate_hz: float, *, terms: str | Iterable[str] = "auto",
              channel: str = "gx", taus: Sequence[float] | None = None) -> ChannelFit:
    """Whittle structure and high-frequency terms, exact block likelihood for B, K."""
    arr = check_series(y, rate_hz, channel)
    if np.isnan(arr).any():
        raise FitError(f"fit {channel}: the exact method needs a record without gaps "
                       "(NaN samples); use --method whittle")
    wanted = parse_terms(terms)
    base = fit_whittle(arr, rate_hz, terms=terms, channel=channel, taus=taus)
    p = base.params
    if wanted is None:
        names = tuple(t for t in FREE if t == "random_walk" or t in base.present)
    else:
        names = tuple(t for t in FREE if t in wanted)
    if not names:
        return replace(base, method="exact")
    m = block_length(arr.size)
    d = block_increments(arr, m)
    n_lags = d.size
    bw = p["bandwidth_hz"] if "bandwidth_hz" in base.present else 0.0
    order = int(p["filter_order"])

    def unit(term: str) -> np.ndarray:
        return term_acv(term, m, n_lags, rate_hz, tau_c_s=p["markov_tau"],
                        bandwidth_hz=bw, filter_order=order)

    fixed = np.zeros(n_lags)
    for term, key in FIXED_KEYS.items():
        if p[key] > 0:
            fixed += p[key] ** 2 * unit(term)
    model = BlockModel(d, fixed, {t: unit(t) for t in names})
    start = np.array([2.0 * math.log(max(p[t], 1e-3 * base.ci.get(t, (0.0, 0.0))[1],
                                         1e-12)) for t in names])

    def f_all(rows: np.ndarray) -> np.ndarray:
        return model.nll(np.exp(rows), names)

    if "random_walk" in names:
        start = _scan_start(f_all, start, names.index("random_walk"))
    x_hat, nll_hat, hess = _newton(f_all, start)
    notes = list(base.notes)
    reasons = dict(base.reasons)
    k = names.index("random_walk") if "random_walk" in names else -1
    theta = np.exp(x_hat)
    nll_0 = math.inf
    if k >= 0:
        others = [j for j in range(len(names)) if j != k]
        if others:
            def f_0(rows: np.ndarray) -> np.ndarray:
                full = np.zeros((rows.shape[0], len(names)))
                full[:, others] = np.exp(rows)
                return model.nll(full, names)

            x0, nll_0, _ = _newton(f_0, x_hat[others])
        else:
            x0, nll_0 = np.zeros(0), float(model.nll(np.zeros((1, 1)), names)[0])
        if nll_0 <= nll_hat:
            theta = np.zeros(len(names))
            theta[others] = np.exp(x0)
            nll_hat = nll_0
    params = dict(p)
    ci = dict(base.ci)
    present = [key for key in base.present if key not in FREE]
    for j, term in enumerate(names):
        params[term] = math.sqrt(theta[j])
    if "flicker" in names:
        j = names.index("flicker")
        cov = np.linalg.pinv(hess) if theta[j] > 0 else np.zeros_like(hess)
        half = Z95 * math.sqrt(max(float(cov[j, j]), 0.0))
        ci["flicker"] = (math.sqrt(theta[j] * math.exp(-half)),
                         math.sqrt(theta[j] * math.exp(half)))
        present.append("flicker")
    if k >= 0:
        lr = max(2.0 * (nll_0 - nll_hat), 0.0)
        keep = wanted is not None or lr >= TERM_LR
        se = (math.sqrt(max(float(np.linalg.pinv(hess)[k, k]), 0.0))
              if theta[k] > 0 else 1.0)
        psi = math.log(theta[k]) if theta[k] > 0 else x_hat[k]
        prof = _Profile(model, names, k, np.delete(x_hat, k))
        level = CHI2_1_95 if keep else CHI2_1_90
        upper = math.exp(0.5 * _profile_end(prof, nll_hat, psi, se, level, +1.0))
        inside = 2.0 * (nll_0 - nll_hat) <= level
        lower = 0.0 if (inside or not keep) else math.exp(
            0.5 * _profile_end(prof, nll_hat, psi, se, level, -1.0))
        if keep and theta[k] > 0:
            present.append("random_walk")
            ci["random_walk"] = (lower, upper)
            reasons["random_walk"] = (f"kept, block likelihood LR {lr:.1f}"
                                      + (f" >= {TERM_LR}" if wanted is None else ", listed"))
        else:
            params["random_walk"] = 0.0
            ci["random_walk"] = (0.0, upper)
            reasons["random_walk"] = (f"dropped, block likelihood LR {lr:.2f} < {TERM_LR} "
                                      "(one-sided 95 % upper limit from the profile)")
    order_keys = [key for key in params if key in present]
    notes.append(f"exact: flicker and random walk from the Gaussian likelihood of "
                 f"{d.size} differenced means of {m}-sample blocks, -log L = {nll_hat:.6g}")
    return replace(base, method="exact", params=params, ci=ci, present=tuple(order_keys),
                   notes=tuple(notes), reasons=reasons)


__all__ = ["CHI2_1_90", "CHI2_1_95", "BlockModel", "fit_exact"]
