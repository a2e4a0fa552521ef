"""How long the simulated acceptance run of one board takes (issue 16 acceptance 4:
under 60 s on this machine, in virtual time). Run:
``.venv/bin/python bench/bench_jig.py [--repeat N]``.

Measured: the whole ``imubench jig run --station config/station-sim.toml`` as a
subprocess (interpreter start, imports, the 47-test suite through pytest, report with
plots), its wall and CPU time (children's rusage), the pytest part's wall time and the
DUT's own (virtual) time from result.json. Reference in the same run: ``imubench acquire``
of the same simulated chip for as many source seconds as the jig ran (interpreter start,
imports, the driver and the recorder, no analysis), as a subprocess too; the ratio says
what the jig's captures, settling, statistics and reports cost on top of reading the same
amount of data. The machine is shared: wall time includes other people's load, CPU time
does not.

Prints one line per measurement; figures go to docs/benchmarks.md by hand.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
STATION = REPO / "config" / "station-sim.toml"


def child_cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def timed(cmd: list[str]) -> tuple[float, float, subprocess.CompletedProcess[str]]:
    c0, t0 = child_cpu_s(), time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=REPO, env=os.environ)
    return time.perf_counter() - t0, child_cpu_s() - c0, proc


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=1)
    args = ap.parse_args()
    py = sys.executable
    with tempfile.TemporaryDirectory(prefix="bench-jig-") as tmp:
        for k in range(args.repeat):
            wall, cpu, proc = timed([py, "-m", "imubench.cli", "jig", "run", "--station",
                                     str(STATION), "--serial", f"BENCH-{k}", "--report", tmp])
            if proc.returncode != 0:
                sys.exit(f"jig run exited {proc.returncode}:\n{proc.stdout[-2000:]}"
                         f"\n{proc.stderr[-2000:]}")
            runs = sorted(p for p in (Path(tmp) / f"BENCH-{k}").iterdir() if p.is_dir())
            res = json.loads((runs[-1] / "result.json").read_text())
            source_s = float(res["source_time_s"])
            uri = "sim://lsm6dsl?odr_hz=104&seed=1&clock=virtual&model=datasheet:lsm6dsl"
            rwall, rcpu, rproc = timed([py, "-m", "imubench.cli", "acquire", uri,
                                        "--duration-s", f"{source_s:.0f}", "--out",
                                        str(Path(tmp) / f"ref-{k}.imbr")])
            if rproc.returncode != 0:
                sys.exit(f"acquire exited {rproc.returncode}: {rproc.stderr[-2000:]}")
            print(f"jig run (verdict {res['verdict']}, {len(res['measurements'])} measurements):"
                  f" wall {wall:.1f} s, CPU {cpu:.1f} s; pytest part {res['wall_time_s']:.1f} s"
                  f" wall; DUT time {source_s:.0f} s virtual ({source_s / wall:.0f} x wall)")
            print(f"reference acquire of {source_s:.0f} s: wall {rwall:.1f} s, CPU {rcpu:.1f} s;"
                  f" jig / reference: wall {wall / rwall:.2f}, CPU {cpu / rcpu:.2f}")
            print(f"load average {os.getloadavg()[0]:.1f} (2 cores); target: jig run < 60 s"
                  f" -> {'met' if wall < 60 else 'NOT met'}")


if __name__ == "__main__":
    main()
