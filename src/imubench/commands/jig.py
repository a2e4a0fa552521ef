"""``imubench jig run --station STATION.toml [--dut URI] [--serial SN] --report DIR``.

Runs the shipped acceptance suite (and the station's own tests) on one board through
pytest, writes JUnit XML, ``result.json`` and ``report.html`` (with plots) into
``DIR/<serial>/<run id>/``, keeps every run (a re-test adds one), writes the board's
calibration file there, and publishes the result (retained) on
``imubench/<station>/<sensor>/jig`` when the station names a broker. Exit status: 0 all
passed, 1 a failure, 3 inconclusive, 2 usage error. See docs/jig.md.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from imubench.jig.measurement import FAIL, INCONCLUSIVE


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "jig", help="hardware-in-the-loop test jig: test, calibrate and judge a board",
        description="Hardware-in-the-loop test jig (docs/jig.md).",
    )
    jsub = p.add_subparsers(dest="jig_command", metavar="SUBCOMMAND", required=True)
    r = jsub.add_parser(
        "run", help="run the acceptance suite on one board",
        description="Run the acceptance suite on one board and keep its report under its "
        "serial number. Exit status: 0 all pass, 1 any fail, 3 inconclusive, 2 usage error.",
    )
    r.add_argument("--station", type=Path, required=True, metavar="STATION.toml",
                   help="station file (config/station-sim.toml for a simulated jig)")
    r.add_argument("--dut", default=None, metavar="URI",
                   help="board source URI (default: the station's dut.uri)")
    r.add_argument("--serial", default=None, metavar="SN",
                   help="board serial number (default: the station's dut.serial)")
    r.add_argument("--report", type=Path, required=True, metavar="DIR",
                   help="results directory; the run goes to DIR/<serial>/<run id>/")
    r.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from imubench.jig.runner import run_jig

    res = run_jig(args.station, args.report, dut=args.dut, serial=args.serial)
    result = res.result
    bad = [m for m in result["measurements"] if m["verdict"] in (FAIL, INCONCLUSIVE)]
    for m in bad:
        print(f"{m['verdict']}: {m['name']} = {m['value']} {m['unit']} (CI {m['ci_low']} .."
              f" {m['ci_high']}, limits {m['low']} .. {m['high']})")
    reasons = result.get("broken_reasons", {})
    for nodeid in result["broken_tests"]:
        why = reasons.get(nodeid) or "see the report"
        print(f"FAIL: test {nodeid} failed without a measurement: {why}")
    for nodeid, why in result.get("inconclusive_tests", {}).items():
        print(f"INCONCLUSIVE: test {nodeid} measured nothing: {why}")
    print(f"{result['serial']}: {result['verdict']} ({len(result['measurements'])}"
          f" measurements); report {res.run_dir / 'report.html'}")
    if res.published_topic:
        print(f"published on {res.published_topic}")
    if res.publish_error:
        print(f"imubench jig: warning: {res.publish_error}", file=sys.stderr)
    return res.exit_status
