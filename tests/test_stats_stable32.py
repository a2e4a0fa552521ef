"""Acceptance: every Stable32 reference file in allantools-stable32/ is reproduced.

Deviations within 1e-4 relative (2e-3 for the OCXO ``*_octave`` runs, made by Stable32 on
frequency ratios near 1.0, see the README), term counts exact (Theo1: as Stable32 prints
them, 5 significant digits). CI limits: within 1e-3 given Stable32's alpha, and within
1e-2 with our own noise identification wherever our alpha equals Stable32's (the rows
where it does not are listed exactly in ``OWN_ALPHA_DIFFERS``).
"""

from __future__ import annotations

import gzip
import re
from dataclasses import dataclass
from decimal import ROUND_HALF_UP, Decimal
from pathlib import Path

import numpy as np
import pytest

import imubench.stats as st

SET = "allantools-stable32"


@dataclass(frozen=True)
class Case:
    rel: str  # reference file relative to SET
    stat: str
    data: str  # "phasedat" | "ocxo" | "tic" | "pink"
    rate: float
    bias: bool  # Stable32 applied a bias correction in this run
    rtol: float = 1e-4
    ci_rtol: float = 1e-3
    has_ci: bool = True  # the file carries Min/Max Sigma (CIs were on in that run)


CASES = [
    *[
        Case(f"phasedat/phase_dat_{s}.txt", s, "phasedat", 1.0, False, has_ci=False)
        for s in ("adev", "oadev", "mdev", "tdev", "hdev", "ohdev", "totdev")
    ],
    *[
        Case(f"phasedat/phase_dat_{s}_octave.txt", s, "phasedat", 1.0, False)
        for s in ("adev", "oadev", "mdev", "tdev", "hdev", "ohdev", "totdev")
    ],
    Case("phasedat/phase_dat_htotdev_octave.txt", "htotdev", "phasedat", 1.0, True),
    Case("phasedat/phase_dat_htotdev_octave_nobias.txt", "htotdev", "phasedat", 1.0, False),
    Case("phasedat/phase_dat_mtotdev.txt", "mtotdev", "phasedat", 1.0, False, has_ci=False),
    *[
        Case(f"phasedat/phase_dat_mtotdev{s}.txt", "mtotdev", "phasedat", 1.0, False)
        for s in ("_decade", "_octave", "_octave_alpha0")
    ],
    Case("phasedat/phase_dat_ttotdev_all.txt", "ttotdev", "phasedat", 1.0, False, has_ci=False),
    *[
        Case(f"phasedat/phase_dat_ttotdev_{s}.txt", "ttotdev", "phasedat", 1.0, False)
        for s in ("decade", "octave")
    ],
    Case("phasedat/phase_dat_theo1.txt", "theo1", "phasedat", 1.0, True, has_ci=False),
    Case("phasedat/phase_dat_theo1_alpha0.txt", "theo1", "phasedat", 1.0, False, has_ci=False),
    Case(
        "phasedat/phase_dat_theo1_alpha0_decade.txt",
        "theo1",
        "phasedat",
        1.0,
        False,
        has_ci=False,
    ),
    *[
        Case(f"ocxo/stable32_{s}_alltau.txt", s, "ocxo", 1.0, False, has_ci=False)
        for s in ("adev", "oadev", "mdev", "tdev", "hdev", "ohdev", "totdev")
    ],
    *[
        Case(f"ocxo/{s}_octave.txt", s, "ocxo", 1.0, False, rtol=2e-3, ci_rtol=5e-3)
        for s in ("adev", "oadev", "mdev", "tdev", "hdev", "ohdev")
    ],
    Case("ocxo/totdev_octave.txt", "totdev", "ocxo", 1.0, True, rtol=2e-3, ci_rtol=5e-3),
    Case("Keysight53230A_ti_noise_floor/tic_adev.txt", "adev", "tic", 1.0, False, has_ci=False),
    *[
        Case(f"Keysight53230A_ti_noise_floor/tic_{s}.txt", s, "tic", 1.0, False)
        for s in ("oadev", "mdev", "tdev", "hdev", "ohdev", "totdev")
    ],
    *[
        Case(f"pink_frequency/{s}.txt", s, "pink", 1.0 / 42.0, False, has_ci=False)
        for s in ("adev", "oadev", "mdev", "tdev", "hdev", "ohdev")
    ],
    Case("pink_frequency/totdev_alpha0.txt", "totdev", "pink", 1.0 / 42.0, False, has_ci=False),
    Case("pink_frequency/s32_oadev_octave.txt", "oadev", "pink", 1.0, False),
]

_ROW = re.compile(
    r"^#?\s*(\d+)\s+([-+0-9.eE]+)\s+([-+0-9.eE]+)\s+(-?\d+)\s+"
    r"([-+0-9.eE]+)\s+([-+0-9.eE]+)\s+([-+0-9.eE]+)\s*$"
)


