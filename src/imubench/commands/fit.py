"""``imubench fit``: fit the noise model file's terms to a recording.

Writes a model file (TOML) that the simulator loads unchanged (``sim://...&model=PATH``),
and optionally the full result as JSON (per channel: parameters, 95 % intervals, terms
present, the AVAR points used, datasheet units; Kalibr values; datasheet comparison) and a
Kalibr ``imu.yaml``. See docs/noise-fit.md.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from imubench.batchrun import add_batch_options, is_batch
from imubench.commands import check_writable, write_json
from imubench.noisefit.errors import FitError
from imubench.noisefit.fit import METHODS
from imubench.noisefit.recording_fit import RecordingFit, fit_recording
from imubench.noisefit.units import (
    WHITE_EQUIVALENT,
    check_kalibr_request,
    kalibr_limit_message,
    kalibr_yaml,
    param_units,
)
from imubench.progress import progress
from imubench.recording.options import add_input_arguments, input_options


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "fit",
        help="fit the noise model (white, flicker, random walk, ...) to a recording",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("recording", type=Path,
                   help="recording (.imbr, .csv, CSV from elsewhere, text; docs/recordings.md)")
    p.add_argument("--channels", default=None,
                   help="channels to fit, e.g. gx,gy,gz (default: every channel present)")
    p.add_argument("--terms", default="auto",
                   help="auto (model selection) or a comma list of: white, flicker, "
                        "random_walk, ramp, quantization, markov, sine, filter, resonance "
                        "(wls only; at the spectrum's narrowband peak)")
    p.add_argument("--method", choices=METHODS, default="wls",
                   help="wls: GLS on the Allan variance with EDF weights (default); "
                        "tangent: datasheet slope lines; whittle: spectral likelihood; "
                        "exact: whittle plus the exact block-mean likelihood for flicker "
                        "and random walk (no gaps)")
    p.add_argument("--fit-temperature", action="store_true",
                   help="where a channel follows the recording's temperature column, fit "
                        "that linear response (GLS of block-mean increments under the "
                        "fitted noise's covariance; accepted at |t| > 5 with halves that "
                        "agree and a better likelihood), take it out before the noise terms "
                        "are fitted and write it as temp_coeff, temp_ref (default: only "
                        "warn; the random walk, flicker or ramp then carry the drift)")
    p.add_argument("-o", "--output", type=Path, default=None, metavar="MODEL.toml",
                   help="model file to write (required for one recording)")
    p.add_argument("--json", default=None, metavar="PATH|-", help="full result as JSON")
    p.add_argument("--kalibr-inflate", type=float, default=1.0, metavar="FACTOR",
                   help="multiply every Kalibr noise value by FACTOR >= 1 (a safety "
                   "factor for real-world use; docs/noise-fit.md)")
    p.add_argument("--kalibr", type=Path, default=None, metavar="imu.yaml",
                   help="also write Kalibr noise parameters")
    add_input_arguments(p)
    add_batch_options(p)
    p.set_defaults(func=run)


def format_summary(result: RecordingFit) -> str:
    """Per channel: present terms with value and 95 % interval, why each term was kept or
    dropped (:func:`short_reasons`), and the fit's notes (e.g. a model-discrepancy floor:
    the model does not describe the curve within its estimates' scatter)."""
    coverage = result.coverage()
    lines = [f"# {result.source}  rate={result.rate_hz:g} Hz  method={result.method}"
             + (f"  {coverage}" if coverage else "")]
    for ch, f in result.fits.items():
        parts = []
        for key in f.present:
            if key == "filter_order":
                continue
            lo, hi = f.ci.get(key, (float("nan"), float("nan")))
            unit = param_units(ch)[key]
            interval = (f"[{lo:.3g}, {hi:.3g}]" if math.isfinite(lo) and math.isfinite(hi)
                        else "(no interval: fixed, see its reason)")
            parts.append(f"{key}={f.params[key]:.4g} {unit} {interval}")
        lines.append(f"{ch}: " + ("  ".join(parts) if parts else "(no term found)"))
        n, ci = f.coefficient(WHITE_EQUIVALENT)
        if n > 0 and not math.isclose(n, f.params.get("white", 0.0)):
            lo, hi = ci if ci is not None else (float("nan"), float("nan"))
            lines.append(f"    white-equivalent density N={n:.4g} {param_units(ch)['white']} "
                         f"[{lo:.3g}, {hi:.3g}] (white, output_white and a Markov term with "
                         "tau_c <= 10 s together: the datasheet noise density)")
        if f.reasons:
            lines.append("    " + short_reasons(f.reasons))
        lines.extend(f"    note: {note}" for note in f.notes)
    return "\n".join(lines)


