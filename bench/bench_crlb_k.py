"""Cramer-Rao bounds on ln N, ln B, ln K for the round-trip configuration (issue 14).

Three informations for (ln N^2, ln B^2, ln K^2) at the truth, 3 h at 100 Hz by default:

* whole record, exact Gaussian likelihood of the increments, periodogram form
  F_ab = sum_j (d ln S_j / d theta_a)(d ln S_j / d theta_b) over the Fourier frequencies
  nu_j = j/M, 0 < j < M/2, with the increments' exact PSDs (white 4 sin^2(pi nu)/tau0,
  flicker 2 sin(pi nu), random walk tau0 (1 - 2/3 sin^2(pi nu))): Whittle 1953, the
  asymptotic information of a stationary Gaussian series;
* debiased Whittle (``whittle``'s taper and bands): sum_b L_b f_a f_b / f^2;
* exact block-mean likelihood (``exact``): F_ab = 1/2 tr(S^-1 S_a S^-1 S_b) with S the
  Toeplitz covariance of the differenced block means (dense, O(n^3)), N free and known.

Prints sd(ln K) = sd(ln K^2)/2 and the median |K_hat/K - 1| an unbiased, efficient, log-normal
estimator would have. ~1 min.

    .venv/bin/python bench/bench_crlb_k.py [--hours 3]
"""

from __future__ import annotations

import argparse
import math

import numpy as np
from scipy.linalg import cho_factor, cho_solve, toeplitz
from scipy.optimize import brentq
from scipy.stats import norm

from imubench.noisefit import whittle
from imubench.noisefit.blockmean import block_length, term_acv

RATE_HZ = 100.0
TRUTH: dict[str, float] = {"white": 0.004, "flicker": 0.0015, "random_walk": 1e-4}


def periodogram_information(n: int) -> np.ndarray:
    tau0 = 1.0 / RATE_HZ
    m = n - 1
    s = np.pi * np.arange(1, (m - 1) // 2 + 1) / m
    psd = {"white": 4 * np.sin(s) ** 2 / tau0, "flicker": 2 * np.sin(s),
           "random_walk": tau0 * (1 - 2 / 3 * np.sin(s) ** 2)}
    total = sum(v**2 * psd[t] for t, v in TRUTH.items())
    d = np.array([v**2 * psd[t] / total for t, v in TRUTH.items()])
    return np.asarray(d @ d.T)


def whittle_information(n: int) -> np.ndarray:
    sp = whittle.spectrum(np.random.default_rng(0).standard_normal(n), RATE_HZ)
    cols = [v**2 * sp.band_mean(whittle.term_basis(t, sp)) for t, v in TRUTH.items()]
    u = np.column_stack(cols) / sum(cols)[:, None]
    return np.asarray((u * sp.weight[:, None]).T @ u)


def block_information(n: int) -> tuple[np.ndarray, int]:
    m = block_length(n)
    lags = n // m - 1
    acvs = [v**2 * term_acv(t, m, lags, RATE_HZ) for t, v in TRUTH.items()]
    cf = cho_factor(toeplitz(sum(acvs)))
    a = [cho_solve(cf, toeplitz(g)) for g in acvs]
    return np.array([[0.5 * np.sum(x * y.T) for y in a] for x in a]), m


def median_error(sd_log: float) -> float:
    """c with P(|exp(x) - 1| < c) = 1/2 for x ~ N(0, sd_log^2)."""
    def share(c: float) -> float:
        return float(norm.cdf(math.log1p(c) / sd_log) - norm.cdf(math.log1p(-c) / sd_log))
    return float(brentq(lambda c: share(c) - 0.5, 1e-6, 0.99))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=3.0)
    n = round(ap.parse_args().hours * 3600 * RATE_HZ)
    blocks, m = block_information(n)
    rows = [("whole record (periodogram form)", periodogram_information(n)),
            ("debiased Whittle (taper, bands)", whittle_information(n)),
            (f"block means m = {m}, N free", blocks)]
    print("| information | sd ln N | sd ln B | sd ln K | median error K (efficient) |")
    print("|---|---|---|---|---|")
    for name, info in rows:
        sd = 0.5 * np.sqrt(np.diag(np.linalg.inv(info)))
        print(f"| {name} | {sd[0]:.4f} | {sd[1]:.4f} | {sd[2]:.4f} | "
              f"{100 * median_error(float(sd[2])):.1f} % |")
    sd_known = 0.5 * np.sqrt(np.diag(np.linalg.inv(blocks[1:, 1:])))
    print(f"| block means m = {m}, N known | - | {sd_known[0]:.4f} | {sd_known[1]:.4f} | "
          f"{100 * median_error(float(sd_known[1])):.1f} % |")


if __name__ == "__main__":
    main()
