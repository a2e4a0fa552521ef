"""Bias factors Stable32 divides raw variances by (``bias_correction=True``).

``bias_factor(stat, alpha, m, n_phase)`` returns B with ``var_corrected = var_raw / B``;
1.0 where Stable32 applies no correction. Sources and checks:

* TOTVAR (D. A. Howe, "Total variance explained", Proc. 1999 Joint EFTF/IFCS, table 1;
  NIST SP 1065 section 5.2.11): for flicker FM and random-walk FM the expected TOTVAR is
  AVAR times ``B = 1 - a tau/T`` with ``a = 1/(3 ln 2) = 0.481`` (FFM) and ``0.750``
  (RWFM), T = N tau0 the record length (tau/T = m/N). No correction for other noises.
  Checked against ``ocxo/totdev_octave.txt`` (alpha -1 and -2 rows) with allantools'
  uncorrected TOTDEV in the tests.
* HTOTVAR (D. A. Howe et al., "A total estimator of the Hadamard function used for GPS
  operations", 32nd PTTI, 2000; SP 1065 section 5.2.14): ``B = 1 + a`` with a = -0.005
  (WFM), -0.149 (FFM), -0.229 (RWFM), -0.283 (FWFM), -0.321 (RRFM); none for PM noise and
  none at m = 1, where Stable32 reports OHVAR. Checked with ``phasedat/
  phase_dat_htotdev_octave{,_nobias}.txt`` (ratio 1/0.995 at alpha 0, AF > 1).
* Theo1 (D. A. Howe and T. N. Tasset, "Theo1: characterization of very long-term frequency
  stability", EFTF 2004; W. J. Riley, "Fast bias-removed Theo1 calculation with R"):
  Stable32 multiplies Theo1 by a nominal ratio AVAR/Theo1 per noise type, i.e. divides it
  by ``B = Theo1/AVAR``: WPM 1/0.4, FPM 1/0.6028, WFM 1, FFM 1/1.71, RWFM 1/2.24. The
  FPM value 0.6028 is measured from ``phasedat/phase_dat_theo1.txt`` (alpha 1) over
  ``phase_dat_theo1_alpha0.txt`` (uncorrected): the variance ratio is 0.60279 +- 5e-5 at
  all 181 AFs (the literature rounds it to 0.6). The other values are the published nominal
  ratios, not checked against a Stable32 file here.
* TheoBR and TheoH are bias-removed by construction (factor 1). MTOT and TTOT: Stable32
  1.60 applies none (the phasedat references are uncorrected), although SP 1065 lists
  ratios (0.94 ... 0.69); AVAR, OAVAR, MVAR, TVAR, HVAR, OHVAR, STDVAR, OSTDVAR: none.
"""

from __future__ import annotations

import math

from imubench.errors import StatsError
from imubench.stats.edf import canonical_stat

__all__ = ["HTOTVAR_BIAS_A", "THEO1_AVAR_RATIO", "TOTVAR_BIAS_A", "bias_factor"]

#: TOTVAR: a in B = 1 - a m/N (Howe 1999 table 1).
TOTVAR_BIAS_A: dict[int, float] = {-1: 1.0 / (3.0 * math.log(2.0)), -2: 0.75}
#: HTOTVAR: a in B = 1 + a (Howe et al. 2000).
HTOTVAR_BIAS_A: dict[int, float] = {0: -0.005, -1: -0.149, -2: -0.229, -3: -0.283, -4: -0.321}
#: Theo1: nominal AVAR/Theo1 ratio by alpha (Stable32 multiplies Theo1 by it).
THEO1_AVAR_RATIO: dict[int, float] = {2: 0.4, 1: 0.6028, 0: 1.0, -1: 1.71, -2: 2.24}

_NO_BIAS = {
    "avar",
    "oavar",
    "mvar",
    "tvar",
    "hvar",
    "ohvar",
    "mtotvar",
    "ttotvar",
    "theobrvar",
    "theohvar",
    "stdvar",
    "ostdvar",
}


def bias_factor(stat: str, alpha: int, m: int, n_phase: int) -> float:
    """Factor B by which Stable32 divides the raw ``stat`` variance at averaging factor m.

    ``alpha`` is the noise exponent in use, ``n_phase`` the number of phase points N.
    Returns 1.0 where no correction applies. See the module docstring for the formulas
    and their sources. Raises :class:`StatsError` for an unknown statistic or a TOTVAR
    factor that would not be positive (m >= N/a).
    """
    name = canonical_stat(stat)
    alpha = int(alpha)
    if m < 1 or n_phase < 2:
        raise StatsError(f"bias_factor({stat!r}): need m >= 1 and N >= 2, got m={m}, N={n_phase}")
    if name in _NO_BIAS:
        return 1.0
    if name == "totvar":
        a = TOTVAR_BIAS_A.get(alpha)
        if a is None:
            return 1.0
        b = 1.0 - a * m / n_phase
        if b <= 0.0:
            raise StatsError(
                f"bias_factor('totvar'): 1 - {a:.3f}*m/N = {b:.3f} <= 0 at m={m}, N={n_phase}; "
                "the averaging factor is too large for this record"
            )
        return b
    if name == "htotvar":
        if m == 1:
            return 1.0
        return 1.0 + HTOTVAR_BIAS_A.get(alpha, 0.0)
    if name == "theo1var":
        ratio = THEO1_AVAR_RATIO.get(alpha)
        if ratio is None:
            raise StatsError(f"bias_factor('theo1var'): no Theo1 bias for alpha={alpha} (-2..2)")
        return 1.0 / ratio
    raise StatsError(
        f"bias_factor: unknown statistic {stat!r}; expected a variance or deviation name such "
        "as 'oavar', 'totvar', 'htotvar', 'theo1var'"
    )
