"""Batch analysis of many recordings (``imubench allan|fit|gap DIR-or-GLOB``), in this
process, on a 2-worker Dask LocalCluster and on an external ``dask scheduler`` started
here on loopback: the per-recording reports must equal what the one-file command writes
for each recording (an independent run of the existing per-file path), the tables hold
one row per recording and channel, and bad inputs are reported without losing the rest.
"""

from __future__ import annotations

import csv
import json
import re
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from fleet_helpers import MODEL, Proc, subprocess_env

from imubench.cli import main

CLI = [sys.executable, "-m", "imubench.cli"]
FIT = ["--channels", "gx,ax", "--terms", "white,flicker"]  # a short fit: the runner is tested


def cli(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*CLI, *args], capture_output=True, text=True, cwd=cwd, timeout=600,
                          env=subprocess_env())


@pytest.fixture(scope="module")
def recs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """recs/ with two native recordings and one CSV (120 s at 104 Hz, virtual time)."""
    root = tmp_path_factory.mktemp("batch")
    (root / "recs").mkdir()
    for name, seed in (("a.imbr", 1), ("b.imbr", 2), ("c.csv", 3)):  # (in this process:
        # the batch commands under test run as subprocesses)
        assert main(["sim", "--chip", "lsm6dsl", "--odr-hz", "104", "--duration-s", "120",
                     "--model", str(MODEL), "--seed", str(seed),
                     "--out", str(root / "recs" / name)]) == 0
    (root / "recs" / "notes.txt").write_text("not a recording\n")
    return root


def no_created(toml: str) -> str:
    return re.sub(r'^created = ".*"$', "", toml, flags=re.M)


@pytest.mark.slow  # 20 s; the LocalCluster path runs by default in the gap batch test
def test_fit_batch_matches_one_file_runs_sequential_and_on_two_workers(recs: Path) -> None:
    seq = cli("fit", "recs", *FIT, "--out-dir", "seq", "--progress", "on", cwd=recs)
    assert seq.returncode == 0, seq.stderr
    assert "fit: 3 recording(s), 6 task(s), 0 failed" in seq.stdout
    assert re.search(r"fit: .*3/3", seq.stderr)  # the progress bar, recordings done
    par = cli("fit", "recs", *FIT, "--out-dir", "par", "--workers", "2",
              cwd=recs)
    assert par.returncode == 0, par.stderr
    for stem, suffix in (("a", ".imbr"), ("b", ".imbr"), ("c", ".csv")):
        one = cli("fit", f"recs/{stem}{suffix}", *FIT, "-o", f"{stem}.toml",
                  "--json", f"{stem}.json", cwd=recs)
        assert one.returncode == 0, one.stderr
        single = json.loads((recs / f"{stem}.json").read_text())
        for out in ("seq", "par"):
            assert json.loads((recs / out / f"{stem}.json").read_text()) == single
            assert (no_created((recs / out / f"{stem}.toml").read_text())
                    == no_created((recs / f"{stem}.toml").read_text()))
    rows = list(csv.DictReader((recs / "seq" / "fit.csv").open()))
    assert [(r["recording"], r["channel"]) for r in rows] == [
        ("recs/a.imbr", "gx"), ("recs/a.imbr", "ax"), ("recs/b.imbr", "gx"),
        ("recs/b.imbr", "ax"), ("recs/c.csv", "gx"), ("recs/c.csv", "ax")]
    a = json.loads((recs / "seq" / "a.json").read_text())
    assert float(rows[0]["white"]) == a["channels"]["gx"]["params"]["white"]
    assert (recs / "seq" / "fit.csv").read_text() == (recs / "par" / "fit.csv").read_text()
    table = json.loads((recs / "par" / "fit.json").read_text())
    assert table["workers"] == 2 and table["failed"] == 0 and table["tasks"] == 6


@pytest.fixture
def dask_cluster(tmp_path: Path) -> Iterator[str]:
    """A ``dask scheduler`` and one ``dask worker`` on 127.0.0.1; yields the address."""
    sched_file = tmp_path / "scheduler.json"
    scheduler = Proc([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host",
                      "127.0.0.1", "--port", "0", "--dashboard-address", "127.0.0.1:0",
                      "--scheduler-file", str(sched_file)], tmp_path)
    worker = None
    try:
        address = scheduler.wait_for(r"Scheduler at:\s+(tcp://127\.0\.0\.1:\d+)", 60).group(1)
        worker = Proc([sys.executable, "-m", "distributed.cli.dask_worker", address,
                       "--host", "127.0.0.1", "--nworkers", "1", "--nthreads", "1",
                       "--no-dashboard"], tmp_path)
        scheduler.wait_for(r"Register worker", 60)
        yield address
    finally:
        if worker is not None:
            worker.stop()
        scheduler.stop()


