"""Damaged configurations: each one is accepted or refused with one line per problem
naming the file, never a traceback or a hang (bench/bench_config_fuzz.py runs 20 000)."""

from __future__ import annotations

import os
import random
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest
from config_damage import base_configs, damaged, load_outcome

N_DEFAULT = 1000


@pytest.fixture(autouse=True)
def _no_imubench_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in list(os.environ):
        if name.upper().startswith("IMUBENCH_"):
            monkeypatch.delenv(name)


def test_damaged_configs_are_accepted_or_refused_cleanly(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    rng = random.Random(20261123)
    texts = base_configs(tmp_path)
    verdicts: Counter[str] = Counter()
    bad = []
    for i in range(N_DEFAULT):
        kind, data = damaged(texts, rng)
        p = tmp_path / f"d{i}.toml"
        p.write_bytes(data)
        out = load_outcome(p)
        verdicts[out.verdict] += 1
        if out.verdict == "bad":
            bad.append(f"{kind} {p}: {out.detail[:1500]}")
    assert not bad, "\n".join(bad[:3])
    assert verdicts["refused"] > N_DEFAULT // 3 and verdicts["accepted"] > 0, verdicts


def test_damaged_configs_through_the_command_line(tmp_path: Path) -> None:
    rng = random.Random(7)
    texts = base_configs(tmp_path)
    env = {k: v for k, v in os.environ.items() if not k.upper().startswith("IMUBENCH_")}
    for i in range(4):
        _, data = damaged(texts, rng)
        p = tmp_path / f"cli{i}.toml"
        p.write_bytes(data)
        proc = subprocess.run([sys.executable, "-m", "imubench", "run", "--config", str(p),
                               "--check"], capture_output=True, text=True, timeout=120,
                              env=env)
        assert proc.returncode in (0, 2), proc.stderr
        assert "Traceback" not in proc.stderr
        if proc.returncode == 2:
            assert all(line.startswith(f"imubench run: error: {p}")
                       for line in proc.stderr.splitlines()), proc.stderr