def short_reasons(reasons: dict[str, str]) -> str:
    """The model-selection reasons in one line: kept terms by name, dropped ones with
    their reason (without the upper limit, which ``--json`` carries)."""
    kept = [t for t, why in reasons.items() if why.startswith("kept")]
    dropped = [f"{t} ({why.removeprefix('dropped, ').split(' (one-sided')[0]})"
               for t, why in reasons.items() if why.startswith("dropped")]
    other = [f"{t} ({why})" for t, why in reasons.items()
             if not why.startswith(("kept", "dropped"))]
    parts = []
    if kept:
        parts.append("kept: " + ", ".join(kept))
    if dropped:
        parts.append("dropped: " + ", ".join(dropped))
    if other:
        parts.append(", ".join(other))
    return "; ".join(parts)


def run(args: argparse.Namespace) -> int:
    if is_batch(args.recording, args):
        from imubench.batchrun.jobs import run_fit_batch

        return run_fit_batch(args)
    if args.output is None:
        raise FitError("-o MODEL.toml is required for one recording (a directory or glob "
                       "writes into --out-dir)")
    for dest, option in ((args.output, "-o"), (args.json, "--json"),
                         (args.kalibr, "--kalibr")):
        check_writable(dest, option)  # refused before a long fit, not after it
    if args.kalibr is not None:
        check_kalibr_request(args.kalibr_inflate, args.channels.replace(",", " ").split()
                             if args.channels else None)
    try:
        with progress(100, "fit", unit="%") as bar:
            result = fit_recording(args.recording, channels=args.channels, terms=args.terms,
                                   method=args.method, options=input_options(args),
                                   fit_temperature=args.fit_temperature,
                                   on_channel=lambda done, total: bar.fraction(done / total))
        if args.kalibr is not None and result.units_assumed:
            raise FitError(
                f"{args.recording}: --kalibr writes SI values, but nothing states the "
                f"unit of {', '.join(result.units_assumed)} (read as dps / g); give "
                "--units GYRO,ACCEL (e.g. --units rad/s,m/s2)")
        # before any file is written: a Kalibr file that cannot be complete is an error
        kalibr = result.kalibr(args.kalibr_inflate) if args.kalibr is not None else None
        model = result.noise_model()
        args.output.write_text(model.to_toml(), encoding="utf-8")
        if args.json is not None:
            write_json(result.to_dict(), args.json)
        if args.kalibr is not None and kalibr is not None:
            args.kalibr.write_text(kalibr_yaml(kalibr), encoding="utf-8")
            for key in kalibr["upper_limits"]:
                print(kalibr_limit_message(args.kalibr, kalibr, key), file=sys.stderr)
        # the summary goes to stderr when stdout carries the JSON (docs/cli.md)
        print(format_summary(result), file=sys.stderr if args.json == "-" else sys.stdout)
    except BrokenPipeError:
        raise  # stdout's reader went away: cli.main exits 141, no message
    except OSError as exc:
        print(f"imubench fit: error: cannot write {exc.filename}: {exc.strerror}",
              file=sys.stderr)
        return 2
    return 0
