"""How well could any estimator see the blind set's withheld effects? Oracles that know
the true noise spectrum, for the cases ``imubench gap`` misses (issue 15).

**Part 1, the pair ``markov+temperature``.** The pair of ``bench_gap_blind.py --pairs``
adds a Gauss-Markov term (sigma 4 mdps, tau_c 30 s) and a temperature response (1e-3
dps/degC on the generator's +-4 degC profile, periods 23-31 min and 6-9 min). Both of the
temperature's periods lie inside the Markov term's flat band (corner 1 / (2 pi 30 s) = 5.3
mHz), where its one-sided PSD 4 sigma^2 tau_c = 1.9e-3 dps^2/Hz is ~60 times the white
noise's. The best linear unbiased estimate of the coefficient with the true PSD known is
the frequency-domain generalised least squares (Whittle) estimate (Brillinger, "Time
Series: Data Analysis and Theory", 1981, ch. 6), on the DFTs Y_k of the rate and T_k of
the temperature:

    a = sum_k w_k Re(conj(T_k) Y_k) / sum_k w_k |T_k|^2,   w_k = 1 / S_k,
    var(a) = sum_k w_k^2 |T_k|^2 S_k n fs / 4 / (sum_k w_k |T_k|^2)^2,

with E|Y_k|^2 = S_k n fs / 2 (the convention of ``bench_gap_blind.spectral``), of which the
real part carries half. The script draws the pair's records with the blind bench's own
generator (its seeds, not the split's: the oracle's spread is a property of the magnitudes),
and prints the oracle estimate's spread and its z of the truth on the fit half (the first
30 min, where the diagnosis selects) and on the whole hour.

**Part 2, the spectral effects alone.** For an effect that only adds to the spectrum, S1 =
S0 + S_e, the Neyman-Pearson test of "S0" against "S1" on the periodogram (Whittle: the
ordinates I_k independent, exponential of mean S(f_k)) has the log-likelihood ratio
sum_k [ln(S0/S1) + I_k (1/S0 - 1/S1)]; with r_k = S_e / S0 small its means under the two
hypotheses are d'^2 apart in units of its standard deviation, d'^2 = sum_k r_k^2 (over the
Fourier frequencies 0 < f_k < fs / 2). A nuisance the test must estimate (the white level,
when the model's is not taken as known) takes out the part of r along its own score
v_k = 2 N^2 / S0_k: d'^2 = sum r^2 - (sum r v)^2 / sum v^2 (the efficient information;
Whittle 1953, Ark. Mat. 2, 423; Brockwell and Davis 1991, sec. 10.8). No test of the
record's spectrum separates the two better; a test at a one-sided threshold z_th detects
the effect with probability Phi(d' - z_th). Printed for each spectral effect of the blind
set at its clear and near magnitudes, on the fit half and on the whole hour. The
independence of the ordinates is Whittle's approximation: a Monte Carlo of the same
log-likelihood ratio on the generator's records (``--records`` of each hypothesis, the fit
half) checks it for the near sizes of the quantization (a high-frequency effect) and the
Markov term (a low-frequency one, where flicker's ordinates are correlated by leakage and
the approximation is optimistic).

**Part 3, look-alikes.** Telling an effect from another spectral effect is the same test
between S0 + S_e and S0 + S_a with the look-alike's parameters a free: d'^2 = min_a sum
((S_e - S_a) / S)^2 (S their mean; the white level estimated as above), the minimum over a
grid of amplitudes (and of tau_c for a Gauss-Markov look-alike). A telegraph and a Markov
process have the same spectrum (d' = 0): only the level distribution tells them apart
(``imubench.gap.two_level``, measured there: 2.4 pooled standard deviations at the near
size, whole hour).

Usage: ``PYTHONPATH=src:drivers:simulator:bench python bench/bench_gap_oracle.py
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


def base_psd(f_hz: np.ndarray, lsb_rounding: bool = True) -> np.ndarray:
    """One-sided PSD (dps^2/Hz) of the blind base: white 2 N^2, flicker B^2 / (pi f), and
    the LSB rounding's white 2 (LSB^2 / 12) / fs (left out where the converter is the angle
    quantizer, :func:`bench_gap_blind.model_toml`)."""
    out = 2.0 * blind.WHITE**2 + blind.FLICKER**2 / (math.pi * f_hz)
    if lsb_rounding:
        out = out + 2.0 * blind.LSB**2 / 12.0 / blind.RATE
    return out


def effect_psd(effect: str, p: dict[str, float], f_hz: np.ndarray) -> np.ndarray:
    """One-sided PSD (dps^2/Hz) an effect of the blind generator adds: Gauss-Markov 4
    sigma^2 tau_c / (1 + (2 pi f tau_c)^2) (a telegraph has the same, Machlup 1954); angle
    quantization of step S = sqrt(12) Q differenced over tau0 (IEEE 952 C.2), (2 Q^2 /
    (tau0^2 fs)) 4 sin^2(pi f / fs); added flicker B^2 / (pi f); random walk K^2 / (2 pi^2
    f^2); the Lorentzian resonance at its clear centre 15 Hz (the draw is 5-25 Hz)."""
    fs = blind.RATE
    if effect == "markov":
        s, tau = p["markov_sigma"], p["markov_tau"]
        return 4.0 * s**2 * tau / (1.0 + (2.0 * math.pi * f_hz * tau) ** 2)
    if effect == "telegraph":
        return effect_psd("markov", {"markov_sigma": p["telegraph_step"] / 2.0,
                                     "markov_tau": p["telegraph_dwell_s"] / 2.0}, f_hz)
    if effect == "quantization":
        k = max(1, round(math.sqrt(12.0) * p["quantization"] * fs / blind.LSB))
        q2 = (k * blind.LSB / fs) ** 2 / 12.0  # the step drawn, as _angle_quantizer
        return 2.0 * q2 * fs * 4.0 * np.sin(math.pi * f_hz / fs) ** 2
    if effect == "flicker":
        return p["flicker"] ** 2 / (math.pi * f_hz)
    if effect == "random_walk":
        return p["random_walk"] ** 2 / (2.0 * math.pi**2 * f_hz**2)
    if effect == "resonance":
        return blind.line_shape("lorentzian", f_hz, 15.0, p["resonance_width_hz"],
                                p["resonance_height"])
    raise ValueError(effect)


def spectral_dprime(effect: str, p: dict[str, float], seconds: float
                    ) -> tuple[float, float]:
    """(d' with the base known, d' with the white level estimated) of ``effect`` on a
    record of ``seconds`` (part 2 of the module docstring)."""
    n = int(seconds * blind.RATE)
    f = np.fft.rfftfreq(n, 1.0 / blind.RATE)[1:-1]
    s0 = base_psd(f, lsb_rounding=effect != "quantization")
    r = effect_psd(effect, p, f) / s0
    v = 2.0 * blind.WHITE**2 / s0
    known = float(np.sum(r * r))
    return math.sqrt(known), math.sqrt(max(known - float(np.sum(r * v)) ** 2
                                           / float(np.sum(v * v)), 0.0))


def monte_carlo_dprime(effect: str, p: dict[str, float], records: int) -> float:
    """d' of part 2's log-likelihood ratio (base known) measured on ``records`` records of
    the fit half's length drawn by the blind generator without and with ``effect``."""
    fs, n = blind.RATE, int(blind.DURATION_S / 2.0 * blind.RATE)
    f_all = np.fft.rfftfreq(n, 1.0 / fs)
    f = f_all[1:-1]
    lsb = effect != "quantization"
    s0 = base_psd(f, lsb_rounding=lsb)
    s1 = s0 + effect_psd(effect, p, f)
    fl = np.zeros_like(f_all)
    fl[1:] = 1.0 / (math.pi * f_all[1:])

    def llr(y: np.ndarray) -> float:
        per = np.abs(np.fft.rfft(y - y.mean())[1:-1]) ** 2 * 2.0 / (n * fs)  # E = S
        return float(np.sum(np.log(s0 / s1) + per * (1.0 / s0 - 1.0 / s1)))

    null, alt = [], []
    for r in range(records):
        rng = np.random.default_rng([0x0AC1E, 2, r])
        if lsb:
            y0, _ = blind.generate(rng, [], n, fs, np.zeros(n))
        else:  # the converter is the quantizer: no LSB rounding in the base
            y0 = (blind.WHITE * math.sqrt(fs) * rng.standard_normal(n)
                  + blind.spectral(rng, n, fs, blind.FLICKER**2 * fl))
        null.append(llr(y0))
        y1, _ = blind.generate(rng, [(effect, p)], n, fs, np.zeros(n))
        alt.append(llr(y1))
    a, b = np.array(null), np.array(alt)
    return float((b.mean() - a.mean()) / math.sqrt(0.5 * (a.var(ddof=1) + b.var(ddof=1))))


