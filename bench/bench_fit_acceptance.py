"""Issue 14 acceptance figures of the noise fit's model selection. Prints tables; no asserts.

Part 1, false terms: records of every shipped chip model (``datasheet:lsm6ds3h``,
``datasheet:lsm6dsl``, ``datasheet:lsm6dsm``, i.e. white + flicker + random walk +
temperature coefficient on six channels) and of each model with one noise term absent in
turn are simulated with the project's simulator (``lsm6ds_sim.physics.simulate``, 30 min
at 104 Hz, constant 25 degC so the temperature coefficient adds nothing) and fitted
(``fit_channel``, ``terms="auto"``). A channel fit counts as *false* when it reports a
term (white, flicker, random_walk, ramp, quantization, markov, sine, filter) whose
amplitude in the truth is zero. Target: at most 2 % of channel fits. The rate is given
with its Clopper-Pearson 95 % interval. ``--log`` appends one JSON line per channel fit
(truth, terms reported, reasons, chi2 drops), so a long run that is stopped still counts
(``--summarize LOG`` prints its tables); seeds are the outer loop. The run also prints
the null distribution of the selection statistic: for each term, the chi2 drops of the
fits whose truth lacks it, against the threshold (the calibration by simulation).

Part 2 (round trip with an independent generator, ``--method``) is not in this module;
``PARTS`` below is where it registers.

Part 3, ADIS16405 replicates (../shared/reference/imu-real/adis16405, 3 replicates x 6
axes, 10 000 s at 100 Hz each): for every ordered pair (A, B) of replicates and every axis,
the model fitted on A predicts B's overlapping ADEV at octave taus up to T/10 (T = B's
length). The issue's metric, per case: rms_pred = RMS over those taus of
ln(ADEV_B / sqrt(AVAR_model_A)); rms_raw = the same with A's own measured ADEV curve as
the predictor; the case passes when rms_pred <= 1.10 * rms_raw ("predicts the other
replicates at least as well as that replicate's own curve", with the 10 % allowance). B is
never fitted. Target: >= 85 % of cases. Cases between replicates 1 and 2 (the only ones
looked at while tuning) and those involving replicate 3 (held out) are reported apart.
A stricter figure is printed beside it: B's own fit (an in-sample fit of B) as the
reference instead of A's raw curve.

    python bench/bench_fit_acceptance.py --part 1 --quick
    python bench/bench_fit_acceptance.py --part 1 --seeds 50 --log part1.jsonl
    python bench/bench_fit_acceptance.py --part 3
    python bench/bench_fit_acceptance.py --part 3 \
        --terms white,flicker,random_walk,quantization,markov,filter,resonance

``--terms LIST`` (part 3): every fit uses these terms instead of ``auto`` (no selection),
to measure what the model family can reach at best; ``resonance`` is kept only on the
axes whose spectrum has a narrowband peak (the fit refuses it elsewhere).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from lsm6ds_sim.model import NoiseModel, load_model
from lsm6ds_sim.physics import simulate
from scipy.stats import beta

from imubench.noisefit import ChannelFit, FitError, fit_channel
from imubench.noisefit.fit import EXTENSION_DCHI2, EXTENSIONS, entry_dchi2
from imubench.stats import oadev

CHIPS: tuple[str, ...] = ("lsm6ds3h", "lsm6dsl", "lsm6dsm")
CHANNELS: tuple[str, ...] = ("gx", "gy", "gz", "ax", "ay", "az")
RATE_HZ = 104.0
MINUTES = 30.0
NOISE_TERMS: tuple[str, ...] = ("white", "flicker", "random_walk")
"""Noise terms of the shipped models, each removed in turn for the 'absent' variants."""
TERM_KEY: dict[str, str] = {
    "white": "white", "flicker": "flicker", "random_walk": "random_walk", "ramp": "ramp",
    "quantization": "quantization", "markov": "markov_sigma", "sine": "sine_amplitude",
    "filter": "bandwidth_hz", "resonance": "resonance_height",
}
"""Term -> the model key whose non-zero value means the term is there (truth or fit)."""
REFERENCE = Path(__file__).resolve().parents[2] / "shared" / "reference" / "imu-real"


def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Exact binomial interval for k successes in n trials."""
    a = (1.0 - level) / 2.0
    lo = 0.0 if k == 0 else float(beta.ppf(a, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(1.0 - a, k + 1, n - k))
    return lo, hi


def variants(chip: str) -> dict[str, NoiseModel]:
    """The shipped model and the model with each noise term absent in turn."""
    base = load_model(f"datasheet:{chip}")
    out = {"full": base}
    for term in NOISE_TERMS:
        chans = {ch: base.channels[ch].replace(**{term: 0.0}) for ch in CHANNELS}
        out[f"no {term}"] = NoiseModel(channels=chans, meta=dict(base.meta),
                                       source=base.source)
    return out


def false_terms(fit: ChannelFit, truth: dict[str, float]) -> list[str]:
    """Terms the fit reports that the truth lacks."""
    return [t for t, key in TERM_KEY.items()
            if key in fit.present and not truth.get(key, 0.0)]


def fit_rows(seeds: range, minutes: float, log: Path | None) -> list[dict[str, object]]:
    """Simulate and fit every (seed, chip, variant, channel); one row per channel fit.

    Seeds are the outer loop, so that a run stopped early covers every model evenly.
    """
    n = round(minutes * 60 * RATE_HZ)
    rows: list[dict[str, object]] = []
    models = {chip: variants(chip) for chip in CHIPS}
    t_start = time.perf_counter()
    for seed in seeds:
        for chip, vs in models.items():
            for name, model in vs.items():
                data = simulate(model, n, RATE_HZ, seed + 1000 * CHIPS.index(chip))
                for ch in CHANNELS:
                    truth = model.channels[ch].to_dict()
                    fit = fit_channel(data[ch], RATE_HZ, channel=ch)
                    row = {"chip": chip, "variant": name, "seed": seed, "channel": ch,
                           "false": false_terms(fit, truth), "present": list(fit.present),
                           "absent_in_truth": [t for t, key in TERM_KEY.items()
                                               if not truth.get(key, 0.0)],
                           "reasons": fit.reasons, "chi2_drop": fit.chi2_drop}
                    rows.append(row)
                    if log is not None:
                        with open(log, "a", encoding="utf-8") as fh:
                            fh.write(json.dumps(row) + "\n")
        bad = sum(bool(r["false"]) for r in rows)
        print(f"seed {seed}: {len(rows)} channel fits so far, {bad} with a false term "
              f"({time.perf_counter() - t_start:.0f} s)", flush=True)
    return rows


def summarize(rows: list[dict[str, object]]) -> None:
    """Tables of part 1 from its rows (a run's, or a ``--log`` file's)."""
    groups: dict[tuple[str, str], list[dict[str, object]]] = {}
    for r in rows:
        groups.setdefault((str(r["chip"]), str(r["variant"])), []).append(r)
    print("| chip | variant | channel fits | with a false term | false terms |")
    print("|---|---|---|---|---|")
    per_term: dict[str, int] = {}
    for (chip, name), rs in groups.items():
        terms: dict[str, int] = {}
        for r in rs:
            for t in r["false"]:  # type: ignore[attr-defined]
                terms[t] = terms.get(t, 0) + 1
                per_term[t] = per_term.get(t, 0) + 1
        listed = ", ".join(f"{t} {c}" for t, c in sorted(terms.items())) or "-"
        print(f"| {chip} | {name} | {len(rs)} | {sum(bool(r['false']) for r in rs)} | "
              f"{listed} |")
    total, bad = len(rows), sum(bool(r["false"]) for r in rows)
    lo, hi = clopper_pearson(bad, total)
    seeds = len({r["seed"] for r in rows})
    print(f"\nfalse-term rate: {bad}/{total} = {100 * bad / total:.2f} % "
          f"(95 % CI {100 * lo:.2f}-{100 * hi:.2f} %; target <= 2 %) over {seeds} seeds; "
          "by term: " + (", ".join(f"{t} {c}" for t, c in sorted(per_term.items()))
                         or "none"))
    print("\nNull distribution of the selection statistic (chi2 drop) over the fits whose "
          "truth lacks the term:")
    print("| term | fits | median | 99 % | 99.9 % | max | threshold | share above |")
    print("|---|---|---|---|---|---|---|---|")
    for t in TERM_KEY:
        vals = [float(r["chi2_drop"][t]) for r in rows  # type: ignore[index]
                if t in r["absent_in_truth"] and t in r["chi2_drop"]  # type: ignore[operator]
                and r["chi2_drop"][t] is not None  # type: ignore[index]
                and math.isfinite(r["chi2_drop"][t])]  # type: ignore[index]
        if not vals:
            continue
        v = np.asarray(vals)
        thr = EXTENSION_DCHI2 if t in EXTENSIONS else entry_dchi2(t)
        print(f"| {t} | {v.size} | {np.median(v):.2f} | {np.quantile(v, 0.99):.2f} | "
              f"{np.quantile(v, 0.999):.2f} | {v.max():.2f} | {thr:g} | "
              f"{100 * np.mean(v > thr):.2f} % |")


def part1(args: argparse.Namespace) -> None:
    if args.summarize is not None:
        with open(args.summarize, encoding="utf-8") as fh:
            rows = [json.loads(line) for line in fh if line.strip()]
        print(f"\n### Part 1 from {args.summarize}: {len(rows)} channel fits")
        summarize(rows)
        return
    seeds = 2 if args.quick else args.seeds
    print(f"\n### Part 1: false terms, {seeds} seeds from {args.first_seed} x {len(CHIPS)} chips x "
          f"{1 + len(NOISE_TERMS)} variants x 6 channels, {args.minutes:g} min at "
          f"{RATE_HZ:g} Hz per record")
    summarize(fit_rows(range(args.first_seed, args.first_seed + seeds), args.minutes,
                       args.log))


def _adis(rep: int) -> dict[str, np.ndarray]:
    d = np.load(REFERENCE / "adis16405" / f"adis16405_rep{rep}.npz")
    g = d["gyro_counts"].astype(float) * float(d["gyro_lsb_dps"])
    a = d["accel_counts"].astype(float) * float(d["accel_lsb_g"])
    return dict(zip(CHANNELS, np.column_stack([g, a]).T, strict=True))


def _rms_ln(meas: np.ndarray, pred: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.log(meas / pred) ** 2)))


