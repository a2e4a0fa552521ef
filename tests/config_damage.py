"""Damaged configuration files for the loader's fuzz test (tests/test_config_fuzz.py) and
benchmark (bench/bench_config_fuzz.py): random truncation, byte and bit flips, value
type swaps, deleted, unknown and misplaced keys, applied to valid configurations.

:func:`load_outcome` loads one file the way ``imubench run --check`` does and classifies
the result: ``accepted``, ``refused`` (a :class:`ConfigError` whose every line names the
file or the environment variable) or ``bad`` (any other exception, a malformed message,
or longer than ``HANG_S``: what the fuzz must never see).
"""

from __future__ import annotations

import random
import signal
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import tomli_w

from imubench.config import load_config, quickstart_file
from imubench.errors import ConfigError

HANG_S = 20
"""A load taking longer than this counts as a hang."""

EDGE_VALUES: tuple[Any, ...] = (
    "", "abc", "{nope}", "{station", "}", "octave", "all", "0", "-1", "1e9", "nan",
    "/", ".", "..", "/dev/zero", "sim://", "mqtt://", "mqtts://:0", "x" * 5000, "\x00",
    "sim://lsm6dsl?odr_hz=1e9", "replay:///dev/zero", "sim://lsm6dsl?model=/dev/zero",
    0, -1, 1, 2**63 - 1, -(2**63), 65536, 1e308, -1e308, 1e-300, 0.0, -0.0,
    float("inf"), float("-inf"), float("nan"), True, False, [], [1, "a"], ["oadev"] * 50,
    [1e-300, 1e300], {"x": 1}, {},
)


def base_configs(tmp: Path) -> list[str]:
    """Valid configuration texts (each loads): the quick start, the service example and
    one that sets every key to a non-default value."""
    repo = Path(__file__).resolve().parents[1]
    full = {
        "source": {"uri": "sensortile-sim://?mode=ascii&seed=3&model=datasheet:lsm6dsm"},
        "log": {"enabled": True, "path": f"{tmp}/rec/{{station}}-{{sensor}}-{{start}}.csv",
                "fsync_interval_s": 0.5},
        "allan": {"stats": ["mdev", "oadev", "ostdev"], "taus": "1,10,100",
                  "max_tau_s": 1000.0, "memory": "exact", "state_path": f"{tmp}/st/s.npz"},
        "mqtt": {"broker": "mqtt://127.0.0.1:1884", "port": 1999, "station": "lab",
                 "sensor": "z9", "publish_interval_s": 2.0, "username": "u",
                 "password": "p", "qos": 1, "keepalive_s": 60},
        "display": {"live_table": "off", "interval_s": 0.5},
        "buffer": {"capacity_s": 10.0},
        "run": {"duration_s": 3600.0},
    }
    texts = [quickstart_file().read_text(), (repo / "config" / "service.toml").read_text(),
             tomli_w.dumps(full)]
    for i, text in enumerate(texts):
        p = tmp / f"base{i}.toml"
        p.write_text(text)
        load_config(p)  # the bases are valid
    return texts


def _leaves(node: dict[str, Any], path: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    out: list[tuple[str, ...]] = []
    for k, v in node.items():
        out.extend(_leaves(v, (*path, k)) if isinstance(v, dict) and v else [(*path, k)])
    return out


def _swap_value(text: str, rng: random.Random) -> bytes:
    import tomllib

    doc = tomllib.loads(text)
    for _ in range(rng.randint(1, 3)):
        leaves = _leaves(doc)
        path = rng.choice(leaves)
        node = doc
        for k in path[:-1]:
            node = node[k]
        op = rng.random()
        if op < 0.7:
            node[path[-1]] = rng.choice(EDGE_VALUES)
        elif op < 0.8:
            del node[path[-1]]
        elif op < 0.9:
            node[path[-1] + rng.choice(["x", "_", "s"])] = node.pop(path[-1])
        else:  # move a key to another section or to the top level
            value = node.pop(path[-1])
            target = doc if rng.random() < 0.3 else doc.setdefault(
                rng.choice([*doc.keys(), "extra"]), {})
            if isinstance(target, dict):
                target[path[-1]] = value
    return tomli_w.dumps(doc).encode()


def _truncate(data: bytes, rng: random.Random) -> bytes:
    return data[: rng.randrange(len(data))]


def _flip_bytes(data: bytes, rng: random.Random) -> bytes:
    b = bytearray(data)
    for _ in range(rng.randint(1, 6)):
        b[rng.randrange(len(b))] = rng.randrange(256)
    return bytes(b)


def _flip_bits(data: bytes, rng: random.Random) -> bytes:
    b = bytearray(data)
    for _ in range(rng.randint(1, 8)):
        b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
    return bytes(b)


def _splice(data: bytes, rng: random.Random) -> bytes:
    lines = data.splitlines(keepends=True)
    i, j = rng.randrange(len(lines)), rng.randrange(len(lines))
    lines.insert(i, lines[j])  # a duplicated line: duplicate keys or misplaced tables
    return b"".join(lines)


DAMAGES: dict[str, Callable[[bytes, random.Random], bytes]] = {
    "truncate": _truncate, "byte_flip": _flip_bytes, "bit_flip": _flip_bits,
    "splice": _splice,
}


def damaged(texts: list[str], rng: random.Random) -> tuple[str, bytes]:
    """(kind, bytes) of one damaged configuration."""
    text = rng.choice(texts)
    if rng.random() < 0.4:
        return "type_swap", _swap_value(text, rng)
    kind = rng.choice(list(DAMAGES))
    return kind, DAMAGES[kind](text.encode(), rng)


@dataclass
class Outcome:
    verdict: str  # accepted | refused | bad
    seconds: float
    detail: str


class _HangError(Exception):
    pass


def _alarm(signum: int, frame: object) -> None:
    raise _HangError


def load_outcome(path: Path) -> Outcome:
    """Load ``path`` as ``imubench run --check`` does; classify the result."""
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(HANG_S)
    t0 = time.perf_counter()
    try:
        load_config(path)
        return Outcome("accepted", time.perf_counter() - t0, "")
    except ConfigError as exc:
        lines = str(exc).splitlines()
        ok = bool(lines) and all(
            line.startswith((str(path), "environment")) and len(line) < 2000 for line in lines
        )
        return Outcome("refused" if ok else "bad", time.perf_counter() - t0, str(exc))
    except _HangError:
        return Outcome("bad", time.perf_counter() - t0, f"no answer within {HANG_S} s")
    except Exception:
        return Outcome("bad", time.perf_counter() - t0, traceback.format_exc())
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
