"""Command-line conventions: exit statuses, signals, closed pipes, options after the
subcommand, help texts, logging format, progress bars on stderr, ``--stats-json -``."""

from __future__ import annotations

import argparse
import json
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from imubench import cli
from imubench.recording import load_recording

ISO_LINE = re.compile(
    r"^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}[+-]\d\d:\d\d (DEBUG|INFO|WARNING|ERROR) \S+: "
)


def imubench(*args: str) -> list[str]:
    return [sys.executable, "-m", "imubench", *args]


def one_column(tmp_path: Path, n: int = 20000) -> Path:
    p = tmp_path / "y.txt"
    rng = np.random.default_rng(1)
    p.write_text("\n".join(f"{v:.9g}" for v in rng.standard_normal(n)) + "\n")
    return p


def test_every_option_and_command_has_help() -> None:
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    helped = {a.dest for a in sub._choices_actions if a.help}
    assert helped == set(cli.COMMANDS)
    for name, p in [("imubench", parser), *sub.choices.items()]:
        for action in p._actions:
            if isinstance(action, argparse._SubParsersAction):
                continue
            assert action.help, f"{name}: {action.option_strings or action.dest} has no help"


def test_python_dash_m_and_version() -> None:
    proc = subprocess.run(imubench("--version"), capture_output=True, text=True, timeout=120)
    from imubench import __version__

    assert proc.returncode == 0 and proc.stdout.strip() == f"imubench {__version__}"


