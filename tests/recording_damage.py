"""Damaged copies of recordings (truncations, byte and bit flips) through the one reader
and through the commands that read recordings: shared by ``tests/test_foreign_inputs.py``
and ``bench/fault_recordings.py``."""

from __future__ import annotations

import contextlib
import io
import random
import shutil
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from imubench.errors import ImubenchError
from imubench.recording import InputOptions, load_recording

CORPUS = Path(__file__).parent / "data" / "foreign"
MAX_SAMPLES = 209
"""No damaged corpus file may yield more samples than its 208 (+1 for a torn index)."""
COMMANDS: tuple[str, ...] = ("allan", "fit", "report", "gap", "convert", "tilt")
"""Every command that reads one recording (the batch runs read through the same calls)."""
CHEAP_COMMANDS: tuple[str, ...] = ("allan", "fit", "gap", "convert", "tilt")
"""The commands run on a sample of the fuzzed files by default (``report`` draws plots:
seconds per file)."""


def cli_flags(options: InputOptions) -> list[str]:
    """The command-line options that say what ``options`` say."""
    out: list[str] = []
    if options.rate_hz is not None:
        out += ["--rate", repr(options.rate_hz)]
    if options.time_unit is not None:
        out += ["--time-unit", options.time_unit]
    if options.columns:
        out += ["--columns", ",".join(f"{k}={v}" for k, v in options.columns.items())]
    if options.gyro_unit is not None:
        out += ["--units", f"{options.gyro_unit},{options.accel_unit}"]
    if options.topic is not None:
        out += ["--topic", options.topic]
    return out


def command_argv(command: str, path: Path, out: Path) -> list[str]:
    """``imubench COMMAND`` on ``path`` with cheap settings, writing into folder ``out``
    (JSON where the command writes JSON: ``out/COMMAND.json``)."""
    p, j = str(path), str(out / f"{command}.json")
    return {
        "allan": ["allan", p, "--stat", "oadev", "--column", "gx", "--json", j],
        "fit": ["fit", p, "-o", str(out / "model.toml"), "--channels", "gx",
                "--terms", "white", "--json", j],
        "report": ["report", p, "--out", str(out / "report"), "--terms", "white"],
        "gap": ["gap", p, "--model", "datasheet:lsm6dsl", "--channels", "gx",
                "--realisations", "3", "--holdout-fraction", "0", "--effects", "flicker",
                "--json", j],
        "convert": ["convert", p, str(out / "converted.imbr")],
        "tilt": ["tilt", p, "--average", "16", "--json", j],
    }[command]


def run_command(argv: Sequence[str]) -> tuple[int, str, str]:
    """``imubench ARGV`` in this process (no progress bars): (exit status, stdout,
    stderr)."""
    from imubench.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = main([*argv, "--progress", "off"])
    return status, out.getvalue(), err.getvalue()


def check_command(argv: Sequence[str], path: Path) -> int:
    """Run ``argv``: it succeeds (0), or fails with exit status 2 and an error line that
    names ``path``; never a traceback nor an internal error. Its exit status."""
    status, _, err = run_command(argv)
    assert "Traceback" not in err and status in (0, 2), (argv, status, err)
    if status == 2:
        errors = [line for line in err.splitlines() if f"imubench {argv[0]}: error:" in line]
        assert errors and str(path) in errors[0], (argv, err)
    return status


def _damaged(data: bytes, rng: random.Random) -> bytes:
    if rng.random() < 0.4:
        return data[: rng.randrange(len(data))]
    out = bytearray(data)
    for _ in range(rng.randint(1, 6)):
        i = rng.randrange(len(out))
        out[i] = rng.randrange(256) if rng.random() < 0.5 else out[i] ^ (1 << rng.randrange(8))
    return bytes(out)


def fuzz(files: Mapping[str, tuple[InputOptions, Any, Any, Any]], n_per_file: int, tmp: Path,
         seed: int = 1, command_every: int = 0,
         commands: Sequence[str] = CHEAP_COMMANDS) -> dict[str, int]:
    """Truncations and byte/bit flips of every corpus file through the reader: each is
    read (perhaps with damage reported) or refused with ImubenchError; counts by outcome.
    Anything else raised fails. With ``command_every`` = k, every k-th damaged file also
    goes through one of ``commands`` in turn (:func:`check_command`), counted as
    ``command ok`` / ``command refused``."""
    rng = random.Random(seed)
    counts = {"read": 0, "damage reported": 0, "refused": 0, "command ok": 0,
              "command refused": 0}
    done = 0
    out = tmp / "out"
    for name, (options, *_rest) in sorted(files.items()):
        src = CORPUS / name
        if src.is_dir():  # a ROS 2 bag: damage its storage file in a copy
            bag = tmp / name
            shutil.copytree(src, bag, dirs_exist_ok=True)
            storage = next(bag.glob("*.db3"))
            data, target = storage.read_bytes(), bag
        else:
            data = src.read_bytes()
        for i in range(n_per_file):
            p = tmp / f"{i % 50}{name}"
            if src.is_dir():
                storage.write_bytes(_damaged(data, rng))
                p = target
            else:
                p.write_bytes(_damaged(data, rng))
            done += 1
            if command_every and done % command_every == 0:
                command = commands[(done // command_every) % len(commands)]
                shutil.rmtree(out, ignore_errors=True)
                out.mkdir()
                argv = command_argv(command, p, out) + cli_flags(options)
                ok = check_command(argv, p) == 0
                counts["command ok" if ok else "command refused"] += 1
            try:
                rec = load_recording(p, options)
            except ImubenchError as exc:
                assert str(exc).startswith(str(p)), exc
                counts["refused"] += 1
                continue
            assert len(rec) <= MAX_SAMPLES
            counts["damage reported" if rec.damage else "read"] += 1
    return counts