def _fit(y: np.ndarray, rate: float, ch: str, terms: str) -> ChannelFit:
    """``fit_channel`` with ``terms``; a forced ``resonance`` is left out on a channel
    without a narrowband peak."""
    try:
        return fit_channel(y, rate, terms=terms, channel=ch)
    except FitError as exc:
        if "resonance" not in terms.split(",") or "no narrowband peak" not in str(exc):
            raise
        rest = ",".join(t for t in terms.split(",") if t != "resonance")
        return fit_channel(y, rate, terms=rest, channel=ch)


def part3(args: argparse.Namespace) -> None:
    if not (REFERENCE / "adis16405").is_dir():
        print("ADIS16405 reference data not found; part 3 skipped")
        return
    rate = 100.0
    reps = {r: _adis(r) for r in (1, 2, 3)}
    print("\n### Part 3: ADIS16405, model of replicate A predicts replicate B "
          "(octave taus up to T/10; pass: rms_pred <= 1.10 rms_raw, A's measured curve)")
    print("| axis | A -> B | terms of A's fit | rms_pred | rms_raw (A's curve) | ratio | pass | "
          "rms_own (B's fit) | pass (vs B's fit) |")
    print("|---|---|---|---|---|---|---|---|---|")
    counts = {"tune": [0, 0, 0], "held-out": [0, 0, 0]}
    held_out: dict[str, ChannelFit] = {}
    for ch in CHANNELS:
        fits = {r: _fit(reps[r][ch], rate, ch, args.terms) for r in (1, 2, 3)}
        held_out[ch] = fits[3]
        curves = {r: oadev(reps[r][ch], rate, "freq", "octave") for r in (1, 2, 3)}
        for a in (1, 2, 3):
            for b in (1, 2, 3):
                if a == b:
                    continue
                cb = curves[b]
                keep = cb.tau_s <= reps[b][ch].size / rate / 10
                tau, meas = cb.tau_s[keep], cb.dev[keep]
                rms_pred = _rms_ln(meas, np.sqrt(fits[a].model_avar(tau)))
                rms_own = _rms_ln(meas, np.sqrt(fits[b].model_avar(tau)))
                raw_a = oadev(reps[a][ch], rate, "freq", list(tau)).dev
                rms_raw = _rms_ln(meas, raw_a)
                ok, ok_own = rms_pred <= 1.10 * rms_raw, rms_pred <= 1.10 * rms_own
                group = "tune" if 3 not in (a, b) else "held-out"
                counts[group][0] += ok
                counts[group][1] += ok_own
                counts[group][2] += 1
                terms = ",".join(k for k in fits[a].present if k != "filter_order")
                print(f"| {ch} | {a} -> {b} | {terms} | {rms_pred:.4f} | {rms_raw:.4f} | "
                      f"{rms_pred / rms_raw:.2f} | {'yes' if ok else 'NO'} | {rms_own:.4f} | "
                      f"{'yes' if ok_own else 'NO'} |", flush=True)
    for group, (n_ok, n_own, tot) in counts.items():
        print(f"{group} (replicates {'1, 2' if group == 'tune' else 'involving 3'}): "
              f"{n_ok}/{tot} = {100 * n_ok / tot:.0f} % pass (A's raw curve; target >= 85 %); "
              f"against B's own fit {n_own}/{tot} = {100 * n_own / tot:.0f} %")
    print("\nreasons of the fits of replicate 3 (held out):")
    for ch, f3 in held_out.items():
        print(f"  {ch}: " + "; ".join(f"{t}: {w}" for t, w in f3.reasons.items()))