def test_allan_batch_on_an_external_scheduler(recs: Path, dask_cluster: str) -> None:
    run = cli("allan", "recs/*.imbr", "--stat", "oadev", "--column", "gz", "--out-dir",
              "ext", "--scheduler", dask_cluster, cwd=recs)
    assert run.returncode == 0, run.stderr
    for stem in ("a", "b"):
        one = cli("allan", f"recs/{stem}.imbr", "--stat", "oadev", "--column", "gz", "--json",
                  "-", cwd=recs)
        assert one.returncode == 0, one.stderr
        assert json.loads((recs / "ext" / f"{stem}.gz.oadev.json").read_text()) == \
            json.loads(one.stdout)
    table = json.loads((recs / "ext" / "allan.json").read_text())
    assert table["scheduler"] == dask_cluster and table["recordings"] == [
        "recs/a.imbr", "recs/b.imbr"]
    a = json.loads((recs / "ext" / "a.gz.oadev.json").read_text())
    rows_a = [r for r in table["rows"] if r["recording"] == "recs/a.imbr"]
    assert [r["dev"] for r in rows_a] == a["dev"] and {r["channel"] for r in rows_a} == {"gz"}


def test_gap_batch_matches_one_file_run(recs: Path) -> None:
    opts = ["--model", str(MODEL), "--channels", "gx,ax", "--effects", "flicker",
            "--realisations", "3"]
    run = cli("gap", "recs/a.imbr", "--workers", "1", "--out-dir", "gapb", *opts, cwd=recs)
    assert run.returncode == 0, run.stderr
    one = cli("gap", "recs/a.imbr", "--json", "a.gap.json", *opts, cwd=recs)
    assert one.returncode == 0, one.stderr
    assert (json.loads((recs / "gapb" / "a.gap.json").read_text())
            == json.loads((recs / "a.gap.json").read_text()))
    rows = list(csv.DictReader((recs / "gapb" / "gap.csv").open()))
    assert [r["channel"] for r in rows] == ["gx", "ax"] and rows[0]["verdict"]


def test_a_damaged_recording_is_reported_and_the_others_kept(
        recs: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    mixed = tmp_path / "mixed"
    mixed.mkdir()
    shutil.copy(recs / "recs" / "a.imbr", mixed)
    (mixed / "bad.csv").write_text("t,gx\n0.0,zero\n")
    assert main(["allan", str(mixed), "--stat", "adev", "--out-dir", str(tmp_path / "o")]) == 2
    assert re.search(r"imubench allan: error: \S+bad\.csv: ", capsys.readouterr().err)
    table = json.loads((tmp_path / "o" / "allan.json").read_text())
    assert table["failed"] == 1
    assert {r["channel"] for r in table["rows"] if "error" not in r} == {
        "gx", "gy", "gz", "ax", "ay", "az"}
    assert (tmp_path / "o" / "a.gx.adev.json").exists()


@pytest.mark.parametrize(("args", "message"), [
    (["fit", "recs/*", "--out-dir", "x"], "notes.txt is not a recording"),
    (["fit", "recs", "-o", "m.toml", "--out-dir", "x"], "-o names one recording's output"),
    (["fit", "recs"], "needs --out-dir DIR"),
    (["fit", "recs/a.imbr"], "-o MODEL.toml is required for one recording"),
    (["gap", "recs/a.imbr", "--model", "m.toml"], "--json OUT is required"),
    (["gap", "recs", "--model", "m.toml", "--out-dir", "x", "--jobs", "2"],
     "--jobs runs one recording's channels"),
    (["fit", "empty", "--out-dir", "x"], "no recordings"),
    (["fit", "nothing*.imbr"], "nothing*.imbr: no recordings"),  # not "needs --out-dir"
    (["fit", "recs", "--out-dir", "x", "--workers", "2", "--scheduler", "tcp://127.0.0.1:1"],
     "not both"),
])
def test_batch_option_errors(recs: Path, args: list[str], message: str,
                             monkeypatch: pytest.MonkeyPatch,
                             capsys: pytest.CaptureFixture[str]) -> None:
    (recs / "empty").mkdir(exist_ok=True)
    monkeypatch.chdir(recs)
    assert main(args) == 2
    assert message in capsys.readouterr().err


def test_a_file_named_like_a_glob_is_that_file(tmp_path: Path) -> None:
    """``run_[1].csv`` was taken as a pattern and ``run_1.csv`` analysed instead."""
    from imubench.batchrun.runner import expand_inputs, has_glob

    (tmp_path / "run_[1].csv").write_text("t,gx\n")
    (tmp_path / "run_1.csv").write_text("t,gx\n")
    assert not has_glob(str(tmp_path / "run_[1].csv"))
    assert expand_inputs(tmp_path / "run_[1].csv") == [tmp_path / "run_[1].csv"]
    assert has_glob(str(tmp_path / "run_[12].csv"))
    assert expand_inputs(str(tmp_path / "run_[12].csv")) == [tmp_path / "run_1.csv"]
