"""Fault matrix of the acquisition pipeline and the daemon (issue 12 acceptance 5).

Each case is repeated; every run is checked for what reached the recording or the
consumer (delivered), what was declared lost with a reason (lost, accounted), what was
neither (unaccounted: must be 0 except the stated SIGKILL bound), samples delivered twice
(duplicated: must be 0), tracebacks and hangs (must be 0).

Cases:

* ``sigkill``: ``imubench run`` (sim 833 Hz, wall clock) killed with SIGKILL at a random
  moment; the recording must read, and hold every sample up to the last fsync interval
  (``log.fsync_interval_s`` 0.5 s; bound stated: 1.5 s of data).
* ``stall-104`` / ``stall-6660``: reader stalls between the FIFO status and data reads
  (3.5 s at 104 Hz, 0.06 s at 6660 Hz, every 10 s / 1 s), virtual time; every delivered
  sample under its own index (counting signal), no gap longer than the stall.
* ``chip-faults``: NACK bursts, chip resets, a forced overrun, stuck outputs, in one run.
* ``disk-full``: a 512 KiB tmpfs filled then emptied under a running daemon (needs root
  and ``mount``; skipped otherwise): segments + gap records account for every sample.

The MQTT faults (broker stopped, killed and hung; malformed packets) are in
``bench/fault_mqtt.py``, damaged recordings in ``bench/fault_recordings.py`` and damaged
configurations in ``bench/bench_config_fuzz.py``; ``--all`` runs them after this table
and prints theirs (figures in ``docs/benchmarks.md``).

Run: ``.venv/bin/python bench/fault_matrix.py [--sigkills 50] [--repeats 5] [--quick]
[--all]``.
"""

from __future__ import annotations

import argparse
import os
import random
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from imubench.batch import UNEXPLAINED
from imubench.commands.acquire import record_uri
from imubench.errors import RecordingError
from imubench.recording import load_recording

REPO = Path(__file__).resolve().parents[1]


@dataclass
class Row:
    case: str
    repeats: int = 0
    delivered: int = 0
    lost: int = 0
    unaccounted: int = 0
    duplicated: int = 0
    tracebacks: int = 0
    hangs: int = 0
    note: str = ""

    def line(self) -> str:
        return (f"| {self.case} | {self.repeats} | {self.delivered} | {self.lost} | "
                f"{self.unaccounted} | {self.duplicated} | {self.tracebacks} | {self.hangs} "
                f"| {self.note} |")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def daemon_config(tmp: Path, uri: str, extra: str = "") -> Path:
    cfg = tmp / "d.toml"
    cfg.write_text(
        f'[source]\nuri = "{uri}"\n'
        f'[log]\npath = "{tmp}/rec/{{station}}_{{sensor}}.imbr"\nfsync_interval_s = 0.5\n'
        f'[allan]\nstats = ["oadev"]\nmax_tau_s = 100\n'
        f'[mqtt]\nport = {free_port()}\n[display]\nlive_table = "off"\n' + extra)
    return cfg