PARTS: dict[str, Callable[[argparse.Namespace], None]] = {"1": part1, "3": part3}
"""Acceptance parts of issue 14 run by this script (part 2 lives in its own module)."""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--part", choices=sorted(PARTS), default="1")
    ap.add_argument("--quick", action="store_true",
                    help="part 1 with 2 seeds (a few minutes)")
    ap.add_argument("--seeds", type=int, default=50, help="part 1 seeds (default 50)")
    ap.add_argument("--first-seed", type=int, default=1,
                    help="part 1: first seed (default 1; seeds 1-16 were used to set the "
                    "thresholds, so the acceptance figure uses 101 on)")
    ap.add_argument("--minutes", type=float, default=MINUTES,
                    help=f"part 1 record length (default {MINUTES:g} min)")
    ap.add_argument("--log", type=Path, default=None,
                    help="part 1: append one JSON line per channel fit to this file")
    ap.add_argument("--summarize", type=Path, default=None, metavar="LOG",
                    help="part 1: print the tables from a --log file (no fitting)")
    ap.add_argument("--terms", default="auto",
                    help="part 3: the fit's terms (default auto: model selection); a list "
                         "forces them in, an upper bound for the model family")
    args = ap.parse_args()
    print(f"# bench_fit_acceptance  {platform.node()} "
          f"{platform.processor() or platform.machine()} cpus={os.cpu_count()}  "
          f"load {os.getloadavg()[0]:.1f}  {time.strftime('%Y-%m-%d %H:%M')}")
    if not math.isfinite(args.minutes) or args.minutes <= 0:
        ap.error("--minutes must be > 0")
    PARTS[args.part](args)


if __name__ == "__main__":
    main()