def read_stable32(path: Path) -> tuple[np.ndarray, dict[str, str]]:
    """Rows (commented ones included) as an (n, 7) array and header key/values."""
    rows, header = [], {}
    for line in path.read_text(encoding="latin-1").splitlines():
        mt = _ROW.match(line)
        if mt:
            rows.append([float(v) for v in mt.groups()])
        elif ":" in line or "=" in line:
            key, _, val = line.lstrip("# ").partition(":" if ":" in line else "=")
            header[key.strip()] = val.strip()
    return np.array(rows), header


_DATA_CACHE: dict[str, tuple[np.ndarray, str]] = {}


def load_data(ref: Path, which: str) -> tuple[np.ndarray, str]:
    if which not in _DATA_CACHE:
        base = ref / SET
        if which == "phasedat":
            out = (np.loadtxt(base / "phasedat" / "PHASE.DAT"), "phase")
        elif which == "ocxo":
            f = np.loadtxt(base / "ocxo" / "ocxo_frequency.txt")
            out = (f / 1e7 - 1.0, "freq")
        elif which == "tic":
            out = (np.loadtxt(base / "Keysight53230A_ti_noise_floor" / "tic_phase.txt"), "phase")
        elif which == "pink":
            out = (np.loadtxt(base / "pink_frequency" / "pink_frequency.txt"), "freq")
        else:  # pragma: no cover
            raise KeyError(which)
        _DATA_CACHE[which] = out
    return _DATA_CACHE[which]


def sig5(v: np.ndarray) -> np.ndarray:
    """Round to 5 significant digits, half up, as Stable32 prints its Theo1 counts."""
    out = []
    for x in v:
        shift = len(str(int(x))) - 5
        q = Decimal(int(x)).scaleb(-shift).quantize(Decimal(1), rounding=ROUND_HALF_UP)
        out.append(float(q.scaleb(shift)))
    return np.array(out)


# Stable32 1.53 (phase_dat_mtotdev.txt, phase_dat_ttotdev_all.txt) divided MTOT/TTOT by the
# published MTOT bias factors (Howe & Vernotte; SP 1065 sec. 5.2.12 table; the same numbers
# are in allantools' mtotdev docstring); Stable32 1.60 no longer does. Per alpha:
MTOT_BIAS_S32_153 = {2: 0.94, 1: 0.83, 0: 0.73, -1: 0.70, -2: 0.69}
S32_153_BIASED = {"phasedat/phase_dat_mtotdev.txt", "phasedat/phase_dat_ttotdev_all.txt"}


def _compute_case(reference_dir: Path, case: Case, rows: np.ndarray,
                  alpha: np.ndarray | None) -> st.StatResult:
    """compute() on the case's data at the file's AFs (alpha None: our own noise ID)."""
    data, dtype = load_data(reference_dir, case.data)
    return st.compute(case.stat, data, case.rate, dtype, afs=rows[:, 0].astype(np.int64),
                      alpha=alpha, bias_correction=case.bias)


@pytest.mark.parametrize("case", CASES, ids=[c.rel for c in CASES])
def test_stable32_deviation_and_counts(reference_dir: Path, case: Case) -> None:
    rows, _ = read_stable32(reference_dir / SET / case.rel)
    assert rows.shape[0] >= 5
    res = _compute_case(reference_dir, case, rows, rows[:, 3].astype(int))
    np.testing.assert_array_equal(res.m, rows[:, 0].astype(np.int64))
    tau = rows[:, 1]
    np.testing.assert_allclose(res.tau_s, tau, rtol=1e-4)
    if case.stat == "theo1":
        np.testing.assert_array_equal(sig5(res.n.astype(float)), rows[:, 2])
    else:
        np.testing.assert_array_equal(res.n, rows[:, 2].astype(np.int64))
    dev = res.dev
    if case.rel in S32_153_BIASED:
        dev = dev / np.sqrt([MTOT_BIAS_S32_153[int(a)] for a in rows[:, 3]])
    np.testing.assert_allclose(dev, rows[:, 5], rtol=case.rtol)


# Every Stable32 limit is reproduced to ci_rtol with Stable32's alpha (HTOT at flicker PM,
# phasedat AF 128/256, was off by 2.6e-3 and 1.4e-2 until the simple-formula EDF got
# Stable32's +2, edf.SIMPLE_EDF_OFFSET).
CI_CASES = [pytest.param(c, id=c.rel) for c in CASES if c.has_ci]


def _ci_rel_err(res: st.StatResult, rows: np.ndarray) -> np.ndarray:
    return np.maximum(np.abs(res.ci_low / rows[:, 4] - 1.0), np.abs(res.ci_high / rows[:, 6] - 1.0))


@pytest.mark.parametrize("case", CI_CASES)
def test_stable32_ci_given_alpha(reference_dir: Path, case: Case) -> None:
    rows, _ = read_stable32(reference_dir / SET / case.rel)
    assert np.all(rows[:, 4] > 0), "a file listed with CIs has a row without them"
    res = _compute_case(reference_dir, case, rows, rows[:, 3].astype(int))
    err = _ci_rel_err(res, rows)
    assert np.all(err <= case.ci_rtol), dict(zip(rows[:, 0], err, strict=True))