def lookalike_dprime(effect: str, p: dict[str, float], alt: str, seconds: float) -> float:
    """d' between ``effect`` and the closest ``alt`` (part 3 of the module docstring)."""
    n = int(seconds * blind.RATE)
    f = np.fft.rfftfreq(n, 1.0 / blind.RATE)[1:-1]
    s0 = base_psd(f)
    se = effect_psd(effect, p, f)
    v = 2.0 * blind.WHITE**2 / s0
    grids: dict[str, list[dict[str, float]]] = {
        "flicker": [{"flicker": b} for b in np.geomspace(1e-4, 1e-2, 241)],
        "random_walk": [{"random_walk": k} for k in np.geomspace(1e-6, 1e-3, 241)],
        "markov": [{"markov_sigma": sg, "markov_tau": t} for sg in np.geomspace(2e-4, 2e-2, 81)
                   for t in np.geomspace(0.2, 2000.0, 81)],
    }
    best = math.inf
    for a in grids[alt]:
        sa = effect_psd(alt, a, f)
        q = (se - sa) / (s0 + 0.5 * (se + sa))
        d2 = float(np.sum(q * q)) - float(np.sum(q * v)) ** 2 / float(np.sum(v * v))
        best = min(best, d2)
    return math.sqrt(max(best, 0.0))