def sigkill(trials: int) -> Row:
    row = Row("sigkill (833 Hz, random moment)", note="bound: 1.5 s of data per kill")
    worst = 0.0
    rng = random.Random(12)
    for _ in range(trials):
        tmp = Path(tempfile.mkdtemp(prefix="fm-kill-"))
        cfg = daemon_config(tmp, "sim://lsm6dsl?odr_hz=833&clock=wall&counting=1")
        proc = subprocess.Popen([sys.executable, "-m", "imubench.cli", "run", "--config",
                                 str(cfg)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                text=True)
        assert proc.stdout is not None
        line = ""
        t_end = time.monotonic() + 60
        while "recording to" not in line and time.monotonic() < t_end:
            line = proc.stdout.readline()
            if not line and proc.poll() is not None:
                break
        t_rec = time.monotonic()
        time.sleep(0.5 + rng.random() * 4.0)
        alive = time.monotonic() - t_rec
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        rest = proc.stdout.read()
        row.repeats += 1
        row.tracebacks += "Traceback" in line + rest
        try:
            rec = load_recording(tmp / "rec" / "bench1_imu0.imbr")
        except Exception as exc:  # an unreadable recording is the failure this counts
            row.note += f" unreadable: {exc};"
            row.unaccounted += round(alive * 833)
            continue
        n = len(rec)
        row.delivered += n
        row.duplicated += n - len(np.unique(rec.index))
        missing = alive - (int(rec.index[-1]) + 1) / 833.0 if n else alive
        worst = max(worst, missing)
        row.lost += rec.lost_samples
        shutil.rmtree(tmp, ignore_errors=True)
    row.note += f" worst tail not on disk {worst:.2f} s"
    return row


def stall(odr: int, stall_s: float, every_s: float, duration_s: float, repeats: int) -> Row:
    row = Row(f"stall {stall_s:g} s every {every_s:g} s at {odr} Hz")
    worst = 0
    for k in range(repeats):
        tmp = Path(tempfile.mkdtemp(prefix="fm-stall-"))
        out = tmp / "s.imbr"
        stats = record_uri(f"sim://lsm6dsl?odr_hz={odr}&duration_s={duration_s}&counting=1"
                           f"&stall_every_s={every_s}&stall_s={stall_s}&seed={k}", out, None)
        rec = load_recording(out)
        gx = rec.raw[:, 0].astype(np.int64) & 0xFFFF if rec.raw is not None else None
        wrong = 0 if gx is None else len(np.unique((gx - rec.index) & 0xFFFF)) - 1
        row.repeats += 1
        row.delivered += len(rec)
        row.lost += sum(g.lost for g in rec.gaps)
        row.unaccounted += round(odr * duration_s) - len(rec) - rec.lost_samples + wrong
        row.duplicated += len(rec) - len(np.unique(rec.index))
        row.unaccounted += sum(g.lost for g in rec.gaps if g.reason == UNEXPLAINED)
        worst = max(worst, max((g.lost for g in rec.gaps), default=0))
        assert stats["produced"] == round(odr * duration_s)
        shutil.rmtree(tmp, ignore_errors=True)
    row.note = f"largest gap {worst} samples, stall {stall_s * odr:.0f}"
    return row


def chip_faults(repeats: int) -> Row:
    row = Row("chip faults (NACK bursts, resets, overrun, stuck output), 104 Hz 400 kHz")
    for k in range(repeats):
        tmp = Path(tempfile.mkdtemp(prefix="fm-chip-"))
        out = tmp / "c.imbr"
        record_uri("sim://lsm6dsl?odr_hz=104&bus_khz=400&nack_rate=1e-3&nack_burst=3"
                   "&reset_every_s=10&overrun_at_s=25&stuck_output_at_s=40"
                   f"&stuck_output_for_s=2&counting=1&duration_s=60&seed={k}", out, None)
        rec = load_recording(out)
        row.repeats += 1
        row.delivered += len(rec)
        row.lost += rec.lost_samples
        row.unaccounted += 104 * 60 - len(rec) - rec.lost_samples
        row.unaccounted += sum(g.lost for g in rec.gaps if g.reason == UNEXPLAINED)
        row.duplicated += len(rec) - len(np.unique(rec.index))
        shutil.rmtree(tmp, ignore_errors=True)
    return row


def disk_full(repeats: int) -> Row:
    row = Row("disk full (512 KiB tmpfs, emptied after 1 s), 1660 Hz")
    if os.geteuid() != 0 or shutil.which("mount") is None:
        row.note = "skipped: needs root and mount"
        return row
    for _ in range(repeats):
        tmp = Path(tempfile.mkdtemp(prefix="fm-disk-"))
        disk = tmp / "disk"
        disk.mkdir()
        if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=512k", "tmpfs", str(disk)],
                          capture_output=True).returncode:
            row.note = "skipped: mount refused"
            return row
        try:
            (disk / "filler").write_bytes(b"\0" * (512 * 1024 - 96 * 1024))
            cfg = daemon_config(tmp, "sim://lsm6dsl?odr_hz=1660&clock=wall&counting=1",
                                "[run]\nduration_s = 14\n")
            cfg.write_text(cfg.read_text().replace(f"{tmp}/rec/", f"{disk}/"))
            proc = subprocess.Popen([sys.executable, "-m", "imubench.cli", "run", "--config",
                                     str(cfg)], stdout=subprocess.PIPE,
                                    stderr=subprocess.STDOUT, text=True)
            assert proc.stdout is not None
            out = ""
            while "not recording" not in out:
                line = proc.stdout.readline()
                if not line:
                    break
                out += line
            time.sleep(1.0)
            (disk / "filler").unlink()
            try:
                rest, _ = proc.communicate(timeout=60)
            except subprocess.TimeoutExpired:
                proc.kill()
                rest, _ = proc.communicate()
                row.hangs += 1
            out += rest
            row.repeats += 1
            row.tracebacks += "Traceback" in out
            m = re.search(r"stopped after (\d+) samples produced", out)
            produced = int(m[1]) if m else 0
            # the first segment reads with the ones after it (their indices must increase)
            try:
                rec = load_recording(disk / "bench1_imu0.imbr")
            except RecordingError as exc:  # e.g. a segment repeating samples
                row.unaccounted += produced
                row.note = str(exc)
                continue
            got = len(rec)
            lost = sum(g.lost for g in rec.gaps)
            row.delivered += got
            row.lost += lost
            row.unaccounted += produced - got - lost
            row.duplicated += len(rec.index) - len(np.unique(rec.index))
            row.note = (f"{len(rec.metadata.get('segments', [1]))} segments in the last "
                        f"run; damage: {rec.damage or 'none'}")
        finally:
            subprocess.run(["umount", "-l", str(disk)], capture_output=True)
            shutil.rmtree(tmp, ignore_errors=True)
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sigkills", type=int, default=50)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--quick", action="store_true", help="5 kills, 1 repeat")
    ap.add_argument("--all", action="store_true",
                    help="then run fault_mqtt.py, fault_recordings.py, bench_config_fuzz.py")
    args = ap.parse_args()
    if args.quick:
        args.sigkills, args.repeats = 5, 1
    print(f"machine: {os.uname().nodename} {os.cpu_count()} cores; "
          f"{time.strftime('%Y-%m-%d %H:%M')}")
    rows = [
        stall(104, 3.5, 10, 120, args.repeats),
        stall(6660, 0.06, 1, 20, args.repeats),
        chip_faults(args.repeats),
        disk_full(args.repeats),
        sigkill(args.sigkills),
    ]
    print("| case | repeats | delivered | lost (accounted) | unaccounted | duplicated | "
          "tracebacks | hangs | note |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(r.line())
    if args.all:
        quick = {"fault_mqtt.py": ["--quick"], "fault_recordings.py": ["--n", "60"],
                 "bench_config_fuzz.py": ["--n", "1000", "--cli", "5"]}
        for script in ("fault_mqtt.py", "fault_recordings.py", "bench_config_fuzz.py"):
            print(f"\n## {script}", flush=True)
            subprocess.run([sys.executable, str(REPO / "bench" / script),
                            *(quick[script] if args.quick else [])], check=False)


if __name__ == "__main__":
    main()