# Rows where our noise identification (compute() with alpha=None) gives another alpha than
# the file: (file, AF) -> (ours, Stable32's). One cause only, "fixed": Stable32 was told the
# alpha (README: the phasedat *_octave runs used alpha 0, the HTOT nobias run alpha 2 on
# white FM, the _alpha0 MTOT run alpha 0), so the file's column is not a noise
# identification at all. (The longest AFs, where Stable32 keeps the previous tau's alpha
# beyond half the largest AF, are reproduced by noise_id.identifies_at.)
# The fixed-alpha-0 octave runs of ADEV..OHDEV agree with our identification (AF 128 is
# beyond half their largest AF, so it keeps AF 64's alpha 0); TOTDEV's largest AF is 500.
OWN_ALPHA_DIFFERS: dict[tuple[str, int], tuple[int, int]] = {
    ("phasedat/phase_dat_totdev_octave.txt", 128): (1, 0),
    ("phasedat/phase_dat_totdev_octave.txt", 256): (1, 0),
    ("phasedat/phase_dat_mtotdev_octave_alpha0.txt", 128): (1, 0),
    ("phasedat/phase_dat_mtotdev_octave_alpha0.txt", 256): (1, 0),
    **{  # alpha 2 forced on white FM data
        ("phasedat/phase_dat_htotdev_octave_nobias.txt", m): (a, 2)
        for m, a in ((1, 0), (2, 0), (4, 0), (8, 0), (16, 0), (32, 0), (64, 0), (128, 1), (256, 1))
    },
}


@pytest.mark.parametrize("case", CI_CASES)
def test_stable32_ci_own_noise_id(reference_dir: Path, case: Case) -> None:
    """Acceptance 1: CI limits within 1e-2 with our own noise identification."""
    rows, _ = read_stable32(reference_dir / SET / case.rel)
    res = _compute_case(reference_dir, case, rows, None)
    theirs = rows[:, 3].astype(int)
    differs = {
        (case.rel, int(m)): (int(a), int(b))
        for m, a, b in zip(rows[:, 0], res.alpha, theirs, strict=True)
        if a != b
    }
    expected = {k: v for k, v in OWN_ALPHA_DIFFERS.items() if k[0] == case.rel}
    assert differs == expected
    same = res.alpha == theirs
    err = _ci_rel_err(res, rows)
    tol = max(1e-2, case.ci_rtol)
    assert np.all(err[same] <= tol), dict(zip(rows[same, 0], err[same], strict=True))


# The OCXO all-tau runs (no CIs) still carry Stable32's own per-tau noise identification,
# except TOTDEV's, whose Alpha column is 0 throughout (README: no identification there).
ALLTAU_ID = [
    pytest.param(c, id=c.rel)
    for c in CASES
    if c.rel.endswith("_alltau.txt") and c.stat != "totdev"
]


@pytest.mark.parametrize("case", ALLTAU_ID)
def test_stable32_alltau_noise_id(reference_dir: Path, case: Case) -> None:
    """Every AF: lag-1 ACF, B1/R(n) below 30 points, and beyond half the largest AF the
    previous tau's alpha (noise_id.identifies_at), as in the file's Alpha column."""
    rows, _ = read_stable32(reference_dir / SET / case.rel)
    data, dtype = load_data(reference_dir, case.data)
    afs = rows[:, 0].astype(np.int64)
    res = st.compute(case.stat, data, case.rate, dtype, afs=afs, bias_correction=False)
    theirs = rows[:, 3].astype(int)
    bad = res.alpha != theirs
    pairs = zip(res.alpha[bad], theirs[bad], strict=True)
    assert not bad.any(), dict(zip(afs[bad], pairs, strict=True))
    held = afs[2 * afs > st.taus.max_af(case.stat, data.size)]
    assert held.size >= 10  # the hold region is exercised, not only the identified one


def test_gzip_reader_smoke(tmp_path: Path) -> None:
    """The reference loader path for .gz inputs works as numpy documents (README note)."""
    p = tmp_path / "x.txt.gz"
    with gzip.open(p, "wt") as fh:
        fh.write("# c\n1\n2\n3\n")
    assert np.loadtxt(p).tolist() == [1.0, 2.0, 3.0]


def test_identify_alpha_holds_previous_only_beyond_half_max_af() -> None:
    """``previous`` is returned (clipped) beyond m_max/2 and ignored up to it."""
    x = np.cumsum(np.random.default_rng(7).standard_normal(4001))  # white FM phase
    m_max = st.taus.max_af("oadev", x.size - 1)  # 1000
    inside, beyond = m_max // 2, m_max // 2 + 1
    assert st.noise_id.identifies_at("oavar", inside, x.size)
    assert not st.noise_id.identifies_at("oavar", beyond, x.size)
    own = st.noise_id.identify_alpha(x, inside, "phase", "oavar")
    assert st.noise_id.identify_alpha(x, inside, "phase", "oavar", previous=own - 1) == own
    assert st.noise_id.identify_alpha(x, beyond, "phase", "oavar", previous=-2) == -2
    assert st.noise_id.identify_alpha(x, beyond, "phase", "oavar", previous=-4) == -2  # clipped
    assert st.noise_id.identify_alpha(x, beyond, "phase", "hvar", previous=-4) == -4
