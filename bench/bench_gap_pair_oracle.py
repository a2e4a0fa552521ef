"""How well could any estimator see the temperature response of the blind pair
``markov+temperature``? An oracle that knows the true noise spectrum.

The pair of ``bench_gap_blind.py --pairs`` adds a Gauss-Markov term (sigma 4 mdps, tau_c
30 s) and a temperature response (1e-3 dps/degC on the generator's +-4 degC profile, periods
23-31 min and 6-9 min). Both of the temperature's periods lie inside the Markov term's flat
band (corner 1 / (2 pi 30 s) = 5.3 mHz), where its one-sided PSD 4 sigma^2 tau_c = 1.9e-3
dps^2/Hz is ~6000 times the white noise's. The best linear unbiased estimate of the
coefficient with the true PSD known is the frequency-domain generalised least squares
(Whittle) estimate (Brillinger, "Time Series: Data Analysis and Theory", 1981, ch. 6), on
the DFTs Y_k of the rate and T_k of the temperature:

    a = sum_k w_k Re(conj(T_k) Y_k) / sum_k w_k |T_k|^2,   w_k = 1 / S_k,
    var(a) = sum_k w_k^2 |T_k|^2 S_k n fs / 4 / (sum_k w_k |T_k|^2)^2,

with E|Y_k|^2 = S_k n fs / 2 (the convention of ``bench_gap_blind.spectral``), of which the
real part carries half. The script draws the pair's records with the blind bench's own
generator (its seeds, not the split's: the oracle's spread is a property of the magnitudes),
and prints the oracle estimate's spread and its z of the truth on the fit half (the first
30 min, where the diagnosis selects) and on the whole hour.

Usage: ``PYTHONPATH=src:drivers:simulator:bench python bench/bench_gap_pair_oracle.py
[--records 30]``
"""

from __future__ import annotations

import argparse
import math
import platform
import time

import bench_gap_blind as blind
import numpy as np

MARKOV = {"markov_sigma": 0.004, "markov_tau": 30.0}
TEMP_COEFF = 1e-3


def true_psd(f_hz: np.ndarray) -> np.ndarray:
    """One-sided PSD (dps^2/Hz) of the generator's white + flicker + Markov noise: white
    ``N / sqrt(tau0)`` per sample is 2 N^2, flicker B^2 / (pi f), Markov 4 sigma^2 tau_c /
    (1 + (2 pi f tau_c)^2)."""
    sig, tau = MARKOV["markov_sigma"], MARKOV["markov_tau"]
    return (2.0 * blind.WHITE**2 + blind.FLICKER**2 / (math.pi * f_hz)
            + 4.0 * sig**2 * tau / (1.0 + (2.0 * math.pi * f_hz * tau) ** 2))


def oracle(y: np.ndarray, temp: np.ndarray, fs: float) -> tuple[float, float]:
    """(coefficient in dps/degC, its standard error) by frequency-domain GLS."""
    y = y - y.mean()
    x = temp - temp.mean()
    n = len(y)
    f = np.fft.rfftfreq(n, 1.0 / fs)[1:-1]
    yk, xk = np.fft.rfft(y)[1:-1], np.fft.rfft(x)[1:-1]
    s = true_psd(f)
    w = 1.0 / s
    info = float(np.sum(w * np.abs(xk) ** 2))
    a = float(np.sum(w * np.real(np.conj(xk) * yk))) / info
    se = math.sqrt(float(np.sum(w**2 * np.abs(xk) ** 2 * s)) * n * fs / 4.0) / info
    return a, se


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--records", type=int, default=30)
    args = ap.parse_args(argv)
    fs, n = blind.RATE, int(blind.DURATION_S * blind.RATE)
    print(f"# bench_gap_pair_oracle {time.strftime('%Y-%m-%d %H:%M')} "
          f"{platform.machine()} records={args.records}")
    got: dict[str, list[tuple[float, float]]] = {"fit half": [], "whole hour": []}
    for r in range(args.records):
        rng = np.random.default_rng([0x0AC1E, r])
        temp = blind.temperature(rng, n, fs)
        y, _ = blind.generate(rng, [("markov", MARKOV),
                                    ("temperature", {"temp_coeff": TEMP_COEFF})], n, fs, temp)
        got["fit half"].append(oracle(y[: n // 2], temp[: n // 2], fs))
        got["whole hour"].append(oracle(y, temp, fs))
    for part, res in got.items():
        a = np.array([g[0] for g in res])
        se = np.array([g[1] for g in res])
        z = a / se
        print(f"{part:10s}: estimate {np.mean(a) * 1e3:.3f} +- {np.std(a, ddof=1) * 1e3:.3f} "
              f"mdps/degC (truth {TEMP_COEFF * 1e3:g}; formula se median "
              f"{np.median(se) * 1e3:.3f}); truth / spread {TEMP_COEFF / np.std(a, ddof=1):.1f};"
              f" z median {np.median(z):.1f}, z >= 4 in {np.mean(z >= 4):.0%}, z >= 5 in "
              f"{np.mean(z >= 5):.0%}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