LOOKALIKES = {"markov": ("flicker", "random_walk"), "flicker": ("markov", "random_walk"),
              "random_walk": ("markov", "flicker")}
"""Each spectral effect's look-alikes among the gap's candidates (part 3)."""
SPECTRAL = ("quantization", "markov", "telegraph", "flicker", "random_walk", "resonance")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--records", type=int, default=30)
    args = ap.parse_args(argv)
    fs, n = blind.RATE, int(blind.DURATION_S * blind.RATE)
    print(f"# bench_gap_oracle {time.strftime('%Y-%m-%d %H:%M')} "
          f"{platform.machine()} records={args.records}")
    print("## part 1: the temperature response beside the Markov term (markov+temperature)")
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
    print("## part 2: spectral effects alone, d' of the best test of the record's spectrum "
          "(base known / white level estimated)")
    for effect in SPECTRAL:
        for size, p in zip(("clear", "near"), blind.EFFECTS[effect], strict=True):
            half = spectral_dprime(effect, p, blind.DURATION_S / 2.0)
            whole = spectral_dprime(effect, p, blind.DURATION_S)
            print(f"{effect:12s} {size:5s} {p}: fit half d' {half[0]:6.1f} / {half[1]:6.1f}; "
                  f"whole hour {whole[0]:6.1f} / {whole[1]:6.1f}")
    for effect in ("quantization", "markov"):
        p = blind.EFFECTS[effect][1]
        print(f"  Monte Carlo check, {effect} near, fit half, base known: d' "
              f"{monte_carlo_dprime(effect, p, args.records):.1f} ({args.records} records "
              f"each) against {spectral_dprime(effect, p, blind.DURATION_S / 2.0)[0]:.1f}")
    print("## part 3: look-alikes, d' from the closest look-alike (white level estimated)")
    for effect, alts in LOOKALIKES.items():
        for size, p in zip(("clear", "near"), blind.EFFECTS[effect], strict=True):
            print(f"{effect:12s} {size:5s} " + "; ".join(
                f"from {alt}: fit half {lookalike_dprime(effect, p, alt, 1800.0):5.1f}, "
                f"hour {lookalike_dprime(effect, p, alt, 3600.0):5.1f}" for alt in alts))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
