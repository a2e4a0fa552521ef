"""Damaged copies of recordings (truncations, byte and bit flips) through the one reader:
shared by ``tests/test_foreign_inputs.py`` and ``bench/fault_recordings.py``."""

from __future__ import annotations

import random
import shutil
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from imubench.errors import ImubenchError
from imubench.recording import InputOptions, load_recording

CORPUS = Path(__file__).parent / "data" / "foreign"
MAX_SAMPLES = 209
"""No damaged corpus file may yield more samples than its 208 (+1 for a torn index)."""


def _damaged(data: bytes, rng: random.Random) -> bytes:
    if rng.random() < 0.4:
        return data[: rng.randrange(len(data))]
    out = bytearray(data)
    for _ in range(rng.randint(1, 6)):
        i = rng.randrange(len(out))
        out[i] = rng.randrange(256) if rng.random() < 0.5 else out[i] ^ (1 << rng.randrange(8))
    return bytes(out)


def fuzz(files: Mapping[str, tuple[InputOptions, Any, Any, Any]], n_per_file: int, tmp: Path,
         seed: int = 1) -> dict[str, int]:
    """Truncations and byte/bit flips of every corpus file through the reader: each is
    read (perhaps with damage reported) or refused with ImubenchError; counts by outcome.
    Anything else raised fails."""
    rng = random.Random(seed)
    counts = {"read": 0, "damage reported": 0, "refused": 0}
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
            try:
                rec = load_recording(p, options)
            except ImubenchError as exc:
                assert str(exc).startswith(str(p)), exc
                counts["refused"] += 1
                continue
            assert len(rec) <= MAX_SAMPLES
            counts["damage reported" if rec.damage else "read"] += 1
    return counts