def test_verbose_before_or_after_the_command_logs_iso_time(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = one_column(tmp_path, 500)
    assert cli.main(["allan", str(data), "--stat", "adev", "-vv"]) == 0
    err = capsys.readouterr().err.splitlines()
    assert any(ISO_LINE.match(line) and " DEBUG imubench.cli: " in line for line in err), err
    assert cli.main(["-v", "allan", str(data), "--stat", "adev", "-v"]) == 0  # adds up to -vv
    assert "DEBUG imubench.cli" in capsys.readouterr().err
    assert cli.main(["allan", str(data), "--stat", "adev"]) == 0
    assert "DEBUG" not in capsys.readouterr().err


def test_closed_pipe_is_quiet(tmp_path: Path) -> None:
    """``imubench allan ... | head -1`` in a real shell: no traceback, status 141."""
    data = one_column(tmp_path)
    err = tmp_path / "err.txt"
    cmd = " ".join(imubench("allan", str(data), "--stat", "adev", "--taus", "all",
                            "--json", "-"))
    proc = subprocess.run(["bash", "-c", f'{cmd} 2>"{err}" | head -1; '
                           'echo "status=${PIPESTATUS[0]}"'],
                          capture_output=True, text=True, timeout=300)
    lines = proc.stdout.splitlines()
    assert lines[0] == "{" and lines[-1] == "status=141", proc.stdout[-500:]
    assert err.read_text() == ""


@pytest.mark.parametrize("command", ["allan", "fit", "gap"])
def test_json_to_a_closed_pipe_exits_141_quietly(tmp_path: Path, command: str) -> None:
    """``--json -`` into a pipe whose reader is gone (``| head -1`` after its line): exit
    141 and no message, for every command (fit said "cannot write None", exit 2)."""
    import os

    data = one_column(tmp_path)
    model = tmp_path / "m.toml"
    assert cli.main(["fit", str(data), "--rate", "100", "-o", str(model)]) == 0
    args = {"allan": ["allan", str(data), "--stat", "adev", "--json", "-"],
            "fit": ["fit", str(data), "--rate", "100", "-o", str(tmp_path / "m2.toml"),
                    "--json", "-"],
            "gap": ["gap", str(data), "--rate", "100", "--model", str(model), "--json",
                    "-"]}[command]
    r, w = os.pipe()
    os.close(r)  # the reader went away before the JSON came
    try:
        proc = subprocess.run(imubench(*args), stdout=w, stderr=subprocess.PIPE, text=True,
                              timeout=300)
    finally:
        os.close(w)
    assert proc.returncode == 141, proc.stderr
    assert proc.stderr == ""


INTERRUPTED = (130, -signal.SIGINT)
"""Exit 130, or death by SIGINT (which a shell reports as 130 too): CPython ends that way
when a KeyboardInterrupt crossed one of its C-level code runners, even if caught later."""


@pytest.mark.parametrize("delay_s", [0.8, 1.5])
def test_ctrl_c_in_the_first_second(tmp_path: Path, delay_s: float) -> None:
    """While the interpreter imports numpy & co (an interrupted C-level import surfaces
    as ImportError) or the source starts: one line, no traceback."""
    proc = subprocess.Popen(imubench("sim", "--duration-s", "1e6", "--out",
                                     str(tmp_path / "r.imbr")),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(delay_s)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode in INTERRUPTED, err
    assert len(err.splitlines()) == 1 and "interrupted (Ctrl-C)" in err, err
    assert "Traceback" not in err


@pytest.mark.parametrize(("sig", "status", "word"), [(signal.SIGINT, 130, "interrupted"),
                                                     (signal.SIGTERM, 143, "terminated")])
def test_interrupted_sim_keeps_what_it_made(tmp_path: Path, sig: int, status: int,
                                            word: str) -> None:
    out = tmp_path / "r.imbr"
    stats = tmp_path / "s.json"
    proc = subprocess.Popen(imubench("sim", "--duration-s", "1e6", "--out", str(out),
                                     "--stats-json", str(stats)),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    end = time.monotonic() + 120
    while (not out.exists() or out.stat().st_size < 200_000) and time.monotonic() < end:
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.1)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode in (status, -sig), err
    assert err.splitlines() == [f"imubench sim: {word} "
                                f"({'Ctrl-C' if sig == signal.SIGINT else 'SIGTERM'}); "
                                "output written so far is kept"]
    rec = load_recording(out)
    assert len(rec) > 1000 and rec.damage is None  # closed cleanly, end record written
    np.testing.assert_array_equal(rec.index, np.arange(len(rec)))
    counted = json.loads(stats.read_text())  # the counters are written too (they were not)
    assert counted["interrupted"] is True and counted["recorded"] == len(rec)
    assert counted["produced"] == counted["recorded"] + counted["recording_lost"]


def test_an_interrupted_convert_says_its_partial_output_is_removed(tmp_path: Path) -> None:
    """A conversion is all or nothing: Ctrl-C removes the partial CSV, and the message
    said "output written so far is kept" over a file that was not there."""
    rec = tmp_path / "r.imbr"
    assert cli.main(["sim", "--odr-hz", "1660", "--duration-s", "600", "--out", str(rec)]) == 0
    out = tmp_path / "r.csv"
    proc = subprocess.Popen(imubench("convert", str(rec), str(out)),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    end = time.monotonic() + 120
    while (not out.exists() or out.stat().st_size < 1_000_000) and time.monotonic() < end:
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert err.splitlines() == ["imubench convert: interrupted (Ctrl-C); the partial output "
                                "is removed"]
    assert not out.exists()


def test_stats_json_dash_goes_to_stdout(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(tmp_path)
    rc = cli.main(["sim", "--duration-s", "2", "--out", "r.imbr", "--stats-json", "-"])
    captured = capsys.readouterr()
    assert rc == 0
    stats = json.loads(captured.out)  # stdout holds the JSON and nothing else
    assert stats["samples"] == 208
    assert "208 samples" in captured.err
    assert not (tmp_path / "-").exists()


def test_progress_bar_on_stderr_never_stdout(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    data = one_column(tmp_path)
    argv = ["allan", str(data), "--stat", "oadev", "--taus", "all", "--json", "-"]
    assert cli.main([*argv, "--progress", "on"]) == 0
    captured = capsys.readouterr()
    assert json.loads(captured.out)["stat"] == "oadev"
    assert "oadev:" in captured.err and "%" in captured.err
    assert cli.main(argv) == 0  # auto: stderr is not a terminal here
    err = capsys.readouterr().err  # the human table (stdout carries the JSON), no bar
    assert err.startswith("# oadev") and "oadev:" not in err and "%" not in err


def test_input_errors_exit_2_on_one_line(tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert cli.main(["sim", "--duration-s", "1", "--out", f"{blocker}/r.imbr"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("imubench sim: error: ") and str(blocker) in err[0]
    with pytest.raises(SystemExit) as exc:
        cli.main(["allan", "--no-such-option"])
    assert exc.value.code == 2


def test_a_bug_exits_70_with_its_traceback(monkeypatch: pytest.MonkeyPatch,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    from imubench.commands import convert

    def broken(args: argparse.Namespace) -> int:
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(convert, "run", broken)
    assert cli.main(["convert", "a.imbr", "b.csv"]) == cli.EXIT_SOFTWARE == 70
    err = capsys.readouterr().err
    assert "Traceback" in err and "ZeroDivisionError: a bug" in err and "please report" in err


def test_a_signal_stops_the_daemon_with_status_0_also_in_its_first_moments(
        capsys: pytest.CaptureFixture[str]) -> None:
    """Before the daemon's own handlers are in place (imports, parsing) SIGTERM reached
    the commands' path and gave 143, a failure to a service manager; ``run`` is stopped
    by a signal: 0, as docs/service.md says. Other commands keep 143 and 130."""
    cli._received[:] = [signal.SIGTERM]
    try:
        assert cli._signalled("imubench run", daemon=True) == 0
        assert "imubench run: stopped (SIGTERM)" in capsys.readouterr().err
        assert cli._signalled("imubench acquire") == cli.EXIT_SIGTERM == 143
        cli._received[:] = [signal.SIGINT]
        assert cli._signalled("imubench run", daemon=True) == 0
        assert "stopped (Ctrl-C)" in capsys.readouterr().err
        assert cli._signalled("imubench acquire") == 130
    finally:
        cli._received.clear()


def test_signal_handlers_are_restored(tmp_path: Path) -> None:
    before = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
    assert cli.main(["allan", str(one_column(tmp_path, 200)), "--stat", "adev"]) == 0
    assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == before
